#include "sonoshape/publish/igtl_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>
#include <tuple>
#include <vector>

#include "igtlImageMessage.h"
#include "igtlMessageHeader.h"
#include "igtlPolyDataMessage.h"
#include "igtlStatusMessage.h"
#include "igtl_header.h"
#include "sonoshape/core/log.hpp"

namespace sonoshape::publish {
namespace {

// A packed message, shared by the queues of every client it goes to.
struct Packed {
  std::string key;  // type + device: a newer message with the same key replaces an unsent one
  std::vector<std::uint8_t> bytes;
};
using PackedPtr = std::shared_ptr<const Packed>;

// Bytes read from one client per turn of the server's loop: a client that sends without pause
// is served in turns with the others and the publisher, never for good.
constexpr std::size_t kMaxReadPerTurnBytes = 64 << 10;
// The body size field of a header (big-endian u64, after the version, type name, device name
// and timestamp), read whole: the 1.11 library's GetBodySizeToRead() is an int, which reads a
// 2^63-byte body as 0.
constexpr std::size_t kBodySizeOffset = 2 + 12 + 20 + 8;

template <typename Message>
PackedPtr pack(Message& message, const std::string& type) {
  igtl::TimeStamp::Pointer now = igtl::TimeStamp::New();
  now->GetTime();
  message->SetTimeStamp(now);
  message->Pack();
  auto packed = std::make_shared<Packed>();
  packed->key = type + "/" + message->GetDeviceName();
  const auto* begin = static_cast<const std::uint8_t*>(message->GetPackPointer());
  packed->bytes.assign(begin, begin + message->GetPackSize());
  return packed;
}

std::string device_name(const MeshSet::Entry& entry) {
  return entry.name.empty() ? "label_" + std::to_string(entry.label) : entry.name;
}

Result<PackedPtr> pack_polydata(const std::string& name, const TriangleMesh& mesh) {
  igtl::PolyDataPointArray::Pointer points = igtl::PolyDataPointArray::New();
  for (const Vec3& v : mesh.vertices) {
    if (!v.allFinite())
      return Status::error("OpenIGTLink: surface " + name + " has a non-finite vertex");
    points->AddPoint(static_cast<float>(v.x()), static_cast<float>(v.y()),
                     static_cast<float>(v.z()));
  }
  igtl::PolyDataCellArray::Pointer polygons = igtl::PolyDataCellArray::New();
  for (const auto& t : mesh.triangles) {
    if (std::max({t[0], t[1], t[2]}) >= mesh.vertices.size())
      return Status::error("OpenIGTLink: surface " + name + " has a triangle index out of range");
    igtlUint32 cell[3] = {t[0], t[1], t[2]};
    polygons->AddCell(3, cell);
  }
  igtl::PolyDataMessage::Pointer message = igtl::PolyDataMessage::New();
  message->SetDeviceName(name.c_str());
  // A POLYDATA without points crashes the unpacking of the 1.11 library (igtl_polydata_unpack)
  // in the client: a surface with no triangles (a vanished label) goes out as one point and no
  // cells, which viewers draw as nothing.
  if (mesh.triangles.empty()) {
    points = igtl::PolyDataPointArray::New();
    points->AddPoint(0.0f, 0.0f, 0.0f);
  }
  message->SetPoints(points);
  if (!mesh.triangles.empty()) message->SetPolygons(polygons);
  return pack(message, "POLYDATA");
}

Result<PackedPtr> pack_image(const std::string& name, const GreyImage& image,
                             const Eigen::Matrix4d& T_reference_image) {
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != static_cast<std::size_t>(image.width) * image.height)
    return Status::error("OpenIGTLink: cannot send an empty or inconsistent image");
  if (!T_reference_image.allFinite())
    return Status::error("OpenIGTLink: the image pose is not finite");
  const Eigen::Vector3d column_i = T_reference_image.block<3, 1>(0, 0);
  const Eigen::Vector3d column_j = T_reference_image.block<3, 1>(0, 1);
  const Eigen::Vector3d normal = column_i.cross(column_j);
  if (normal.norm() <= 1e-9 * column_i.norm() * column_j.norm() || normal.norm() == 0.0)
    return Status::error("OpenIGTLink: the image pose has parallel or zero pixel axes");
  // OpenIGTLink: unit direction columns, the spacing apart, and the origin at the image centre.
  const Eigen::Vector4d centre_px(0.5 * (image.width - 1), 0.5 * (image.height - 1), 0.0, 1.0);
  const Eigen::Vector3d centre_mm = (T_reference_image * centre_px).head<3>();
  igtl::Matrix4x4 matrix;
  igtl::IdentityMatrix(matrix);
  const Eigen::Vector3d axes[3] = {column_i.normalized(), column_j.normalized(),
                                   normal.normalized()};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) matrix[r][c] = static_cast<float>(axes[c][r]);
    matrix[r][3] = static_cast<float>(centre_mm[r]);
  }
  igtl::ImageMessage::Pointer message = igtl::ImageMessage::New();
  message->SetDeviceName(name.c_str());
  message->SetDimensions(image.width, image.height, 1);
  message->SetSpacing(static_cast<float>(column_i.norm()), static_cast<float>(column_j.norm()),
                      1.0f);
  message->SetScalarTypeToUint8();
  message->SetMatrix(matrix);
  message->AllocateScalars();
  std::memcpy(message->GetScalarPointer(), image.pixels.data(), image.pixels.size());
  return pack(message, "IMAGE");
}

