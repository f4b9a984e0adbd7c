#include "sonoshape/acquisition/igtl_client.hpp"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <sstream>
#include <thread>
#include <utility>

#include "igtlImageMessage.h"
#include "igtlMessageHeader.h"
#include "igtlTrackingDataMessage.h"
#include "igtlTransformMessage.h"
#include "igtl_header.h"
#include "igtl_image.h"
#include "igtl_tdata.h"
#include "igtl_transform.h"
#include "igtl_util.h"
#include "integer_samples.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::acquisition {
namespace {

// IMAGE bodies of a 2D ultrasound frame are well below this; anything larger is a broken stream.
constexpr std::uint64_t kMaxBody = 256ull << 20;

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Connects a non-blocking socket to one resolved address, waiting up to `timeout_s`.
int connect_one(const addrinfo& a, double timeout_s) {
  const int fd = ::socket(a.ai_family, a.ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a.ai_protocol);
  if (fd < 0) return -1;
  if (::connect(fd, a.ai_addr, a.ai_addrlen) != 0 && errno != EINPROGRESS) {
    ::close(fd);
    return -1;
  }
  pollfd p{fd, POLLOUT, 0};
  int error = 0;
  socklen_t length = sizeof error;
  if (::poll(&p, 1, static_cast<int>(1e3 * timeout_s)) != 1 ||
      ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &error, &length) != 0 || error != 0) {
    ::close(fd);
    errno = error ? error : ETIMEDOUT;
    return -1;
  }
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  return fd;
}

// A big-endian u64 field of a raw header.
std::uint64_t header_u64(const std::uint8_t* header, std::size_t offset) {
  std::uint64_t value = 0;
  for (std::size_t i = 0; i < 8; ++i) value = (value << 8) | header[offset + i];
  return value;
}

// Offsets in the 58-byte header: version (2), type name (12), device name (20), timestamp (8),
// body size (8), CRC-64 of the body (8).
constexpr std::size_t kBodySizeOffset = 2 + 12 + 20 + 8;
constexpr std::size_t kCrcOffset = kBodySizeOffset + 8;

// The body size a header announces, read whole: the 1.11 library's GetBodySizeToRead() is an
// int, which reads 2^63 as 0 and 2^31 as negative.
std::uint64_t header_body_size(const std::uint8_t* header) {
  return header_u64(header, kBodySizeOffset);
}

// Checks that `raw` is a header and the body it announces, `min_body` to `max_body` bytes, with
// the header's CRC. Errors (all kDamaged) name the field.
Status check_body(const IgtlMessage& raw, const std::string& what, std::uint64_t min_body,
                  std::uint64_t max_body, const std::string& fixed_part) {
  if (raw.bytes.size() < IGTL_HEADER_SIZE ||
      header_body_size(raw.bytes.data()) != raw.bytes.size() - IGTL_HEADER_SIZE)
    return Status::error(what + ": the header's body size does not match the message");
  const std::uint64_t body = raw.bytes.size() - IGTL_HEADER_SIZE;
  if (body < min_body || body > max_body)
    return Status::error(what + ": a body of " + std::to_string(body) + " bytes; " + fixed_part);
  auto* body_bytes = const_cast<std::uint8_t*>(raw.bytes.data()) + IGTL_HEADER_SIZE;
  if (::crc64(body_bytes, body, 0) != header_u64(raw.bytes.data(), kCrcOffset))
    return Status::error(what + ": the header's CRC does not match the body (damaged in transit)");
  return Status::ok();
}

