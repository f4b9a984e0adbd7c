// `sonoshape listen`: subscribes to a live mesh stream, checks every message against
// docs/formats/mesh-stream.md, and records what it receives: the newest mesh of every label as
// PLY, every header as a JSON line, and a summary (counts, invalid messages, seq gaps).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "commands.hpp"
#include "option_checks.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/publish/subscriber.hpp"
#include "subscriber_options.hpp"

namespace sonoshape::apps {
namespace {

using nlohmann::ordered_json;

// How often the loop looks at the clock and the signal flag while no message comes.
constexpr std::chrono::milliseconds kPollInterval{100};
// How long to wait for the publisher and its snapshot (unless --no-snapshot).
constexpr int kSnapshotTimeoutMs = 5000;

volatile std::sig_atomic_t g_stop_signal = 0;

extern "C" void on_stop_signal(int signal) { g_stop_signal = signal; }

struct ListenOptions {
  StreamFollowOptions stream;
  std::filesystem::path output;
  std::uint64_t count = 0;  // 0: no limit
  int slow_ms = 0;
  bool until_idle = false;
  // A recorder wants every message: a deep receive queue lets ZeroMQ's I/O thread drain the
  // publisher's small per-subscriber queue even while this process is briefly starved of CPU.
  int receive_hwm = 1000;
};

// What the summary reports.
struct Tally {
  std::uint64_t messages = 0;
  std::uint64_t invalid = 0;
  std::uint64_t seq_gaps = 0;
  std::uint64_t missed = 0;  // messages the gaps skipped
  std::uint64_t write_errors = 0;
  std::uint64_t slices = 0;
  std::uint64_t statuses = 0;
  std::uint64_t frame_images = 0;  // `frame` messages (B-mode previews), not written
  std::optional<std::uint64_t> first_seq;
  std::optional<std::uint64_t> last_seq;
  std::optional<std::uint64_t> snapshot_seq;
  std::string scan;
  std::vector<std::string> scans;
  std::map<int, std::uint64_t> meshes;
  // Mesh messages of labels beyond the first kMaxStreamLabels of the run: not written.
  std::uint64_t meshes_over_label_limit = 0;
  std::optional<std::string> last_state;
  std::string stopped_by = "signal";
  std::optional<std::string> setup_error;  // why the subscription failed (stopped_by setup_error)
};

// Replaces a file only once the new one is complete: a viewer of DIR never reads half a mesh.
Status write_mesh_atomically(const TriangleMesh& mesh, const std::filesystem::path& path) {
  const std::filesystem::path partial =
      path.parent_path() / (path.stem().string() + ".part" + path.extension().string());
  if (Status written = write_mesh(mesh, partial); !written) return written;
  std::error_code ec;
  std::filesystem::rename(partial, path, ec);
  if (ec) return Status::error("cannot replace " + path.string() + ": " + ec.message());
  return Status::ok();
}

template <typename T>
ordered_json optional_json(const std::optional<T>& value) {
  return value ? ordered_json(*value) : ordered_json(nullptr);
}

// `snapshot_endpoint`: where the snapshot was asked for; empty: nowhere.
Status write_summary(const ListenOptions& options, const std::string& snapshot_endpoint,
                     const Tally& tally, double duration_s) {
  ordered_json summary;
  summary["endpoint"] = options.stream.endpoint;
  summary["snapshot_endpoint"] =
      snapshot_endpoint.empty() ? ordered_json(nullptr) : ordered_json(snapshot_endpoint);
  summary["scan"] = tally.scan.empty() ? ordered_json(nullptr) : ordered_json(tally.scan);
  summary["scans"] = tally.scans;
  summary["messages"] = tally.messages;
  summary["invalid"] = tally.invalid;
  summary["seq_gaps"] = tally.seq_gaps;
  summary["missed"] = tally.missed;
  summary["first_seq"] = optional_json(tally.first_seq);
  summary["last_seq"] = optional_json(tally.last_seq);
  summary["snapshot_seq"] = optional_json(tally.snapshot_seq);
  ordered_json meshes = ordered_json::object();
  for (const auto& [label, count] : tally.meshes) meshes[std::to_string(label)] = count;
  summary["meshes"] = meshes;
  summary["meshes_over_label_limit"] = tally.meshes_over_label_limit;
  summary["slices"] = tally.slices;
  summary["statuses"] = tally.statuses;
  summary["frame_images"] = tally.frame_images;
  summary["last_state"] = optional_json(tally.last_state);
  summary["write_errors"] = tally.write_errors;
  summary["duration_s"] = duration_s;
  summary["stopped_by"] = tally.stopped_by;
  if (tally.setup_error) summary["error"] = *tally.setup_error;
  const std::filesystem::path path = options.output / "summary.json";
  std::ofstream out(path, std::ios::trunc);
  out << summary.dump(2) << '\n';
  out.flush();
  if (!out) return Status::error("cannot write " + path.string() + "; check the folder");
  return Status::ok();
}

// Writes the newest mesh of its label, for the first kMaxStreamLabels labels: a publisher with
// thousands of labels would otherwise fill the folder with one file each.
void record_mesh(const ListenOptions& options, const publish::MeshUpdate& mesh, Tally& tally) {
  if (!tally.meshes.count(mesh.label) &&
      tally.meshes.size() >= static_cast<std::size_t>(publish::kMaxStreamLabels)) {
    if (tally.meshes_over_label_limit++ == 0)
      log_warning("listen: the stream carries more than " +
                  std::to_string(publish::kMaxStreamLabels) + " mesh labels; label " +
                  std::to_string(mesh.label) +
                  " and further ones are not written (counted in summary.json as "
                  "meshes_over_label_limit; said once)");
    return;
  }
  ++tally.meshes[mesh.label];
  const auto path = options.output / ("label_" + std::to_string(mesh.label) + ".ply");
  if (Status written = write_mesh_atomically(mesh.mesh, path); !written) {
    ++tally.write_errors;
    std::cerr << "error: " << written.message() << '\n';
  }
}

// The subscription: the shared subscriber options (endpoints, the publisher's key), a snapshot
// wait that fits in --duration, and --receive-hwm.
Result<publish::SubscriberOptions> listen_subscription(const ListenOptions& options) {
  Result<publish::SubscriberOptions> out = subscription_of(options.stream);
  if (!out) return out;
  const double duration_s = options.stream.duration_s;
  out->snapshot_timeout_ms =
      duration_s > 0.0
          ? static_cast<int>(std::min<double>(kSnapshotTimeoutMs, duration_s * 1000.0 + 1))
          : kSnapshotTimeoutMs;
  out->receive_hwm = options.receive_hwm;
  return out;
}

// The listen's accounting of the messages it receives: snapshot or live, seq runs and gaps,
// scans, and what the bodies hold; one log line per header.
class Listener {
 public:
  Listener(const ListenOptions& options, bool with_snapshot, std::ofstream& log_file,
           const Stopwatch& clock)
      : options_(options), log_file_(log_file), clock_(clock), in_snapshot_(with_snapshot) {}