PackedPtr pack_status(const std::string& name, const StatusReport& status) {
  igtl::StatusMessage::Pointer message = igtl::StatusMessage::New();
  message->SetDeviceName(name.c_str());
  message->SetCode(status.state == ScanState::kError ? igtl::StatusMessage::STATUS_UNKNOWN_ERROR
                                                     : igtl::StatusMessage::STATUS_OK);
  message->SetSubCode(static_cast<igtlInt64>(status.state));
  message->SetErrorName(std::string(to_string(status.state)).c_str());
  std::ostringstream text;
  text << "frames " << status.frames_received << ", dropped " << status.frames_dropped
       << ", slices " << status.slices << ", last update " << std::lround(status.total_ms) << " ms";
  if (!status.message.empty()) text << "; " << status.message;
  message->SetStatusString(text.str().c_str());
  return pack(message, "STATUS");
}

// A request's type and device name (its body, if any, is skipped).
struct Request {
  std::string type, name;
  bool operator<(const Request& other) const {
    return std::tie(type, name) < std::tie(other.type, other.name);
  }
};

// One connection. The queue is the publishers' and the server thread's (under Impl::mutex);
// the rest only the server thread touches.
struct Client {
  int fd = -1;
  std::string peer;  // "address:port", for the messages
  // Guarded by Impl::mutex: what is queued (the front possibly half sent), and whether the
  // server thread is sending the front right now (then it is not replaced or evicted).
  std::deque<PackedPtr> queue;
  std::size_t front_sent = 0;  // bytes of queue.front() already written
  bool sending = false;
  // The server thread's: the header being read, and the body bytes still to skip.
  std::array<std::uint8_t, IGTL_HEADER_SIZE> header{};
  std::size_t header_have = 0;
  std::uint64_t body_left = 0;
  bool closing = false;
};

std::string peer_of(const sockaddr_in& address) {
  char text[INET_ADDRSTRLEN] = "?";
  ::inet_ntop(AF_INET, &address.sin_addr, text, sizeof text);
  return std::string(text) + ":" + std::to_string(ntohs(address.sin_port));
}

std::uint64_t body_size_of(const std::array<std::uint8_t, IGTL_HEADER_SIZE>& header) {
  std::uint64_t size = 0;
  for (std::size_t i = 0; i < 8; ++i) size = (size << 8) | header[kBodySizeOffset + i];
  return size;
}

// A fixed-width, possibly unterminated name field of a header; bytes that are not printable
// ASCII shown as '?', so that a peer's noise never reaches the terminal as control codes.
std::string field_text(const std::uint8_t* field, std::size_t width) {
  const auto* begin = reinterpret_cast<const char*>(field);
  std::string text(begin, std::find(begin, begin + width, '\0'));
  for (char& c : text)
    if (c < 0x20 || c > 0x7e) c = '?';
  return text;
}

}  // namespace

struct IgtlServer::Impl {
  IgtlServerOptions options;
  int listen_fd = -1;
  int wake_fd = -1;
  int port = 0;
  std::thread thread;
  std::atomic<bool> stopping{false};

  // Guards everything below and each client's queue: held only to queue or take a message,
  // never across a system call or a parse, so that publishing never waits on a client.
  mutable std::mutex mutex;
  std::vector<std::unique_ptr<Client>> clients;  // added and removed by the server thread only
  std::map<std::string, PackedPtr> surfaces;     // by device name: the newest of every label
  std::vector<std::string> surface_order;        // device names in label order
  PackedPtr image, status;
  IgtlServerStats stats;

