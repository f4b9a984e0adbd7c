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
#include "subscriber_options.hpp"
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
  StreamFollowOptions stream;
  std::string http = kDefaultViewAddress;
  std::filesystem::path web_root = SONOSHAPE_VIEWER_DIR;
};

int run_view(const ViewCommandOptions& options) {
#ifdef SONOSHAPE_WITH_VIEWER
  Result<publish::SubscriberOptions> subscription = subscription_of(options.stream);
  if (!subscription) {
    std::cerr << "error: " << subscription.message() << '\n';
    return 1;
  }
  publish::StreamViewOptions view;
  view.stream = std::move(*subscription);
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
      "view: open " + started->url() + " in a browser (following " + options.stream.endpoint +
      (view.stream.snapshot_endpoint.empty() ? "" : ", snapshot " + view.stream.snapshot_endpoint) +
      "; Ctrl-C stops)");
  const auto start = std::chrono::steady_clock::now();
  while (!g_view_stop) {
    if (options.stream.duration_s > 0.0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >=
            options.stream.duration_s)
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
  add_subscriber_options(app, options->stream);
  app.add_option("--http", options->http,
                 "HOST:PORT the page is served on (loopback unless you name another interface; "
                 "port 0 picks a free one)")
      ->capture_default_str();
  app.add_option("--web-root", options->web_root,
                 "The page's folder (viewer/ of the sources, with three.js installed by "
                 "scripts/install-deps)")
      ->capture_default_str();
  return [options] { return run_view(*options); };
}

}  // namespace sonoshape::apps
