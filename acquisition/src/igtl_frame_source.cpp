#include "sonoshape/acquisition/igtl_frame_source.hpp"

#include <utility>

namespace sonoshape::acquisition {

IgtlFrames::IgtlFrames(IgtlEndpoint endpoint, std::string image_device, IgtlPixels pixels)
    : link_(std::move(endpoint)),
      image_device_(std::move(image_device)),
      pixels_(pixels),
      drops_("igtl:" + link_.endpoint().text()) {}

IgtlFrames::IgtlFrames(IgtlEndpoint endpoint, std::string image_device, IgtlConnection connection,
                       std::optional<IgtlMessage> first)
    : link_(std::move(endpoint), std::move(connection)),
      image_device_(std::move(image_device)),
      pending_(std::move(first)),
      drops_("igtl:" + link_.endpoint().text()) {}

Status IgtlFrames::open() { return link_.open(); }

Result<Polled> IgtlFrames::poll(Frame& frame) {
  std::optional<IgtlMessage> message =
      pending_ ? std::exchange(pending_, std::nullopt) : link_.next(0.1);
  set_condition(link_.trouble());
  if (!message || message->type != "IMAGE") return Polled::kNothing;
  if (!image_device_.empty() && message->device != image_device_) return Polled::kNothing;
  IgtlDrop why = IgtlDrop::kDamaged;
  auto image = decode_igtl_image(*message, &why, pixels_);
  if (!image) {
    drops_.count(why, image.message());
    count_lost(1);
    return Polled::kNothing;
  }
  frame.image = std::move(image->image);
  frame.timestamp_s = message->timestamp_s;
  frame.index = next_index_++;
  return Polled::kItem;
}

}  // namespace sonoshape::acquisition
