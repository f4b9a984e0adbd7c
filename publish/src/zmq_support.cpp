#include "zmq_support.hpp"

#include <array>
#include <cerrno>
#include <charconv>

namespace sonoshape::publish::detail {

std::string endpoint_error(const zmq::error_t& error, const std::string& action,
                           const std::string& role, const std::string& endpoint,
                           const std::string& option) {
  const std::string what = "cannot " + action + " " + role + " at " + endpoint + ": ";
  switch (error.num()) {
    case EADDRINUSE:
      return what +
             "the address is already in use (another sonoshape or another program is bound "
             "there); stop it, or choose a free port (" +
             option + ")";
    case EINVAL:
    case EPROTONOSUPPORT:
    case ENOCOMPATPROTO:
      return what +
             "not a valid ZeroMQ endpoint; write tcp://HOST:PORT (for example "
             "tcp://127.0.0.1:5556), ipc:///path/to/socket or inproc://name (" +
             option + ")";
    case EADDRNOTAVAIL:
    case ENODEV:
      return what +
             "the host is not an address of this machine; use 127.0.0.1 (this machine only), * "
             "(every interface) or the address of one of its interfaces (" +
             option + ")";
    case EACCES:
      return what + "permission denied (ports below 1024 need privileges); choose another (" +
             option + ")";
    default:
      return what + error.what() + "; check the endpoint (" + option + ")";
  }
}

Status check_tcp_port(const std::string& endpoint, const std::string& role,
                      const std::string& option) {
  const std::string scheme = "tcp://";
  if (endpoint.compare(0, scheme.size(), scheme) != 0) return Status::ok();
  const std::size_t colon = endpoint.rfind(':');
  // No port at all: ZeroMQ refuses it, and endpoint_error says how to write one.
  if (colon < scheme.size()) return Status::ok();
  const std::string port = endpoint.substr(colon + 1);
  if (port == "*") return Status::ok();
  int number = -1;
  const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), number);
  if (!port.empty() && ec == std::errc() && end == port.data() + port.size() && number >= 0 &&
      number <= 65535)
    return Status::ok();
  // ZeroMQ takes the port modulo 65536: tcp://127.0.0.1:99999 would bind 34463, silently.
  return Status::error("cannot use " + endpoint + " for " + role + ": '" + port +
                       "' is not a TCP port (0 to 65535, or * for any free one); write "
                       "tcp://HOST:PORT, e.g. tcp://127.0.0.1:5556 (" +
                       option + ")");
}

std::string bound_endpoint(zmq::socket_t& socket, const std::string& requested) {
  std::string last = socket.get(zmq::sockopt::last_endpoint);
  // ZeroMQ reports tcp://127.0.0.1:* as the resolved port; ipc and inproc come back unchanged.
  return last.empty() ? requested : last;
}

Result<std::string> next_port_endpoint(const std::string& endpoint, const std::string& option) {
  const std::string scheme = "tcp://";
  const std::size_t colon = endpoint.rfind(':');
  int port = 0;
  if (endpoint.compare(0, scheme.size(), scheme) == 0 && colon != std::string::npos &&
      colon > scheme.size()) {
    const char* first = endpoint.data() + colon + 1;
    const char* last = endpoint.data() + endpoint.size();
    const auto [end, ec] = std::from_chars(first, last, port);
    if (ec == std::errc() && end == last && port > 0 && port < 65535)
      return endpoint.substr(0, colon + 1) + std::to_string(port + 1);
  }
  return Status::error("no default snapshot endpoint for " + endpoint +
                       ": the default is the PUB port + 1, which needs tcp://HOST:PORT; name "
                       "the snapshot endpoint (" +
                       option + ")");
}

bool send_frames(zmq::socket_t& socket, const std::shared_ptr<const Frames>& frames,
                 const Frames& envelope) {
  const std::size_t total = envelope.size() + frames->size();
  for (std::size_t k = 0; k < total; ++k) {
    const bool more = k + 1 < total;
    const zmq::send_flags flags =
        zmq::send_flags::dontwait | (more ? zmq::send_flags::sndmore : zmq::send_flags::none);
    zmq::message_t message;
    if (k < envelope.size()) {
      message.rebuild(envelope[k].data(), envelope[k].size());
    } else {
      // Zero copy: the message keeps the shared frames alive until ZeroMQ has sent them.
      const std::string& frame = (*frames)[k - envelope.size()];
      auto* keep = new std::shared_ptr<const Frames>(frames);
      message.rebuild(
          const_cast<char*>(frame.data()), frame.size(),
          [](void*, void* hint) { delete static_cast<std::shared_ptr<const Frames>*>(hint); },
          keep);
    }
    // ZeroMQ queues all parts or none: only the first can fail, later ones always go.
    if (!socket.send(message, flags)) return false;
  }
  return true;
}

bool receive_frames(zmq::socket_t& socket, Frames& frames) {
  frames.clear();
  zmq::message_t part;
  if (!socket.recv(part, zmq::recv_flags::dontwait)) return false;
  frames.emplace_back(part.to_string());
  while (part.more()) {
    // The rest of a multipart message is delivered together with its first part.
    (void)socket.recv(part, zmq::recv_flags::none);
    frames.emplace_back(part.to_string());
  }
  return true;
}

bool wait_readable(zmq::socket_t& socket, std::chrono::milliseconds timeout) {
  std::array<zmq::pollitem_t, 1> items{{{socket.handle(), 0, ZMQ_POLLIN, 0}}};
  try {
    zmq::poll(items, timeout);
  } catch (const zmq::error_t& e) {
    // A signal ended the wait early: the caller sees a timeout and checks its own flags.
    if (e.num() == EINTR) return false;
    throw;
  }
  return (items[0].revents & ZMQ_POLLIN) != 0;
}

}  // namespace sonoshape::publish::detail
