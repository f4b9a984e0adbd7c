#pragma once
// ZeroMQ helpers shared by the publisher and the subscriber (internal: ZeroMQ types stay in src/).
#include <chrono>
#include <memory>
#include <string>
#include <zmq.hpp>

#include "sonoshape/core/status.hpp"
#include "sonoshape/publish/mesh_stream.hpp"

namespace sonoshape::publish::detail {

/// What a bind or connect failure means and how to fix it. `role` names the socket ("the mesh
/// stream (PUB)"), `option` the command-line option that sets its endpoint.
std::string endpoint_error(const zmq::error_t& error, const std::string& action,
                           const std::string& role, const std::string& endpoint,
                           const std::string& option);

/// Ok unless `endpoint` is tcp:// with a port that is not 0..65535 or `*` (ZeroMQ would take it
/// modulo 65536); the error names the endpoint, its `role` and the `option` that set it.
Status check_tcp_port(const std::string& endpoint, const std::string& role,
                      const std::string& option);

/// The endpoint a socket actually bound (a wildcard port "tcp://127.0.0.1:*" resolved).
std::string bound_endpoint(zmq::socket_t& socket, const std::string& requested);

/// "tcp://HOST:PORT+1" for a tcp endpoint with a numeric port; an error for other transports,
/// which have no port to count from.
Result<std::string> next_port_endpoint(const std::string& endpoint, const std::string& option);

/// Sends `frames` behind `envelope` as one multipart message without blocking: true when queued,
/// false when the socket dropped it (high-water mark, no peer). Frames are shared, not copied.
bool send_frames(zmq::socket_t& socket, const std::shared_ptr<const Frames>& frames,
                 const Frames& envelope = {});

/// Receives one whole multipart message if one is waiting (never blocks); false when none is.
bool receive_frames(zmq::socket_t& socket, Frames& frames);

/// Waits until `socket` has a message, at most `timeout` (negative: forever). False on timeout or
/// when a signal interrupts the wait.
bool wait_readable(zmq::socket_t& socket, std::chrono::milliseconds timeout);

}  // namespace sonoshape::publish::detail
