#pragma once
// The client side of OpenIGTLink (protocol v2, as a PlusServer speaks it): one TCP connection
// read message by message, and the decoding of the IMAGE and TRANSFORM messages the igtl:
// sources use. Built only with SONOSHAPE_WITH_OPENIGTLINK; no OpenIGTLink type appears here.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/image.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition {

/// Where an OpenIGTLink server listens. 18944 is OpenIGTLink's and PlusServer's default port.
struct IgtlEndpoint {
  std::string host = "127.0.0.1";
  int port = 18944;
  std::string text() const { return host + ":" + std::to_string(port); }
};

/// "HOST:PORT", or "HOST" (port 18944). Errors name `option` and the expected form.
Result<IgtlEndpoint> parse_igtl_endpoint(const std::string& text, const std::string& option);

/// One whole message as it came over the wire (header and body; CRC not yet checked).
struct IgtlMessage {
  std::string type;    ///< "IMAGE", "TRANSFORM", ...
  std::string device;  ///< the device name
  /// The header's timestamp (s since 1970 on the sender's clock); when the sender set none (0)
  /// or one more than a day ahead of this machine's clock (an unset field's stray bytes), the
  /// arrival time on this machine's wall clock (and stamped_on_arrival).
  double timestamp_s = 0.0;
  bool stamped_on_arrival = false;
  std::vector<std::uint8_t> bytes;
};

/// A client connection. Not thread-safe: one thread reads it.
class IgtlConnection {
 public:
  /// Connects (waiting up to `timeout_s`); errors name the endpoint and say to check that the
  /// server (e.g. PlusServer) runs and listens there.
  static Result<IgtlConnection> connect(const IgtlEndpoint& endpoint, double timeout_s = 5.0);
  IgtlConnection(IgtlConnection&&) noexcept;
  IgtlConnection& operator=(IgtlConnection&&) noexcept;
  ~IgtlConnection();

  /// The next whole message, waiting up to `timeout_s` (none when none completed in time).
  /// Fails when the server closed the connection or sent a malformed header.
  Result<std::optional<IgtlMessage>> next(double timeout_s);

  /// Sends `bytes` (a packed message) whole, waiting up to `timeout_s` for room. Fails when the
  /// connection is gone or stays full.
  Status send(const std::vector<std::uint8_t>& bytes, double timeout_s = 1.0);

 private:
  struct Impl;
  explicit IgtlConnection(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// A connection that outlives its server's restarts (a PlusServer restarted mid-scan): the
/// first connection must succeed, but once it is lost next() returns nothing, trouble() says why,
/// and a new connection is tried every `retry_s` until the server is back. Not thread-safe: one
/// source's thread uses it.
class IgtlLink {
 public:
  /// Called after every connection, the first included (e.g. to ask for a TDATA stream).
  using OnConnect = std::function<Status(IgtlConnection&)>;

  explicit IgtlLink(IgtlEndpoint endpoint, OnConnect on_connect = {}, double retry_s = 0.5);
  /// Starts from a connection already open (its first messages read by the caller).
  IgtlLink(IgtlEndpoint endpoint, IgtlConnection open, OnConnect on_connect = {},
           double retry_s = 0.5);

  const IgtlEndpoint& endpoint() const { return endpoint_; }
  /// Connects the first time (nothing when already open); errors as IgtlConnection::connect.
  Status open();
  /// The next whole message, waiting up to `timeout_s`; none when none came, or while the
  /// connection is lost (then it tries to reconnect when a retry is due).
  std::optional<IgtlMessage> next(double timeout_s);
  /// Why the connection is lost and being retried; empty while connected.
  const std::string& trouble() const { return trouble_; }
  void close() { connection_.reset(); }

 private:
  void lose(const std::string& why);
  void reconnect_when_due();

  IgtlEndpoint endpoint_;
  OnConnect on_connect_;
  double retry_s_;
  std::optional<IgtlConnection> connection_;
  std::string trouble_;
  double next_try_s_ = 0.0;
};

/// Why a received message was dropped: the key a source counts it under in losses().
enum class IgtlDrop {
  kDamaged,      ///< "damaged": bad CRC, or a body too short for what it declares
  kUnsupported,  ///< "unsupported": well formed, but not what sonoshape reads (16-bit, RGB, 3D)
};
const char* to_string(IgtlDrop reason);

/// The drops of one source, by reason; the first drop of each reason is logged (a warning
/// naming the peer and the field), the later ones only counted, so that a peer sending nothing
/// but bad messages neither goes unnoticed nor floods the terminal. Thread-safe.
class IgtlDrops {
 public:
  /// `peer`: how the messages name the server, e.g. "igtl:127.0.0.1:18944".
  explicit IgtlDrops(std::string peer) : peer_(std::move(peer)) {}
  /// Counts one drop; logs `message` the first time `reason` occurs.
  void count(IgtlDrop reason, const std::string& message);
  /// Drops so far by reason ("damaged", "unsupported"); reasons not seen are absent.
  std::map<std::string, std::size_t> counts() const;

 private:
  std::string peer_;
  mutable std::mutex mutex_;
  std::map<std::string, std::size_t> counts_;
};

/// An IMAGE message's content: an 8-bit single-channel 2D image (grey levels or label values)
/// and its matrix.
struct IgtlImage {
  GreyImage image;
  /// Pixel (column, row, 0) to the sender's reference frame (mm): the message's unit axes
  /// scaled by its spacing, the origin moved from the image centre to pixel (0, 0).
  Eigen::Matrix4d T_reference_image = Eigen::Matrix4d::Identity();
  double spacing_mm[2] = {1.0, 1.0};  ///< column and row spacing
};

/// What an IMAGE's pixels hold. B-mode frames are read as 8-bit grey only. Label maps may come in
/// any integer type: 3D Slicer sends a labelmap volume in its own scalar type (often 16-bit),
/// and each value must lie in 0..255 (0 background, 1..254 organs, 255 or another value unknown).
enum class IgtlPixels { kGrey, kLabels };

/// Decodes an IMAGE (CRC checked). The body must hold the image header and the W*H*D pixels it
/// declares (a peer's sizes are never trusted). Refuses scalar types `pixels` does not take
/// (label values outside 0..255 too, naming the pixel), several components, sub-volumes and 3D
/// volumes. Errors name the device and the field; `why`, when given, says whether the message
/// was damaged or unsupported.
Result<IgtlImage> decode_igtl_image(const IgtlMessage& message, IgtlDrop* why = nullptr,
                                    IgtlPixels pixels = IgtlPixels::kGrey);

/// Decodes a TRANSFORM (CRC checked, a body of exactly 12 floats): the 4x4 matrix, mm.
Result<Eigen::Matrix4d> decode_igtl_transform(const IgtlMessage& message);

/// A packed STT_TDATA request: asks a server to stream TDATA every `interval_ms` (PlusServer
/// and Debian's TrackingDataServer stream TDATA only after one).
std::vector<std::uint8_t> igtl_start_tracking_data(int interval_ms);

/// The matrix (mm) of the element named `element` in a TDATA message (CRC checked, a body of
/// whole 70-byte elements); none when the message has no such element.
Result<std::optional<Eigen::Matrix4d>> decode_igtl_tracking_data(const IgtlMessage& message,
                                                                 const std::string& element);

}  // namespace sonoshape::acquisition
