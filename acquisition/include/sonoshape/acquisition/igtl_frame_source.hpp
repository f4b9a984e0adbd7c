#pragma once
// `--source igtl:HOST:PORT`, frames: the IMAGE messages of an OpenIGTLink server (PlusServer).
// Built only with SONOSHAPE_WITH_OPENIGTLINK.
#include <optional>
#include <string>

#include "sonoshape/acquisition/frame_source.hpp"
#include "sonoshape/acquisition/igtl_client.hpp"

namespace sonoshape::acquisition {

/// Receives the IMAGE messages named `image_device` ("" : any) from an OpenIGTLink server;
/// every other message is skipped. Frame::timestamp_s is the message's timestamp (the
/// sender's clock, as PlusServer stamps its frames), Frame::index counts the frames kept.
/// Images that cannot be read are dropped and counted in losses() as "damaged" (a bad CRC, a
/// body that does not hold the pixels it declares) or "unsupported" (not 8-bit grey 2D); the
/// first of each is logged with its reason (label maps: integer 2D, values 0..255). A server
/// that is not there at start fails the source with its address; one that goes away later is
/// the source's condition() while it is connected to again (IgtlLink), and frames resume when
/// it is back.
class IgtlFrames final : public FrameBackend {
 public:
  /// `pixels`: IgtlPixels::kLabels reads label maps (any integer type, values 0..255).
  IgtlFrames(IgtlEndpoint endpoint, std::string image_device,
             IgtlPixels pixels = IgtlPixels::kGrey);
  /// Reads an open connection, delivering `first` (a message already read from it, e.g. to
  /// learn the image size before the scan starts) before the rest.
  IgtlFrames(IgtlEndpoint endpoint, std::string image_device, IgtlConnection connection,
             std::optional<IgtlMessage> first);

  std::string describe() const override { return "igtl:" + link_.endpoint().text(); }
  std::map<std::string, std::size_t> losses() const override { return drops_.counts(); }

 protected:
  Status open() override;
  Result<Polled> poll(Frame& frame) override;
  void close() override { link_.close(); }

 private:
  IgtlLink link_;
  std::string image_device_;
  IgtlPixels pixels_ = IgtlPixels::kGrey;
  std::optional<IgtlMessage> pending_;
  IgtlDrops drops_;
  std::int64_t next_index_ = 0;
};
/// The stream of an IgtlFrames.
using IgtlFrameSource = SourceOf<IgtlFrames>;

}  // namespace sonoshape::acquisition