  Tally& tally() { return tally_; }

  // Counts a message that did not decode.
  void take_invalid(const std::string& error) {
    ++tally_.messages;
    ++tally_.invalid;
    log_warning("listen: invalid message: " + error);
  }

  // Counts one received message; true when --until-idle ends the listen here.
  bool take(const publish::StreamMessage& message, const std::string& header_frame) {
    ++tally_.messages;
    const bool is_end = std::holds_alternative<publish::SnapshotEnd>(message.body);
    if (!tally_.first_seq) tally_.first_seq = message.seq;
    tally_.last_seq = std::max(tally_.last_seq.value_or(0), message.seq);
    follow_scan(message);
    follow_seq(message, is_end);
    const bool stop = count_body(message);
    if (!is_end) log_header(message, header_frame);
    return stop;
  }

 private:
  void follow_scan(const publish::StreamMessage& message) {
    if (message.scan.empty() || message.scan == tally_.scan) return;
    if (!tally_.scan.empty())
      log_info("listen: new scan " + message.scan + " (its seq starts afresh)");
    tally_.scan = message.scan;
    tally_.scans.push_back(message.scan);
    expected_seq_ = 0;
  }

  void follow_seq(const publish::StreamMessage& message, bool is_end) {
    if (is_end && !in_snapshot_) {
      // `end` closes a snapshot; on the live stream it is a publisher's error.
      ++tally_.invalid;
      log_warning("listen: invalid message: end seq " + std::to_string(message.seq) +
                  " on the live stream; \"end\" only closes a snapshot (see "
                  "docs/formats/mesh-stream.md)");
    } else if (is_end) {
      in_snapshot_ = false;
      tally_.snapshot_seq = message.seq;
      expected_seq_ = message.seq + 1;
    } else if (!in_snapshot_) {
      if (expected_seq_ && message.seq > expected_seq_) {
        ++tally_.seq_gaps;
        tally_.missed += message.seq - expected_seq_;
        log_info("listen: seq gap: expected " + std::to_string(expected_seq_) + ", got " +
                 std::to_string(message.seq) + " (" + std::to_string(message.seq - expected_seq_) +
                 " messages missed)");
      } else if (expected_seq_ && message.seq < expected_seq_) {
        // One PUB socket delivers in order: a seq that does not grow breaks the format.
        ++tally_.invalid;
        log_warning("listen: invalid message: " + message.topic() + " seq " +
                    std::to_string(message.seq) + " after seq " +
                    std::to_string(expected_seq_ - 1) + "; seq must grow by one per message");
      }
      expected_seq_ = std::max(expected_seq_, message.seq + 1);
    }
  }