  ~Impl() {
    stop();
    if (listen_fd >= 0) ::close(listen_fd);
    if (wake_fd >= 0) ::close(wake_fd);
  }

  void stop() {
    if (!thread.joinable()) return;
    stopping = true;
    wake();
    thread.join();
  }

  void wake() const {
    const std::uint64_t one = 1;
    [[maybe_unused]] const auto written = ::write(wake_fd, &one, sizeof one);
  }

  // Queues `message` for `client` (mutex held): replaces an unsent one of the same device, and
  // evicts the oldest unsent one beyond the bound.
  void enqueue(Client& client, const PackedPtr& message) {
    const std::size_t first_unsent = client.front_sent > 0 || client.sending ? 1 : 0;
    for (std::size_t k = first_unsent; k < client.queue.size(); ++k) {
      if (client.queue[k]->key == message->key) {
        client.queue[k] = message;
        ++stats.messages_dropped;
        return;
      }
    }
    client.queue.push_back(message);
    while (client.queue.size() > options.max_queued_messages + first_unsent) {
      client.queue.erase(client.queue.begin() + static_cast<std::ptrdiff_t>(first_unsent));
      ++stats.messages_dropped;
    }
  }

  void broadcast(const std::vector<PackedPtr>& messages) {
    {
      std::lock_guard lock(mutex);
      for (auto& client : clients)
        for (const PackedPtr& m : messages) enqueue(*client, m);
    }
    wake();
  }

  void send_state(Client& client) {
    for (const std::string& name : surface_order) enqueue(client, surfaces.at(name));
    if (image) enqueue(client, image);
    if (status) enqueue(client, status);
  }

  // Accepts what is pending; beyond max_clients a connection is closed at once (said once).
  void accept_clients() {
    while (true) {
      sockaddr_in address{};
      socklen_t length = sizeof address;
      const int fd = ::accept4(listen_fd, reinterpret_cast<sockaddr*>(&address), &length,
                               SOCK_NONBLOCK | SOCK_CLOEXEC);
      if (fd < 0) return;  // EAGAIN: none left; other errors: try again on the next poll
      std::unique_lock lock(mutex);
      if (clients.size() >= options.max_clients) {
        const bool first = stats.clients_refused++ == 0;
        lock.unlock();
        ::close(fd);
        if (first)
          log_warning("OpenIGTLink " + options.option + ": " + std::to_string(options.max_clients) +
                      " clients connected, the most served at once; refused " + peer_of(address) +
                      " (said once; later refusals are counted)");
        continue;
      }
      lock.unlock();
      const int one = 1;
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      auto client = std::make_unique<Client>();
      client->fd = fd;
      client->peer = peer_of(address);
      lock.lock();
      send_state(*client);
      clients.push_back(std::move(client));
      ++stats.clients_accepted;
    }
  }

  // Closes `client` for a message it should not have sent, saying so.
  void expel(Client& client, const std::string& why) {
    client.closing = true;
    {
      std::lock_guard lock(mutex);
      ++stats.clients_expelled;
    }
    log_warning("OpenIGTLink " + options.option + ": client " + client.peer + " " + why +
                "; closed its connection");
  }

  // Parses `n` bytes from `client` into whole requests (server thread, no lock): only a header
  // is kept; a body is counted down and its bytes dropped as they come.
  void parse(Client& client, const std::uint8_t* data, std::size_t n, std::vector<Request>& out) {
    while (!client.closing) {
      if (client.header_have < IGTL_HEADER_SIZE) {
        const std::size_t take = std::min(n, IGTL_HEADER_SIZE - client.header_have);
        std::memcpy(client.header.data() + client.header_have, data, take);
        client.header_have += take;
        data += take;
        n -= take;
        if (client.header_have < IGTL_HEADER_SIZE) return;
        client.body_left = body_size_of(client.header);
        if (client.body_left > kIgtlMaxClientBodyBytes)
          return expel(client, "announced a " + field_text(client.header.data() + 2, 12) +
                                   " message with a body of " + std::to_string(client.body_left) +
                                   " bytes (the header's body size; at most " +
                                   std::to_string(kIgtlMaxClientBodyBytes) + " are read)");
      }
      const auto skipped = static_cast<std::size_t>(std::min<std::uint64_t>(n, client.body_left));
      data += skipped;
      n -= skipped;
      client.body_left -= skipped;
      if (client.body_left > 0) return;
      out.push_back(
          {field_text(client.header.data() + 2, 12), field_text(client.header.data() + 14, 20)});
      client.header_have = 0;
      if (n == 0) return;
    }
  }