// Unpacks `raw` into `message` when check_body() accepts it. Checked before the library sees the
// body: 1.11 converts a body's fixed part (the IMAGE's 72-byte image header, a TRANSFORM's 48
// bytes) in place without looking at its size, so a short body would be read and written past
// its end.
template <typename Message>
Status unpack(Message& message, const IgtlMessage& raw, const std::string& what,
              std::uint64_t min_body, std::uint64_t max_body, const std::string& fixed_part) {
  if (Status checked = check_body(raw, what, min_body, max_body, fixed_part); !checked)
    return checked;
  const std::uint64_t body = raw.bytes.size() - IGTL_HEADER_SIZE;
  igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
  header->InitPack();
  std::memcpy(header->GetPackPointer(), raw.bytes.data(), IGTL_HEADER_SIZE);
  header->Unpack();
  message->SetMessageHeader(header);
  message->AllocatePack();
  std::memcpy(message->GetPackBodyPointer(), raw.bytes.data() + IGTL_HEADER_SIZE, body);
  if ((message->Unpack(0) & igtl::MessageHeader::UNPACK_BODY) == 0)
    return Status::error(what + ": the body does not unpack (an unknown content version)");
  return Status::ok();
}

// A big-endian float32 of a raw body.
float body_f32(const std::uint8_t* bytes) {
  std::uint32_t word = 0;
  for (int i = 0; i < 4; ++i) word = (word << 8) | bytes[i];
  float value = 0.0f;
  std::memcpy(&value, &word, sizeof value);
  return value;
}

Status refuse(IgtlDrop reason, IgtlDrop* why, const std::string& message) {
  if (why) *why = reason;
  return Status::error(message);
}

}  // namespace

Result<IgtlEndpoint> parse_igtl_endpoint(const std::string& text, const std::string& option) {
  IgtlEndpoint endpoint;
  const std::size_t colon = text.rfind(':');
  endpoint.host = text.substr(0, colon);
  if (colon != std::string::npos) {
    const std::string port = text.substr(colon + 1);
    std::size_t used = 0;
    try {
      endpoint.port = std::stoi(port, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != port.size() || endpoint.port < 1 || endpoint.port > 65535)
      endpoint.host.clear();
  }
  if (endpoint.host.empty())
    return Status::error(option + " '" + text +
                         "': expected HOST:PORT of an OpenIGTLink server, e.g. 127.0.0.1:18944 "
                         "(PlusServer's default port)");
  return endpoint;
}

struct IgtlConnection::Impl {
  int fd = -1;
  std::string where;
  std::vector<std::uint8_t> buffer;
  ~Impl() {
    if (fd >= 0) ::close(fd);
  }

  // The timestamp field of a raw header (big-endian, bytes 34-41: seconds in the high 32 bits,
  // the fraction of a second in the low 32). Read from the bytes rather than through
  // MessageHeader::GetTimeStamp(): for a header whose timestamp is 0 the 1.11 library returned
  // uninitialised memory (0xbebebebe seconds under AddressSanitizer's malloc fill), not 0.
  // A sender's stamp further ahead of this machine's clock than this is not a clock offset.
  static constexpr double kMaxStampAheadS = 86400.0;

  static double header_timestamp_s(const std::uint8_t* header) {
    constexpr std::size_t kTimestampOffset = 2 + 12 + 20;  // version, type name, device name
    std::uint64_t raw = 0;
    for (std::size_t i = 0; i < 8; ++i) raw = (raw << 8) | header[kTimestampOffset + i];
    return static_cast<double>(raw >> 32) + static_cast<double>(raw & 0xffffffffu) / 4294967296.0;
  }

  // The first whole message in the buffer, removed from it; none when incomplete.
  Result<std::optional<IgtlMessage>> take() {
    if (buffer.size() < IGTL_HEADER_SIZE) return std::optional<IgtlMessage>();
    igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
    header->InitPack();
    std::memcpy(header->GetPackPointer(), buffer.data(), IGTL_HEADER_SIZE);
    header->Unpack();
    const std::uint64_t body = header_body_size(buffer.data());
    if (body > kMaxBody)
      return Status::error("OpenIGTLink " + where + ": a message announces " +
                           std::to_string(body) + " bytes; not an OpenIGTLink stream?");
    if (buffer.size() < IGTL_HEADER_SIZE + body) return std::optional<IgtlMessage>();
    IgtlMessage message;
    message.type = header->GetDeviceType();
    message.device = header->GetDeviceName();
    message.timestamp_s = header_timestamp_s(buffer.data());
    const double now_s =
        std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
    // No timestamp (Debian's ImagerServer sets none), or one from beyond tomorrow, which no
    // clock offset explains: OpenIGTLink 1.11's servers send their message object's unset
    // timestamp field, 0 from fresh pages but any bytes from reused ones (0xbebebebe s, the year
    // 2071, under AddressSanitizer's malloc fill). Either way the arrival time on the wall
    // clock, the clock senders stamp with, so that it stays comparable with stamped messages.
    if (message.timestamp_s == 0.0 || message.timestamp_s > now_s + kMaxStampAheadS) {
      message.timestamp_s = now_s;
      message.stamped_on_arrival = true;
    }
    const auto end = buffer.begin() + static_cast<std::ptrdiff_t>(IGTL_HEADER_SIZE + body);
    message.bytes.assign(buffer.begin(), end);
    buffer.erase(buffer.begin(), end);
    return std::optional<IgtlMessage>(std::move(message));
  }
};

Result<IgtlConnection> IgtlConnection::connect(const IgtlEndpoint& endpoint, double timeout_s) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  const std::string port = std::to_string(endpoint.port);
  if (const int error = ::getaddrinfo(endpoint.host.c_str(), port.c_str(), &hints, &found))
    return Status::error("OpenIGTLink " + endpoint.text() + ": cannot resolve '" + endpoint.host +
                         "' (" + ::gai_strerror(error) + ")");
  auto impl = std::make_unique<Impl>();
  impl->where = endpoint.text();
  int error = 0;
  for (const addrinfo* a = found; a && impl->fd < 0; a = a->ai_next) {
    impl->fd = connect_one(*a, timeout_s);
    if (impl->fd < 0) error = errno;
  }
  ::freeaddrinfo(found);
  if (impl->fd < 0)
    return Status::error("OpenIGTLink " + endpoint.text() + ": cannot connect (" +
                         std::strerror(error) +
                         "); check that the server (e.g. PlusServer) runs and listens there");
  return IgtlConnection(std::move(impl));
}