  // Records what the body holds; true when a live status ends an --until-idle listen.
  bool count_body(const publish::StreamMessage& message) {
    if (const auto* mesh = std::get_if<publish::MeshUpdate>(&message.body)) {
      record_mesh(options_, *mesh, tally_);
    } else if (std::holds_alternative<publish::SliceUpdate>(message.body)) {
      ++tally_.slices;
    } else if (std::holds_alternative<publish::FrameImage>(message.body)) {
      ++tally_.frame_images;
    } else if (const auto* status = std::get_if<publish::StatusReport>(&message.body)) {
      ++tally_.statuses;
      tally_.last_state = std::string(publish::to_string(status->state));
      if (status->state == publish::ScanState::kError)
        log_warning("listen: the scan reports an error: " + status->message);
      // A snapshot's status is the past: only a live one ends the listen.
      if (options_.until_idle && !in_snapshot_ && status->state != publish::ScanState::kScanning) {
        tally_.stopped_by = tally_.last_state.value();
        return true;
      }
    }
    return false;
  }

  // One line per header (binary frames left out), tagged with its topic and arrival time.
  void log_header(const publish::StreamMessage& message, const std::string& header_frame) {
    ordered_json line;
    line["topic"] = message.topic();
    line["received_s"] = clock_.seconds();
    if (in_snapshot_) line["snapshot"] = true;
    const ordered_json header = ordered_json::parse(header_frame);
    for (const auto& [key, value] : header.items()) line[key] = value;
    log_file_ << line.dump(-1, ' ', false, ordered_json::error_handler_t::replace) << '\n';
    log_file_.flush();
  }