  // Reads up to kMaxReadPerTurnBytes from `client` (server thread, no lock): its requests.
  std::vector<Request> read_from(Client& client) {
    std::vector<Request> requests;
    std::uint8_t buffer[4096];
    std::size_t read = 0;
    while (read < kMaxReadPerTurnBytes && !client.closing) {
      const ssize_t n = ::recv(client.fd, buffer, sizeof buffer, MSG_DONTWAIT);
      if (n > 0) {
        read += static_cast<std::size_t>(n);
        parse(client, buffer, static_cast<std::size_t>(n), requests);
        continue;
      }
      if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
      if (n < 0 && errno == EINTR) continue;
      client.closing = true;  // closed by the peer, or reset
    }
    return requests;
  }

  // Queues the answers to `requests` (takes the lock): a burst of the same request is answered
  // once, which is all a client can see anyway (a newer copy replaces a queued one).
  void answer(Client& client, std::vector<Request> requests) {
    if (requests.empty()) return;
    std::sort(requests.begin(), requests.end());
    requests.erase(
        std::unique(requests.begin(), requests.end(),
                    [](const Request& a, const Request& b) { return !(a < b) && !(b < a); }),
        requests.end());
    std::lock_guard lock(mutex);
    for (const Request& request : requests) {
      if (request.type == "GET_POLYDATA") {
        if (const auto it = surfaces.find(request.name); it != surfaces.end()) {
          enqueue(client, it->second);
        } else {
          for (const std::string& n : surface_order) enqueue(client, surfaces.at(n));
        }
      } else if (request.type == "GET_IMAGE" && image) {
        enqueue(client, image);
      } else if (request.type == "GET_STATUS" && status) {
        enqueue(client, status);
      } else {
        continue;  // other messages (Slicer's own STATUS, capabilities) need no answer
      }
      ++stats.requests_answered;
    }
  }

  // Sends what is queued for `client` until the socket is full. The send itself runs without
  // the lock: the front is marked as being sent, so that no publisher replaces it meanwhile.
  void write_to(Client& client) {
    while (!client.closing) {
      PackedPtr front;
      std::size_t offset = 0;
      {
        std::lock_guard lock(mutex);
        if (client.queue.empty()) return;
        front = client.queue.front();
        offset = client.front_sent;
        client.sending = true;
      }
      const ssize_t n = ::send(client.fd, front->bytes.data() + offset,
                               front->bytes.size() - offset, MSG_DONTWAIT | MSG_NOSIGNAL);
      const int error = errno;
      std::lock_guard lock(mutex);
      client.sending = false;
      if (n < 0) {
        if (error == EINTR) continue;
        if (error != EAGAIN && error != EWOULDBLOCK) client.closing = true;
        return;
      }
      client.front_sent += static_cast<std::size_t>(n);
      if (client.front_sent == front->bytes.size()) {
        client.queue.pop_front();
        client.front_sent = 0;
        ++stats.messages_sent;
      }
    }
  }

  bool queues_empty() const {
    return std::all_of(clients.begin(), clients.end(),
                       [](const auto& c) { return c->queue.empty() || c->closing; });
  }

  void loop() {
    using Clock = std::chrono::steady_clock;
    std::optional<Clock::time_point> linger_until;
    while (true) {
      std::vector<pollfd> fds;
      {
        std::lock_guard lock(mutex);
        if (stopping && !linger_until)
          linger_until = Clock::now() + std::chrono::milliseconds(options.linger_ms);
        if (linger_until && (queues_empty() || Clock::now() >= *linger_until)) break;
        fds.push_back({wake_fd, POLLIN, 0});
        fds.push_back({listen_fd, static_cast<short>(stopping ? 0 : POLLIN), 0});
        for (const auto& c : clients)
          fds.push_back({c->fd, static_cast<short>(POLLIN | (c->queue.empty() ? 0 : POLLOUT)), 0});
      }
      if (::poll(fds.data(), fds.size(), 100) < 0 && errno != EINTR) break;
      if (fds[0].revents & POLLIN) {
        std::uint64_t count = 0;
        [[maybe_unused]] const auto got = ::read(wake_fd, &count, sizeof count);
      }
      if (fds[1].revents & POLLIN) accept_clients();
      // Only this thread adds or removes clients: it reads `clients` without the lock.
      // Clients accepted during this poll are not in `fds`: they are served from the next one.
      for (std::size_t k = 2; k < fds.size(); ++k) {
        Client& client = *clients[k - 2];
        if (fds[k].revents & (POLLIN | POLLHUP | POLLERR)) answer(client, read_from(client));
        write_to(client);
      }
      std::vector<int> closed;
      {
        std::lock_guard lock(mutex);
        std::erase_if(clients, [&closed](const std::unique_ptr<Client>& c) {
          if (!c->closing) return false;
          closed.push_back(c->fd);
          return true;
        });
        stats.clients = clients.size();
      }
      for (const int fd : closed) ::close(fd);
    }
    std::lock_guard lock(mutex);
    for (const auto& c : clients) ::close(c->fd);
    clients.clear();
    stats.clients = 0;
  }
};