IgtlConnection::IgtlConnection(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
IgtlConnection::IgtlConnection(IgtlConnection&&) noexcept = default;
IgtlConnection& IgtlConnection::operator=(IgtlConnection&&) noexcept = default;
IgtlConnection::~IgtlConnection() = default;

Result<std::optional<IgtlMessage>> IgtlConnection::next(double timeout_s) {
  const double deadline_s = now_s() + timeout_s;
  while (true) {
    auto ready = impl_->take();
    if (!ready || *ready) return ready;
    const double left_s = deadline_s - now_s();
    if (left_s <= 0.0) return std::optional<IgtlMessage>();
    pollfd p{impl_->fd, POLLIN, 0};
    const int polled = ::poll(&p, 1, static_cast<int>(1e3 * left_s) + 1);
    if (polled < 0 && errno != EINTR)
      return Status::error("OpenIGTLink " + impl_->where + ": " + std::strerror(errno));
    if (polled <= 0) continue;
    std::uint8_t chunk[65536];
    const ssize_t n = ::recv(impl_->fd, chunk, sizeof chunk, MSG_DONTWAIT);
    if (n == 0)
      return Status::error("OpenIGTLink " + impl_->where + ": the server closed the connection");
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) continue;
      return Status::error("OpenIGTLink " + impl_->where + ": " + std::strerror(errno));
    }
    impl_->buffer.insert(impl_->buffer.end(), chunk, chunk + n);
  }
}

Status IgtlConnection::send(const std::vector<std::uint8_t>& bytes, double timeout_s) {
  const double deadline_s = now_s() + timeout_s;
  std::size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n =
        ::send(impl_->fd, bytes.data() + sent, bytes.size() - sent, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n > 0) {
      sent += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
      return Status::error("OpenIGTLink " + impl_->where + ": cannot send (" +
                           std::strerror(errno) + ")");
    const double left_s = deadline_s - now_s();
    if (left_s <= 0.0)
      return Status::error("OpenIGTLink " + impl_->where + ": the server takes no data");
    pollfd p{impl_->fd, POLLOUT, 0};
    ::poll(&p, 1, static_cast<int>(1e3 * left_s) + 1);
  }
  return Status::ok();
}

