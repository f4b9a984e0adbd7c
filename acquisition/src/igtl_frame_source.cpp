#include "sonoshape/acquisition/igtl_frame_source.hpp"

#include <utility>

namespace sonoshape::acq {

IgtlFrameSource::IgtlFrameSource(IgtlEndpoint endpoint, std::string image_device)
    : endpoint_(std::move(endpoint)), image_device_(std::move(image_device)) {}

IgtlFrameSource::IgtlFrameSource(IgtlEndpoint endpoint, std::string image_device,
                                 IgtlConnection connection, std::optional<IgtlMessage> first)
    : endpoint_(std::move(endpoint)),
      image_device_(std::move(image_device)),
      connection_(std::move(connection)),
      pending_(std::move(first)) {}

IgtlFrameSource::~IgtlFrameSource() { stop(); }

Status IgtlFrameSource::open() {
  if (connection_) return Status::ok();  // handed over open
  auto connection = IgtlConnection::connect(endpoint_);
  if (!connection) return connection.status();
  connection_.emplace(std::move(*connection));
  return Status::ok();
}

Result<Polled> IgtlFrameSource::poll(Frame& frame) {
  Result<std::optional<IgtlMessage>> message =
      pending_ ? Result<std::optional<IgtlMessage>>(std::exchange(pending_, std::nullopt))
               : connection_->next(0.1);
  if (!message) return message.status();
  if (!*message || (*message)->type != "IMAGE") return Polled::kNothing;
  if (!image_device_.empty() && (*message)->device != image_device_) return Polled::kNothing;
  auto image = decode_igtl_image(**message);
  if (!image) {
    count_lost(1);
    return Polled::kNothing;
  }
  frame.image = std::move(image->image);
  frame.timestamp_s = (*message)->timestamp_s;
  frame.index = next_index_++;
  return Polled::kItem;
}

}  // namespace sonoshape::acq