Result<IgtlServer> IgtlServer::start(const IgtlServerOptions& options) {
  const std::string where = options.host + ":" + std::to_string(options.port);
  if (options.max_queued_messages < 1)
    return Status::error("OpenIGTLink: the per-client queue must hold at least 1 message");
  if (options.max_clients < 1)
    return Status::error("OpenIGTLink: the server must serve at least 1 client");
  if (options.port < 0 || options.port > 65535)
    return Status::error(options.option + " " + std::to_string(options.port) +
                         ": not a TCP port (0 to 65535; 0 picks a free one)");
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(options.port));
  if (::inet_pton(AF_INET, options.host.c_str(), &address.sin_addr) != 1)
    return Status::error(
        options.option + " " + where + ": '" + options.host +
        "' is not an IPv4 address (use 127.0.0.1, or 0.0.0.0 for every interface)");
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->listen_fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  impl->wake_fd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (impl->listen_fd < 0 || impl->wake_fd < 0)
    return Status::error("OpenIGTLink: cannot create a socket: " +
                         std::string(std::strerror(errno)));
  const int one = 1;
  ::setsockopt(impl->listen_fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(impl->listen_fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0 ||
      ::listen(impl->listen_fd, 8) != 0) {
    const int error = errno;
    return Status::error(options.option + " " + where + ": cannot listen (" + std::strerror(error) +
                         ")" +
                         (error == EADDRINUSE ? "; another program serves this port: pick "
                                                "another, or 0 for a free one"
                                              : ""));
  }
  socklen_t length = sizeof address;
  ::getsockname(impl->listen_fd, reinterpret_cast<sockaddr*>(&address), &length);
  impl->port = ntohs(address.sin_port);
  Impl* raw = impl.get();
  impl->thread = std::thread([raw] { raw->loop(); });
  return IgtlServer(std::move(impl));
}

IgtlServer::IgtlServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
IgtlServer::IgtlServer(IgtlServer&&) noexcept = default;
IgtlServer& IgtlServer::operator=(IgtlServer&&) noexcept = default;
IgtlServer::~IgtlServer() = default;

Status IgtlServer::publish_meshes(const MeshSet& meshes) {
  std::vector<PackedPtr> messages;
  std::vector<std::string> names;
  for (const MeshSet::Entry& entry : meshes.meshes) {
    names.push_back(device_name(entry));
    Result<PackedPtr> packed = pack_polydata(names.back(), entry.mesh);
    if (!packed) return packed.status();
    messages.push_back(*packed);
  }
  {
    std::lock_guard lock(impl_->mutex);
    // A label sent before and missing now: an empty surface, so that viewers clear it.
    for (const std::string& old : impl_->surface_order)
      if (std::find(names.begin(), names.end(), old) == names.end())
        messages.push_back(*pack_polydata(old, TriangleMesh{}));
    impl_->surfaces.clear();
    impl_->surface_order = names;
    for (std::size_t k = 0; k < names.size(); ++k) impl_->surfaces[names[k]] = messages[k];
  }
  impl_->broadcast(messages);
  return Status::ok();
}

Status IgtlServer::publish_image(const GreyImage& image, const Eigen::Matrix4d& T_reference_image) {
  Result<PackedPtr> packed = pack_image(impl_->options.image_device, image, T_reference_image);
  if (!packed) return packed.status();
  {
    std::lock_guard lock(impl_->mutex);
    impl_->image = *packed;
  }
  impl_->broadcast({*packed});
  return Status::ok();
}

Status IgtlServer::publish_status(const StatusReport& status) {
  if (status.state == ScanState::kError && status.message.empty())
    return Status::error("OpenIGTLink: an error status needs a message");
  PackedPtr packed = pack_status(impl_->options.status_device, status);
  {
    std::lock_guard lock(impl_->mutex);
    impl_->status = packed;
  }
  impl_->broadcast({packed});
  return Status::ok();
}

int IgtlServer::port() const { return impl_->port; }

IgtlServerStats IgtlServer::stats() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->stats;
}

}  // namespace sonoshape::publish