IgtlLink::IgtlLink(IgtlEndpoint endpoint, OnConnect on_connect, double retry_s)
    : endpoint_(std::move(endpoint)), on_connect_(std::move(on_connect)), retry_s_(retry_s) {}

IgtlLink::IgtlLink(IgtlEndpoint endpoint, IgtlConnection open, OnConnect on_connect, double retry_s)
    : IgtlLink(std::move(endpoint), std::move(on_connect), retry_s) {
  connection_.emplace(std::move(open));
}

Status IgtlLink::open() {
  if (connection_) return Status::ok();
  auto connection = IgtlConnection::connect(endpoint_);
  if (!connection) return connection.status();
  connection_.emplace(std::move(*connection));
  return on_connect_ ? on_connect_(*connection_) : Status::ok();
}

std::optional<IgtlMessage> IgtlLink::next(double timeout_s) {
  if (!connection_) {
    reconnect_when_due();
    if (!connection_) return std::nullopt;
  }
  auto message = connection_->next(timeout_s);
  if (!message) {
    lose(message.message());
    return std::nullopt;
  }
  return std::move(*message);
}

void IgtlLink::lose(const std::string& why) {
  connection_.reset();
  std::ostringstream retry;
  retry << retry_s_;
  trouble_ = why + "; connecting again every " + retry.str() + " s";
  next_try_s_ = now_s() + retry_s_;
}

// A short connect timeout: the source's thread must stay responsive to stop().
void IgtlLink::reconnect_when_due() {
  const double wait_s = next_try_s_ - now_s();
  if (wait_s > 0.0) {
    std::this_thread::sleep_for(std::chrono::duration<double>(std::min(wait_s, 0.05)));
    return;
  }
  next_try_s_ = now_s() + retry_s_;
  auto connection = IgtlConnection::connect(endpoint_, std::min(retry_s_, 0.5));
  if (!connection) return;
  connection_.emplace(std::move(*connection));
  if (on_connect_) {
    if (const Status sent = on_connect_(*connection_); !sent) {
      lose(sent.message());
      return;
    }
  }
  trouble_.clear();
}

std::vector<std::uint8_t> igtl_start_tracking_data(int interval_ms) {
  igtl::StartTrackingDataMessage::Pointer start = igtl::StartTrackingDataMessage::New();
  start->SetDeviceName("sonoshape");
  start->SetResolution(interval_ms);
  start->Pack();
  const auto* begin = static_cast<const std::uint8_t*>(start->GetPackPointer());
  return std::vector<std::uint8_t>(begin, begin + start->GetPackSize());
}

const char* to_string(IgtlDrop reason) {
  return reason == IgtlDrop::kDamaged ? "damaged" : "unsupported";
}

void IgtlDrops::count(IgtlDrop reason, const std::string& message) {
  std::size_t seen = 0;
  {
    std::lock_guard lock(mutex_);
    seen = counts_[to_string(reason)]++;
  }
  if (seen == 0)
    log_warning(peer_ + ": " + message + "; such messages are dropped and counted as '" +
                to_string(reason) + "' (said once)");
}

std::map<std::string, std::size_t> IgtlDrops::counts() const {
  std::lock_guard lock(mutex_);
  return counts_;
}

