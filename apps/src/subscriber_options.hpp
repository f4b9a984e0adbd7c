#pragma once
// The mesh-stream subscriber's options, shared by `listen` and `view`: one name, one meaning, one
// default and one range in both (both follow a stream as docs/formats/mesh-stream.md's late
// joiner). `--receive-hwm` is listen's alone: a recorder wants every message, while the view
// keeps the small queue of a reader that only wants the newest state
// (publish::SubscriberOptions::receive_hwm).
#include <CLI/CLI.hpp>
#include <filesystem>
#include <string>

#include "option_checks.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/publish/curve.hpp"
#include "sonoshape/publish/subscriber.hpp"

namespace sonoshape::apps {

/// The PUB endpoint followed unless the command line names another: where `scan --view`
/// publishes by default.
inline constexpr const char* kDefaultStreamEndpoint = "tcp://127.0.0.1:5556";

/// What the subscriber options hold, as given.
struct StreamFollowOptions {
  std::string endpoint = kDefaultStreamEndpoint;
  std::string snapshot;  ///< empty: the PUB port + 1 (unless no_snapshot)
  bool no_snapshot = false;
  std::filesystem::path server_key;  ///< the publisher's CURVE public key file; empty: none
  double duration_s = 0.0;           ///< 0: until Ctrl-C (SIGINT or SIGTERM)
};

/// Registers the endpoint (positional), --snapshot, --no-snapshot, --server-key and --duration.
inline void add_subscriber_options(CLI::App& app, StreamFollowOptions& options) {
  app.add_option("endpoint", options.endpoint, "PUB endpoint of the mesh stream")
      ->capture_default_str();
  app.add_option("--snapshot", options.snapshot,
                 "Snapshot endpoint, to join a running scan with its current meshes and status "
                 "(default: the PUB port + 1)");
  app.add_flag("--no-snapshot", options.no_snapshot,
               "Do not ask for a snapshot: only what is published from now on (and no wait for "
               "the publisher's answer)")
      ->excludes("--snapshot");
  app.add_option("--server-key", options.server_key,
                 "The publisher's CURVE public key file (NAME.pub of its --curve-secret-key "
                 "NAME.key): needed to follow an encrypted stream");
  app.add_option("--duration", options.duration_s,
                 "Stop after S seconds, the wait for the publisher included (default: at Ctrl-C)")
      ->check(kPositiveNumber);
}

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

/// The subscription the options ask for: the endpoint, the snapshot endpoint (--snapshot, the
/// PUB port + 1, or none with --no-snapshot) and the publisher's key read from --server-key.
/// Errors: a key file that cannot be read or is not a CURVE public key, and an endpoint whose
/// snapshot endpoint cannot be told (not tcp://HOST:PORT) when --snapshot is not given.
inline Result<publish::SubscriberOptions> subscription_of(const StreamFollowOptions& options) {
  publish::SubscriberOptions out;
  out.endpoint = options.endpoint;
  if (!options.server_key.empty()) {
    Result<std::string> key = publish::read_curve_key(options.server_key, "public");
    if (!key) return Status::error("--server-key: " + key.message());
    out.server_public_key = *key;
  }
  if (!options.no_snapshot) {
    Result<std::string> snapshot = options.snapshot.empty() ? next_port_endpoint(options.endpoint)
                                                            : Result<std::string>(options.snapshot);
    if (!snapshot) return snapshot.status();
    out.snapshot_endpoint = *snapshot;
  }
  return out;
}

}  // namespace sonoshape::apps