  const ListenOptions& options_;
  std::ofstream& log_file_;
  const Stopwatch& clock_;
  Tally tally_;
  // Messages before the snapshot's `end` are the snapshot: newest state, not a seq run.
  bool in_snapshot_;
  // The seq the next live message should carry; 0 until known (seqs start at 1).
  std::uint64_t expected_seq_ = 0;
};

// Receives until a signal, --duration, --count or --until-idle ends the listen.
void receive_all(const ListenOptions& options, publish::MeshSubscriber& subscriber,
                 Listener& listener, const Stopwatch& clock) {
  Tally& tally = listener.tally();
  while (true) {
    if (g_stop_signal) {
      tally.stopped_by = "signal";
      return;
    }
    auto wait = kPollInterval;
    if (options.stream.duration_s > 0.0) {
      const double left_s = options.stream.duration_s - clock.seconds();
      if (left_s <= 0.0) {
        tally.stopped_by = "duration";
        return;
      }
      wait = std::min(wait, std::chrono::milliseconds(static_cast<long>(left_s * 1000.0) + 1));
    }
    auto received = subscriber.receive(wait);
    if (received && !*received) continue;  // nothing in this interval
    bool stop = false;
    if (received)
      stop = listener.take(**received, subscriber.last_frames()[1]);
    else
      listener.take_invalid(received.message());
    if (options.slow_ms > 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(options.slow_ms));
    if (options.count > 0 && tally.messages >= options.count) {
      tally.stopped_by = "count";
      return;
    }
    if (stop) return;
  }
}

int run_listen(const ListenOptions& options) {
  std::error_code ec;
  std::filesystem::create_directories(options.output, ec);
  if (ec) {
    std::cerr << "error: cannot create " << options.output.string() << ": " << ec.message() << '\n';
    return 1;
  }
  const std::filesystem::path log_path = options.output / "log.jsonl";
  std::ofstream log_file(log_path, std::ios::trunc);
  if (!log_file) {
    std::cerr << "error: cannot write " << log_path.string() << "; check the folder\n";
    return 1;
  }
  g_stop_signal = 0;
  std::signal(SIGINT, on_stop_signal);
  std::signal(SIGTERM, on_stop_signal);
  // --duration counts from here: the wait for the publisher and its snapshot is part of it.
  const Stopwatch clock;
  const Result<publish::SubscriberOptions> subscription = listen_subscription(options);
  const std::string snapshot = subscription ? subscription->snapshot_endpoint : std::string();
  auto subscriber = subscription ? publish::MeshSubscriber::connect(*subscription)
                                 : Result<publish::MeshSubscriber>(subscription.status());
  if (!subscriber) {
    if (g_stop_signal) {
      // Stopped while waiting for the snapshot: nothing received, an empty summary.
      const Status written = write_summary(options, snapshot, Tally{}, 0.0);
      return written ? 0 : 1;
    }
    std::cerr << "error: " << subscriber.message() << '\n';
    // The summary is promised whatever happens once the folder exists: a failed setup is one.
    Tally failed;
    failed.stopped_by = "setup_error";
    failed.setup_error = subscriber.message();
    if (const Status written = write_summary(options, snapshot, failed, 0.0); !written)
      std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  log_info("listen: subscribed to " + options.stream.endpoint +
           (snapshot.empty() ? "" : " (snapshot from " + snapshot + ")") + "; writing to " +
           options.output.string());
  Listener listener(options, !snapshot.empty(), log_file, clock);
  receive_all(options, *subscriber, listener, clock);
  const Tally& tally = listener.tally();
  const double duration_s = clock.seconds();
  if (Status written = write_summary(options, snapshot, tally, duration_s); !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  log_info("listen: " + std::to_string(tally.messages) + " messages (" +
           std::to_string(tally.invalid) + " invalid, " + std::to_string(tally.seq_gaps) +
           " seq gaps, " + std::to_string(tally.missed) + " missed) in " +
           std::to_string(duration_s) + " s, stopped by " + tally.stopped_by + " -> " +
           (options.output / "summary.json").string());
  return tally.invalid > 0 || tally.write_errors > 0 ? 1 : 0;
}

}  // namespace

CommandRunner add_listen_command(CLI::App& app) {
  auto options = std::make_shared<ListenOptions>();
  add_subscriber_options(app, options->stream);
  app.add_option("-o,--output", options->output,
                 "Folder for label_<id>.ply (newest mesh per label), log.jsonl (every header) "
                 "and summary.json")
      ->required();
  app.add_option("--count", options->count,
                 "Stop after N messages (snapshot and invalid ones included)")
      ->check(kPositiveNumber);
  app.add_option("--slow-ms", options->slow_ms,
                 "Sleep MS after every message (emulates a slow subscriber)")
      ->check(kNonNegativeNumber);
  app.add_option("--receive-hwm", options->receive_hwm,
                 "Messages queued on this side before newer ones are dropped (a viewer that only "
                 "wants the latest state uses a small one)")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_flag("--until-idle", options->until_idle,
               "Stop at the first live status whose state is idle or error");
  return [options] { return run_listen(*options); };
}

}  // namespace sonoshape::apps