Result<std::optional<Eigen::Matrix4d>> decode_igtl_tracking_data(const IgtlMessage& message,
                                                                 const std::string& element) {
  const std::string what = "OpenIGTLink TDATA '" + message.device + "'";
  if (message.type != "TDATA") return Status::error(what + ": not a TDATA message");
  if (Status checked = check_body(message, what, 0, kMaxBody, "expected 70-byte elements");
      !checked)
    return checked;
  const std::size_t body = message.bytes.size() - IGTL_HEADER_SIZE;
  if (body % IGTL_TDATA_ELEMENT_SIZE != 0)
    return Status::error(what + ": a body of " + std::to_string(body) +
                         " bytes is not a whole number of 70-byte elements");
  // Read here rather than by igtl::TrackingDataMessage: 1.11's UnpackBody ends a name that fills
  // its 20 bytes with '\n' instead of a NUL and then takes its strlen, reading past the name
  // into uninitialised stack (found by fuzzing under valgrind). An element: name (20 bytes,
  // NUL-padded when shorter), type, reserved, 12 big-endian floats: the rotation's columns, then
  // the translation (mm).
  for (std::size_t at = IGTL_HEADER_SIZE; at < message.bytes.size();
       at += IGTL_TDATA_ELEMENT_SIZE) {
    const auto* name = reinterpret_cast<const char*>(message.bytes.data() + at);
    if (element != std::string(name, ::strnlen(name, IGTL_TDATA_LEN_NAME))) continue;
    const std::uint8_t* floats = message.bytes.data() + at + IGTL_TDATA_LEN_NAME + 2;
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) T(r, c) = body_f32(floats + 4 * (r + 3 * c));
    return std::optional<Eigen::Matrix4d>(T);
  }
  return std::optional<Eigen::Matrix4d>();
}

namespace {

bool is_integer_scalar(int type) {
  using M = igtl::ImageMessage;
  return type == M::TYPE_INT8 || type == M::TYPE_UINT8 || type == M::TYPE_INT16 ||
         type == M::TYPE_UINT16 || type == M::TYPE_INT32 || type == M::TYPE_UINT32;
}

// A label map's values into 8 bits; the first value outside 0..255 refuses it. The pixels stay
// in the sender's byte order (the image header's endian field: OpenIGTLink does not swap them).
Status copy_label_values(const igtl::ImageMessage::Pointer& image, GreyImage& out,
                         const std::string& what) {
  using M = igtl::ImageMessage;
  const int type = image->GetScalarType();
  const detail::IntegerSamples samples{
      image->GetScalarSize(),
      type == M::TYPE_INT8 || type == M::TYPE_INT16 || type == M::TYPE_INT32,
      image->GetEndian() != M::ENDIAN_LITTLE};
  const auto* data = static_cast<const std::uint8_t*>(image->GetScalarPointer());
  const auto bad = detail::narrow_to_8_bits(data, out.pixels.size(), samples, out.pixels.data());
  if (!bad) return Status::ok();
  const auto width = static_cast<std::size_t>(out.width);
  return Status::error(what + ": label value " +
                       std::to_string(detail::integer_sample(data, *bad, samples)) + " at pixel (" +
                       std::to_string(*bad % width) + ", " + std::to_string(*bad / width) +
                       "); label maps hold 0..255 (0 background, 1..254 organs, 255 or "
                       "--labels-unknown's value unknown): renumber the segments");
}

}  // namespace

