#pragma once
// What `sonoshape view` and `scan --view` share.
#include <string>

#include "sonoshape/core/status.hpp"

namespace sonoshape::apps {

/// Where the page is served unless --http / --view says otherwise: loopback only.
inline constexpr const char* kDefaultViewAddress = "127.0.0.1:8080";

/// Why the browser view is not there, and how to get it.
inline constexpr const char* kViewerMissing =
    "this sonoshape was built without the browser view: install libboost-dev (Boost.Beast) and "
    "configure with -DSONOSHAPE_WITH_VIEWER=ON";

/// "tcp://HOST:PORT+1" for a tcp endpoint with a numeric port (where a publisher's snapshot
/// server listens by default); an error naming --snapshot for other endpoints.
inline Result<std::string> next_port_endpoint(const std::string& endpoint) {
  const std::size_t colon = endpoint.rfind(':');
  const std::string port = colon == std::string::npos ? "" : endpoint.substr(colon + 1);
  const bool numeric = !port.empty() && port.size() <= 5 &&
                       port.find_first_not_of("0123456789") == std::string::npos;
  if (endpoint.rfind("tcp://", 0) != 0 || !numeric || std::stoul(port) >= 65535)
    return Status::error("cannot tell the snapshot endpoint of " + endpoint +
                         ": give it with --snapshot, or --no-snapshot");
  return endpoint.substr(0, colon + 1) + std::to_string(std::stoul(port) + 1);
}

}  // namespace sonoshape::apps
