// `sonoshape view`: follows a live mesh stream and shows it in the browser (docs/viewer.md).
#include <CLI/CLI.hpp>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <iostream>
#include <memory>
#include <thread>

#include "commands.hpp"
#include "option_checks.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/publish/curve.hpp"
#include "view_options.hpp"
#ifdef SONOSHAPE_WITH_VIEWER
#include "sonoshape/publish/stream_view.hpp"
#endif

namespace sonoshape::apps {
namespace {

#ifdef SONOSHAPE_WITH_VIEWER
volatile std::sig_atomic_t g_view_stop = 0;

extern "C" void on_view_stop(int signal) { g_view_stop = signal; }
#endif

struct ViewCommandOptions {
  std::string endpoint = "tcp://127.0.0.1:5556";
  std::string snapshot;  // empty: the PUB port + 1
  bool no_snapshot = false;
  std::filesystem::path server_key;  // --server-key: the publisher's CURVE public key file
  std::string http = kDefaultViewAddress;
  std::filesystem::path web_root = SONOSHAPE_VIEWER_DIR;
  double duration_s = 0.0;  // 0: until Ctrl-C
};

int run_view(const ViewCommandOptions& options) {
#ifdef SONOSHAPE_WITH_VIEWER
  publish::StreamViewOptions view;
  view.stream.endpoint = options.endpoint;
  if (!options.server_key.empty()) {
    Result<std::string> key = publish::read_curve_key(options.server_key, "public");
    if (!key) {
      std::cerr << "error: --server-key: " << key.message() << '\n';
      return 1;
    }
    view.stream.server_public_key = *key;
  }
  if (!options.no_snapshot) {
    Result<std::string> snapshot = options.snapshot.empty() ? next_port_endpoint(options.endpoint)
                                                            : Result<std::string>(options.snapshot);
    if (!snapshot) {
      std::cerr << "error: " << snapshot.message() << '\n';
      return 1;
    }
    view.stream.snapshot_endpoint = *snapshot;
  }
  view.server.http = options.http;
  view.server.web_root = options.web_root;
  Result<publish::StreamView> started = publish::StreamView::start(view);
  if (!started) {
    std::cerr << "error: " << started.message() << '\n';
    return 1;
  }
  g_view_stop = 0;
  std::signal(SIGINT, on_view_stop);
  std::signal(SIGTERM, on_view_stop);
  log_info(
      "view: open " + started->url() + " in a browser (following " + options.endpoint +
      (view.stream.snapshot_endpoint.empty() ? "" : ", snapshot " + view.stream.snapshot_endpoint) +
      "; Ctrl-C stops)");
  const auto start = std::chrono::steady_clock::now();
  while (!g_view_stop) {
    if (options.duration_s > 0.0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >=
            options.duration_s)
      break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  log_info("view: relayed " + std::to_string(started->messages_relayed()) + " messages, " +
           std::to_string(started->server().messages_replaced()) +
           " replaced by newer ones before a page took them");
  return 0;
#else
  (void)options;
  std::cerr << "error: " << kViewerMissing << '\n';
  return 1;
#endif
}

}  // namespace

CommandRunner add_view_command(CLI::App& app) {
  auto options = std::make_shared<ViewCommandOptions>();
  app.add_option("endpoint", options->endpoint, "PUB endpoint of the mesh stream")
      ->capture_default_str();
  app.add_option("--snapshot", options->snapshot,
                 "Snapshot endpoint, to join a running scan with its current surfaces (default: "
                 "the PUB port + 1)");
  app.add_flag("--no-snapshot", options->no_snapshot,
               "Do not ask for a snapshot: show only what is published from now on");
  app.add_option("--server-key", options->server_key,
                 "The publisher's CURVE public key file (NAME.pub of its --curve-secret-key "
                 "NAME.key): needed to show an encrypted stream");
  app.add_option("--http", options->http,
                 "HOST:PORT the page is served on (loopback unless you name another interface; "
                 "port 0 picks a free one)")
      ->capture_default_str();
  app.add_option("--web-root", options->web_root,
                 "The page's folder (viewer/ of the sources, with three.js installed by npm ci)")
      ->capture_default_str();
  app.add_option("--duration", options->duration_s, "Stop after S seconds (default: at Ctrl-C)")
      ->check(kPositiveNumber);
  return [options] { return run_view(*options); };
}

}  // namespace sonoshape::apps