Result<IgtlImage> decode_igtl_image(const IgtlMessage& message, IgtlDrop* why, IgtlPixels pixels) {
  igtl::ImageMessage::Pointer image = igtl::ImageMessage::New();
  const std::string what = "OpenIGTLink IMAGE '" + message.device + "'";
  if (message.type != "IMAGE")
    return refuse(IgtlDrop::kUnsupported, why, what + ": not an IMAGE message");
  if (Status unpacked = unpack(image, message, what, IGTL_IMAGE_HEADER_SIZE, kMaxBody,
                               "an IMAGE needs at least 72 (its image header)");
      !unpacked)
    return refuse(IgtlDrop::kDamaged, why, unpacked.message());
  // The scalar type first: the library's scalar sizes are a table indexed by it.
  const bool labels = pixels == IgtlPixels::kLabels;
  const int type = image->GetScalarType();
  if ((labels ? !is_integer_scalar(type) : type != igtl::ImageMessage::TYPE_UINT8) ||
      image->GetNumComponents() != 1)
    return refuse(IgtlDrop::kUnsupported, why,
                  what + ": scalar type " + std::to_string(type) + " with " +
                      std::to_string(image->GetNumComponents()) + " components; " +
                      (labels ? "label maps are read from integer pixels (8, 16 or 32 bits, "
                                "1 component)"
                              : "only 8-bit grey (uint8, 1 component) B-mode frames are read"));
  const std::uint64_t pixel_bytes = static_cast<std::uint64_t>(image->GetScalarSize());
  int size[3];
  int sub_size[3];
  int sub_offset[3];
  float spacing[3];
  image->GetDimensions(size);
  image->GetSubVolume(sub_size, sub_offset);
  image->GetSpacing(spacing);
  // The pixels the header declares (each size is 16 bits: no overflow) against those the body
  // holds after the image header: never trusted, never read past.
  const std::uint64_t declared = std::uint64_t(sub_size[0]) * std::uint64_t(sub_size[1]) *
                                 std::uint64_t(sub_size[2]) * pixel_bytes;
  const std::uint64_t held = message.bytes.size() - IGTL_HEADER_SIZE - IGTL_IMAGE_HEADER_SIZE;
  const std::string dimensions =
      std::to_string(size[0]) + "x" + std::to_string(size[1]) + "x" + std::to_string(size[2]);
  if (declared != held)
    return refuse(IgtlDrop::kDamaged, why,
                  what + ": the image header declares " + std::to_string(sub_size[0]) + "x" +
                      std::to_string(sub_size[1]) + "x" + std::to_string(sub_size[2]) +
                      " pixels (" + std::to_string(declared) + " bytes), the body holds " +
                      std::to_string(held) + " after the image header");
  if (sub_size[0] != size[0] || sub_size[1] != size[1] || sub_size[2] != size[2] ||
      sub_offset[0] != 0 || sub_offset[1] != 0 || sub_offset[2] != 0)
    return refuse(IgtlDrop::kUnsupported, why,
                  what + ": a sub-volume of " + dimensions + "; whole frames are read");
  if (size[2] != 1 || size[0] < 1 || size[1] < 1)
    return refuse(IgtlDrop::kUnsupported, why,
                  what + ": " + dimensions + "; a 2D frame (depth 1) is expected");
  IgtlImage out;
  out.image = GreyImage(size[0], size[1]);
  if (type == igtl::ImageMessage::TYPE_UINT8) {
    const auto* grey = static_cast<const std::uint8_t*>(image->GetScalarPointer());
    std::copy(grey, grey + out.image.pixels.size(), out.image.pixels.begin());
  } else if (Status copied = copy_label_values(image, out.image, what); !copied) {
    return refuse(IgtlDrop::kUnsupported, why, copied.message());
  }
  igtl::Matrix4x4 m;
  image->GetMatrix(m);
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) T(r, c) = m[r][c];
  // OpenIGTLink: unit axes, the spacing apart, origin at the image centre.
  T.col(0).head<3>() *= spacing[0];
  T.col(1).head<3>() *= spacing[1];
  T.col(2).head<3>() *= spacing[2];
  T.col(3).head<3>() -=
      T.col(0).head<3>() * 0.5 * (size[0] - 1) + T.col(1).head<3>() * 0.5 * (size[1] - 1);
  out.T_reference_image = T;
  out.spacing_mm[0] = spacing[0];
  out.spacing_mm[1] = spacing[1];
  return out;
}

Result<Eigen::Matrix4d> decode_igtl_transform(const IgtlMessage& message) {
  igtl::TransformMessage::Pointer transform = igtl::TransformMessage::New();
  const std::string what = "OpenIGTLink TRANSFORM '" + message.device + "'";
  if (message.type != "TRANSFORM") return Status::error(what + ": not a TRANSFORM message");
  if (Status unpacked = unpack(transform, message, what, IGTL_TRANSFORM_SIZE, IGTL_TRANSFORM_SIZE,
                               "a TRANSFORM has 48 (12 floats)");
      !unpacked)
    return unpacked;
  igtl::Matrix4x4 m;
  transform->GetMatrix(m);
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) T(r, c) = m[r][c];
  return T;
}

}  // namespace sonoshape::acquisition
