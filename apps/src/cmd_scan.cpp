// `sonoshape scan`: the live pipeline. Frames and poses from a source (sim:, replay:), time
// sync, keyframes, segmentation and online reconstruction on their own threads, meshes to
// --out and the ZeroMQ stream. Prints a live status line and a summary. With --out, every
// accepted keyframe goes to a journal there first, and `scan --resume DIR` goes on from it.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <thread>

#include "commands.hpp"
#include "engine_options.hpp"
#include "option_checks.hpp"
#include "preset_option.hpp"
#include "seed_option.hpp"
#include "sim_options.hpp"
#include "sonoshape/apps/file_sink.hpp"
#include "sonoshape/apps/publish_sink.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/publish/curve.hpp"
#include "sonoshape/scan/journal.hpp"
#include "sonoshape/scan/pipeline.hpp"
#ifdef SONOSHAPE_WITH_OPENIGTLINK
#include "sonoshape/apps/igtl_sink.hpp"
#endif
#include "sonoshape/apps/scan_sources.hpp"
#include "sonoshape/scan/sink.hpp"
#include "view_options.hpp"
#ifdef SONOSHAPE_WITH_VIEWER
#include "sonoshape/publish/stream_view.hpp"
#endif

namespace sonoshape::apps {
namespace {

struct ScanCommandOptions {
  std::string source;
  std::string tracker;  ///< --tracker: a live tracker replaces the source's poses
  std::filesystem::path calibration;
  std::string pose_transform;  ///< --pose-transform (replay): FROMToTO
  std::filesystem::path segmentation;
  std::string preset;              // --preset NAME: a named set of segmentation settings
  std::string method;              // "", "threshold" or "graph-cut": overrides the configuration
  std::vector<std::string> seeds;  // LABEL:X,Y,Z, see seed_option.hpp
  std::string labels;              ///< --labels FILE | igtl:DEVICE: the site's own label maps
  int labels_unknown = acquisition::kDefaultUnknownLabelValue;
  double labels_wait_ms = 1000.0;  ///< igtl: how long a frame waits for its label map
  std::filesystem::path out;
  std::filesystem::path resume;  ///< --resume DIR: the scan whose journal is in DIR goes on
  std::size_t save_every = 0;
  double duration_s = 0.0;
  bool real_time = false;
  bool fast = false;
  double speed = 1.0;
  std::size_t max_slices = 0;
  std::string publish;
  std::string snapshot;
  std::filesystem::path curve_secret_key;  ///< --curve-secret-key: the stream's CURVE key file
  bool allow_remote = false;               ///< --allow-remote: bind where others can reach
  std::string igtl_serve;
  std::optional<std::string> view;  ///< --view [ADDR]: the browser view's HOST:PORT
  bool view_hold = false;
  std::optional<double> publish_frames_hz;  ///< --publish-frames: B-mode previews a second
  std::optional<double> tracker_latency_ms;
  double max_pose_gap_ms = 100.0;
  double max_extrapolation_ms = 0.0;
  double pose_wait_ms = 500.0;
  double keyframe_angle_deg = tracking::KeyframeOptions{}.min_angle_deg;
  std::optional<double> keyframe_distance_mm;  ///< none: the field's (keyframe_distance_for)
  std::size_t slice_budget = tracking::KeyframeOptions{}.slice_budget;
  std::size_t segmentation_queue = scan::ScanOptions{}.segmentation_queue;
  std::size_t reconstruction_queue = scan::ScanOptions{}.reconstruction_queue;
  int depth = -1;
  std::string device;  // --device; empty: SONOSHAPE_DEVICE, else cpu
  int smoothing = -1;  // the field's default
  std::string field = kDefaultField;
  std::vector<double> bounds;
  // sim: only
  SimScenarioOptions sim;
  double sweep_s = 20.0;
  double fail_after_s = -1.0;
  // igtl: only
  std::string igtl_image;
  std::string igtl_transform = scan::SourceRequest{}.igtl_transform;
  std::string igtl_tracker;
};

// Set by the SIGINT handler, read by the main loop (a lock-free atomic is signal-safe).
std::atomic<int> g_interrupts{0};

extern "C" void on_interrupt(int) {
  if (g_interrupts.fetch_add(1) >= 1) {
    // Second Ctrl-C: the user insists. Only async-signal-safe calls here.
    const char message[] = "\nscan: interrupted twice, exiting without writing meshes\n";
    [[maybe_unused]] const auto written = ::write(STDERR_FILENO, message, sizeof(message) - 1);
    std::_Exit(130);
  }
}

std::string milliseconds(double seconds) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(0) << 1e3 * seconds;
  return out.str();
}

std::string status_line(const scan::ScanCounters& c) {
  std::ostringstream out;
  out << "scan: frames " << c.frames_received << " in, " << c.dropped.total() << " dropped; "
      << c.slices << " slices (" << c.keyframes_skipped << " near-duplicates skipped); last update "
      << std::fixed << std::setprecision(0) << c.last_update_ms << " ms, latency "
      << milliseconds(c.last_latency_s) << " ms";
  return out.str();
}

std::string summary_text(const scan::ScanSummary& s) {
  const scan::ScanCounters& c = s.counters;
  const scan::DropCounts& d = c.dropped;
  std::ostringstream out;
  out << "scan summary (" << scan::to_string(s.stop_reason) << ", " << std::fixed
      << std::setprecision(1) << s.duration_s << " s):\n"
      << "  frames received " << c.frames_received << ", dropped " << d.total() << " (source "
      << d.source << ", pose missing " << d.pose_missing << ", pose invalid " << d.pose_invalid
      << ", pose gap " << d.pose_gap << ", pose extrapolation " << d.pose_extrapolation
      << ", segmentation behind " << d.segmentation_behind << ", segmentation failed "
      << d.segmentation_failed << ", reconstruction behind " << d.reconstruction_behind
      << ", refused by the reconstruction " << d.reconstruction_rejected << ")\n"
      << "  slices " << c.slices << ", near-duplicate keyframes skipped " << c.keyframes_skipped
      << ", updates " << c.updates << "\n"
      << "  frame-to-mesh latency p50 " << milliseconds(s.latency.p50_s) << " ms, p95 "
      << milliseconds(s.latency.p95_s) << " ms, max " << milliseconds(s.latency.max_s)
      << " ms; update median " << std::setprecision(0) << s.update_ms_median << " ms, p95 "
      << s.update_ms_p95 << " ms, max " << s.update_ms_max << " ms\n"
      << "  " << s.frame_source << "\n  " << s.pose_source;
  if (s.repairs.total()) {
    out << "\n  segmentation repairs " << s.repairs.total() << " (";
    const char* sep = "";
    for (const auto& [kind, count] : s.repairs.counts) {
      out << sep << kind << " " << count;
      sep = ", ";
    }
    out << "; see scan.json)";
  }
  if (s.segmentation_scores) {
    // The keyframes' label maps against the simulator's truth (indented under the summary).
    std::istringstream table(
        segmentation::format_comparison(*s.segmentation_scores, s.label_names));
    for (std::string line; std::getline(table, line);) out << "\n  " << line;
  }
  for (const std::string& missing : s.labels_without_mesh) out << "\n  " << missing;
  for (const std::string& e : s.errors) out << "\n  error: " << e;
  return out.str();
}

// Installs the SIGINT handler for the lifetime of a scan and restores the previous one.
class InterruptGuard {
 public:
  InterruptGuard() {
    g_interrupts.store(0);
    previous_ = std::signal(SIGINT, on_interrupt);
  }
  ~InterruptGuard() { std::signal(SIGINT, previous_); }
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;

 private:
  void (*previous_)(int) = SIG_DFL;
};

// `--igtl-serve [HOST:]PORT`: the OpenIGTLink server as a scan output (null when not asked for);
// false after printing the error.
bool add_igtl_sink(const std::string& spec, scan::ScanPipeline& pipeline,
                   std::shared_ptr<scan::ScanSink>& sink) {
  if (spec.empty()) return true;
#ifdef SONOSHAPE_WITH_OPENIGTLINK
  const std::size_t colon = spec.rfind(':');
  const std::string host = colon == std::string::npos ? "127.0.0.1" : spec.substr(0, colon);
  const std::string port_text = colon == std::string::npos ? spec : spec.substr(colon + 1);
  int port = -1;
  try {
    std::size_t used = 0;
    port = std::stoi(port_text, &used);
    if (used != port_text.size()) port = -1;
  } catch (const std::exception&) {
  }
  if (port < 0 || port > 65535) {
    std::cerr << "error: --igtl-serve " << spec
              << ": expected [HOST:]PORT, e.g. 18944 (Slicer's default) or 0.0.0.0:18944\n";
    return false;
  }
  auto started = IgtlSink::start(host, port);
  if (!started) {
    std::cerr << "error: " << started.message() << '\n';
    return false;
  }
  log_info("scan: OpenIGTLink server on " + host + ":" + std::to_string((*started)->port()) +
           " (3D Slicer: OpenIGTLinkIF, a client connector to this host and port)");
  sink = *started;
  pipeline.add_sink(sink);
  return true;
#else
  (void)pipeline;
  (void)sink;
  return false;  // refused by igtl_serve_available before the source opened
#endif
}

// Without OpenIGTLink, `--igtl-serve` is refused before the source opens (a simulated one learns
// its models first).
bool igtl_serve_available(const std::string& spec) {
#ifndef SONOSHAPE_WITH_OPENIGTLINK
  if (!spec.empty()) {
    std::cerr << "error: --igtl-serve " << spec
              << ": this sonoshape was built without OpenIGTLink; install libopenigtlink-dev "
                 "(scripts/install-deps) and configure with -DSONOSHAPE_WITH_OPENIGTLINK=ON\n";
    return false;
  }
#endif
  (void)spec;
  return true;
}

#ifdef SONOSHAPE_WITH_VIEWER
// `--view`: the same server as `sonoshape view`, following this scan's own stream through its
// snapshot, so that a page opened at any time shows the whole scan so far.
// `server_key`: the stream's CURVE public key, empty for a plain stream.
Result<std::unique_ptr<publish::StreamView>> start_view(const std::string& address,
                                                        const PublishSink& sink,
                                                        const std::string& server_key) {
  publish::StreamViewOptions view;
  view.stream.endpoint = sink.endpoint();
  view.stream.snapshot_endpoint = sink.snapshot_endpoint();
  view.stream.server_public_key = server_key;
  view.server.http = address;
  view.server.web_root = SONOSHAPE_VIEWER_DIR;
  Result<publish::StreamView> started = publish::StreamView::start(view);
  if (!started) return started.status();
  return std::make_unique<publish::StreamView>(std::move(*started));
}

// The end of `--view`: the scan's last status ("finished") reaches the pages open now before
// the server goes (a bounded wait: a page that does not read is not waited for), and the user
// learns what a page opened later gets.
void end_view(publish::StreamView& view, const std::string& scan_id, bool hold) {
  const bool delivered = view.drain(scan_id, std::chrono::seconds(3));
  if (!delivered)
    log_warning("scan: the view's pages did not take the scan's last messages within 3 s");
  if (hold) {
    log_info("scan: finished; " + view.url() + " shows it until Ctrl-C");
    return;
  }
  log_info("scan: finished; the view at " + view.url() +
           " closes with the scan: pages open now keep showing the finished scan, a page "
           "opened later finds no server (--view-hold keeps serving it until Ctrl-C)");
}
#endif

namespace fs = std::filesystem;

// What --resume found in the journal.
struct Resume {
  scan::JournalContents journal;
};

// The arguments after `scan` on this command line, without the global flags (-v, -q).
std::vector<std::string> scan_arguments() {
  const std::vector<std::string>& line = command_line();
  std::vector<std::string> out;
  const auto start = std::find(line.begin() + (line.empty() ? 0 : 1), line.end(), "scan");
  if (start == line.end()) return out;
  for (auto it = start + 1; it != line.end(); ++it)
    if (*it != "-v" && *it != "--verbose" && *it != "-q" && *it != "--quiet") out.push_back(*it);
  return out;
}

// Whether `arguments` name the field (--field F or --field=F).
bool names_field(const std::vector<std::string>& arguments) {
  return std::any_of(arguments.begin(), arguments.end(), [](const std::string& word) {
    return word == "--field" || word.rfind("--field=", 0) == 0;
  });
}

// The arguments the journal records: this command line's, with the field named where the
// default chose it, so that a resume rebuilds the same meshes whatever the default is then.
std::vector<std::string> recorded_arguments(const std::string& field) {
  std::vector<std::string> arguments = scan_arguments();
  if (!names_field(arguments)) arguments.insert(arguments.end(), {"--field", field});
  return arguments;
}

// Temporary files a killed scan left in `directory` (`.partial-*`): never a result.
void remove_partial_files(const fs::path& directory) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(directory, ec)) {
    if (entry.path().filename().string().rfind(".partial-", 0) != 0) continue;
    std::error_code ignored;
    fs::remove(entry.path(), ignored);
  }
}

// --out: a new journal there, unless it holds the journal of a scan that did not finish (its
// keyframes are the patient's: resume it or choose another --out). False after the message.
bool create_journal(const fs::path& out, const std::string& field,
                    std::shared_ptr<scan::KeyframeJournal>& journal) {
  const fs::path path = out / scan::kJournalName;
  if (fs::exists(path)) {
    const auto old = scan::read_journal(path);
    if (!old || !old->finished) {
      std::cerr << "error: --out " << out.string() << " holds the journal of a scan that did not "
                << "finish ("
                << (old ? std::to_string(old->keyframes.size()) + " keyframes" : old.message())
                << "); go on with it: sonoshape scan --resume " << out.string()
                << ", or choose another --out\n";
      return false;
    }
  }
  std::error_code ec;
  fs::create_directories(out, ec);
  auto created = scan::KeyframeJournal::create(path, recorded_arguments(field));
  if (!created) {
    std::cerr << "error: " << created.message() << '\n';
    return false;
  }
  journal = std::move(*created);
  return true;
}

int run_scan(const ScanCommandOptions& options, const Resume* resume);
void add_scan_options(CLI::App& app, ScanCommandOptions& options);

// --resume reads its options from a file in DIR, which anyone who could write there may have
// crafted (issue 40, S5): its relative paths are read where the scan was started, and it never
// opens this machine to the network. These options a resume takes from its own command line
// only when they reach beyond loopback.
const std::vector<std::string> kResumeCommandLineOptions = {
    "--resume",   "--view",         "--igtl-serve",      "--publish",
    "--snapshot", "--allow-remote", "--curve-secret-key"};

// A relative path of the journal, read against the folder the scan was started in.
fs::path from_scan_folder(const fs::path& path, const fs::path& folder) {
  return path.empty() || path.is_absolute() ? path : folder / path;
}

// "PREFIX:PATH..." (replay:FILE, LABEL:PATH[:NAME]) with a relative PATH read from `folder`.
std::string spec_from_scan_folder(const std::string& spec, const std::string& prefix,
                                  const fs::path& folder) {
  if (spec.rfind(prefix, 0) != 0 || spec.size() == prefix.size()) return spec;
  return prefix + from_scan_folder(spec.substr(prefix.size()), folder).string();
}

// LABEL:PATH[:NAME] meshes separated by commas (sim:'s phantom spec, --phantom).
std::string meshes_from_scan_folder(const std::string& meshes, const fs::path& folder) {
  std::string out;
  std::size_t start = 0;
  while (start <= meshes.size()) {
    const std::size_t comma = std::min(meshes.find(',', start), meshes.size());
    const std::string mesh = meshes.substr(start, comma - start);
    const std::size_t colon = mesh.find(':');
    out += (start == 0 ? "" : ",") +
           (colon == std::string::npos
                ? mesh
                : spec_from_scan_folder(mesh, mesh.substr(0, colon + 1), folder));
    start = comma + 1;
  }
  return out;
}

void resolve_journal_paths(ScanCommandOptions& options, const fs::path& folder) {
  if (options.source.rfind("sim:", 0) == 0)
    options.source = "sim:" + meshes_from_scan_folder(options.source.substr(4), folder);
  options.calibration = from_scan_folder(options.calibration, folder);
  options.segmentation = from_scan_folder(options.segmentation, folder);
  if (options.labels.rfind("igtl:", 0) != 0)
    options.labels = from_scan_folder(options.labels, folder);
  options.curve_secret_key = from_scan_folder(options.curve_secret_key, folder);
  options.source = spec_from_scan_folder(options.source, "replay:", folder);
  options.tracker = spec_from_scan_folder(options.tracker, "replay:", folder);
  for (std::string& phantom : options.sim.phantoms)
    phantom = meshes_from_scan_folder(phantom, folder);
}

// Drops the journal's options that other machines could reach (a bind beyond loopback, and
// --allow-remote); returns them as they would be typed.
std::vector<std::string> drop_remote_exposure(ScanCommandOptions& options) {
  std::vector<std::string> dropped;
  const auto reachable = [](const std::string& address) {
    return !publish::is_local_endpoint("tcp://" + address);
  };
  if (options.view) {
    const std::string address = options.view->empty() ? kDefaultViewAddress : *options.view;
    if (reachable(address)) {
      dropped.push_back("--view " + address);
      options.view.reset();
    }
  }
  // [HOST:]PORT: a bare port is served on loopback.
  if (options.igtl_serve.find(':') != std::string::npos && reachable(options.igtl_serve)) {
    dropped.push_back("--igtl-serve " + options.igtl_serve);
    options.igtl_serve.clear();
  }
  for (std::string* endpoint : {&options.publish, &options.snapshot}) {
    if (endpoint->empty() || publish::is_local_endpoint(*endpoint)) continue;
    dropped.push_back((endpoint == &options.publish ? "--publish " : "--snapshot ") + *endpoint);
    endpoint->clear();
  }
  if (options.allow_remote) {
    dropped.push_back("--allow-remote");
    options.allow_remote = false;
  }
  return dropped;
}

std::string joined(const std::vector<std::string>& words) {
  std::string out;
  for (const std::string& word : words) out += (out.empty() ? "" : " ") + word;
  return out;
}

// The options on the command line of --resume DIR: only the network ones may be given (the
// rest comes from the journal). False after the message.
bool parse_resume_command_line(ScanCommandOptions& given, CLI::App& given_app) {
  std::vector<std::string> given_arguments = scan_arguments();
  for (const std::string& word : given_arguments) {
    const std::string name = word.substr(0, word.find('='));
    if (name.empty() || name[0] != '-' ||
        std::find(kResumeCommandLineOptions.begin(), kResumeCommandLineOptions.end(), name) !=
            kResumeCommandLineOptions.end())
      continue;
    std::cerr << "error: --resume DIR takes " << name
              << " from the journal in DIR (the scan goes on as it was started); on the command "
                 "line it takes only the network options "
              << joined({kResumeCommandLineOptions.begin() + 1, kResumeCommandLineOptions.end()})
              << '\n';
    return false;
  }
  add_scan_options(given_app, given);
  std::reverse(given_arguments.begin(), given_arguments.end());  // CLI11 takes them last first
  try {
    given_app.parse(given_arguments);
  } catch (const CLI::ParseError& e) {
    std::cerr << "error: --resume: " << e.what() << '\n';
    return false;
  }
  return true;
}

// The journal's options, parsed where the scan was started, where its relative paths mean what
// they meant (the parser checks that files exist). False after the message.
bool parse_journal_options(const fs::path& directory, const scan::JournalContents& journal,
                           ScanCommandOptions& options) {
  CLI::App app;
  add_scan_options(app, options);
  std::vector<std::string> arguments = journal.arguments;
  // A journal that names no field was written while the mean-value field was the default
  // (every scan since records the field it ran with).
  if (!names_field(arguments)) arguments.insert(arguments.end(), {"--field", "mean-value"});
  std::reverse(arguments.begin(), arguments.end());  // CLI11 takes them last first
  const fs::path here = fs::current_path();
  std::error_code ec;
  if (journal.working_directory) fs::current_path(*journal.working_directory, ec);
  if (ec) {
    std::cerr << "error: --resume " << directory.string() << ": the scan was started in "
              << journal.working_directory->string() << ", which cannot be entered now ("
              << ec.message() << "); its relative paths are read from there\n";
    return false;
  }
  std::string refused;
  try {
    app.parse(arguments);
  } catch (const CLI::ParseError& e) {
    refused = e.what();
  }
  fs::current_path(here, ec);
  if (!refused.empty()) {
    std::cerr << "error: --resume " << directory.string() << ": the journal's options no "
              << "longer parse (" << refused << "); was it written by another sonoshape?\n";
    return false;
  }
  return true;
}

// --resume DIR: the journal's scan again, with its own arguments, going on after its keyframes.
int resume_scan(const fs::path& directory) {
  // The command line: --resume and, to expose the resumed scan again, the network options.
  ScanCommandOptions given;
  CLI::App given_app;
  if (!parse_resume_command_line(given, given_app)) return 1;
  auto journal = scan::read_journal(directory / scan::kJournalName);
  if (!journal) {
    std::cerr << "error: --resume " << directory.string() << ": " << journal.message() << '\n';
    return 1;
  }
  if (journal->torn_tail) log_warning("scan: " + *journal->torn_tail);
  if (journal->arguments.empty()) {
    std::cerr << "error: --resume " << directory.string()
              << ": the journal lost its first record (the scan's options): the scan was killed "
                 "before its first keyframe; start it again\n";
    return 1;
  }
  ScanCommandOptions options;
  if (!parse_journal_options(directory, *journal, options)) return 1;
  // Said every time: the options come from a file, and the user should see what it asks for.
  std::cerr << "scan: --resume " << directory.string()
            << ": the scan's options from its journal: " << joined(journal->arguments) << '\n';
  if (journal->working_directory) {
    // Made absolute: the scan runs from here.
    resolve_journal_paths(options, *journal->working_directory);
    std::cerr << "scan: --resume: their relative paths are read from "
              << journal->working_directory->string() << ", where the scan was started\n";
  } else {
    std::cerr << "scan: --resume: the journal does not record where the scan was started (an "
                 "older sonoshape wrote it): its relative paths are read from here\n";
  }
  for (const std::string& option : drop_remote_exposure(options))
    std::cerr << "note: --resume: the journal asks for " << option
              << ", which other machines could reach; a resume never takes that from a file: "
                 "pass it on the command line if you mean it (sonoshape scan --resume "
              << directory.string() << " " << option << ")\n";
  // The network options given with --resume, as given.
  if (given_app.count("--view")) options.view = given.view;
  if (given_app.count("--igtl-serve")) options.igtl_serve = given.igtl_serve;
  if (given_app.count("--publish")) options.publish = given.publish;
  if (given_app.count("--snapshot")) options.snapshot = given.snapshot;
  if (given_app.count("--allow-remote")) options.allow_remote = given.allow_remote;
  if (given_app.count("--curve-secret-key")) options.curve_secret_key = given.curve_secret_key;
  options.out = directory;
  const Resume state{std::move(*journal)};
  return run_scan(options, &state);
}

// What to open: the source, tracker, calibration, segmentation, volume and label maps; the
// checks of the options that go together.
Result<scan::SourceRequest> source_request(const ScanCommandOptions& options,
                                           const Resume* resume) {
  scan::SourceRequest request;
  request.spec = options.source;
  request.tracker = options.tracker;
  if (!options.calibration.empty()) request.calibration = options.calibration;
  request.pose_transform = options.pose_transform;
  if (!options.segmentation.empty()) request.segmentation = options.segmentation;
  request.preset = options.preset;
  if (!options.bounds.empty()) {
    if (options.bounds.size() != 6)
      return Status::error("--bounds takes 6 numbers: xmin ymin zmin xmax ymax zmax (mm)");
    request.bounds = Box3{Vec3(options.bounds[0], options.bounds[1], options.bounds[2]),
                          Vec3(options.bounds[3], options.bounds[4], options.bounds[5])};
    if (!(request.bounds->size().array() > 0.0).all())
      return Status::error("--bounds: every max must exceed its min");
  }
  request.igtl_image = options.igtl_image;
  request.igtl_transform = options.igtl_transform;
  request.igtl_tracker = options.igtl_tracker;
  request.labels = options.labels;
  request.labels_unknown = options.labels_unknown;
  request.labels_wait_s = 1e-3 * options.labels_wait_ms;
  if (!options.labels.empty() && (!options.method.empty() || !options.seeds.empty()))
    return Status::error(std::string("--labels replaces sonoshape's segmenter, so ") +
                         (options.method.empty() ? "--organ-seed" : "--method") +
                         " does not apply; leave it out");
  if (options.labels.rfind("igtl:", 0) == 0 && options.igtl_image.empty())
    return Status::error("--labels " + options.labels +
                         " needs --igtl-image NAME (the IMAGE device of the B-mode frames): "
                         "without it every IMAGE, the label maps too, would be taken as a frame");
  if (resume && !resume->journal.keyframes.empty())
    request.resume_after_frame = resume->journal.keyframes.back().frame_index;
  return request;
}

// The simulated source's options (sim:).
SimSourceOptions sim_source_options(const ScanCommandOptions& options) {
  SimSourceOptions sim;
  sim.scenario = options.sim;
  sim.duration_s = options.sweep_s;
  sim.fail_after_s = options.fail_after_s;
  sim.models_dir = std::filesystem::path(SONOSHAPE_DATA_DIR) / "models";
  return sim;
}

// The keyframes' distance threshold when --keyframe-distance-mm is not given. The paper's
// field keeps the keyframes' 2.5 mm (about an abdominal probe's elevational beam thickness;
// closer near-parallel planes multiply its cells and gain nothing: docs/benchmarks.md,
// "Keyframes"). The thin-plate field fits segmented outlines as a smoothing spline, which
// averages their error over the neighbouring slices, and a slice costs it only its samples:
// 1.5 mm gives it more of them to average (docs/segmentation.md, "The default scan").
constexpr double kThinPlateKeyframeDistanceMm = 1.5;
double keyframe_distance_for(const ScanCommandOptions& options) {
  if (options.keyframe_distance_mm) return *options.keyframe_distance_mm;
  return recon::parse_field_name(options.field) == recon::FieldKind::thin_plate
             ? kThinPlateKeyframeDistanceMm
             : tracking::KeyframeOptions{}.min_distance_mm;
}

// How the pipeline runs: sync, keyframes, playback, limits and queues.
scan::ScanOptions pipeline_options(const ScanCommandOptions& options,
                                   const scan::ScanSource& source) {
  scan::ScanOptions scan_options;
  scan_options.sync.tracker_latency_s = options.tracker_latency_ms
                                            ? 1e-3 * *options.tracker_latency_ms
                                            : source.tracker_latency_s.value_or(0.0);
  scan_options.sync.max_gap_s = 1e-3 * options.max_pose_gap_ms;
  scan_options.sync.max_extrapolation_s = 1e-3 * options.max_extrapolation_ms;
  scan_options.keyframes.min_angle_deg = options.keyframe_angle_deg;
  scan_options.keyframes.min_distance_mm = keyframe_distance_for(options);
  scan_options.keyframes.slice_budget = options.slice_budget;
  scan_options.real_time = !options.fast;
  // Played fast, nothing needs dropping: every stage waits for the next (deterministic).
  scan_options.drop_when_behind = !options.fast;
  scan_options.speed = options.speed;
  scan_options.pose_wait_s = 1e-3 * options.pose_wait_ms;
  scan_options.duration_s = options.duration_s;
  scan_options.max_slices = options.max_slices;
  scan_options.segmentation_queue = options.segmentation_queue;
  scan_options.reconstruction_queue = options.reconstruction_queue;
  return scan_options;
}

recon::ReconstructorOptions engine_options(const ScanCommandOptions& options,
                                           const scan::ScanSource& source) {
  recon::ReconstructorOptions engine;
  engine.engine.max_depth = options.depth;
  engine.engine.smoothing_iterations = options.smoothing;
  engine.engine.field = *recon::parse_field_name(options.field);
  engine.engine.device = resolve_device(options.device, options.field);
  engine.bounds = source.setup.bounds;
  engine.labels = source.setup.labels;
  return engine;
}

// The segmenter with the options' method and seeds, or the site's label maps (started).
Result<std::unique_ptr<scan::SegmentationStage>> segmentation_stage(
    const ScanCommandOptions& options, scan::ScanSource& source) {
  if (!options.method.empty())
    source.setup.segmentation.method = options.method == "graph-cut"
                                           ? segmentation::LabellingMethod::kGraphCut
                                           : segmentation::LabellingMethod::kThreshold;
  if (const Status seeded = apply_seeds(options.seeds, source.setup.segmentation); !seeded)
    return seeded;
  try {
    if (source.labels) {
      log_info("scan: " + source.labels->describe() + " instead of the segmenter");
      if (const Status started = source.labels->start(); !started)
        return Status::error("--labels " + options.labels + ": " + started.message());
      return std::unique_ptr<scan::SegmentationStage>(
          std::make_unique<scan::LabelMapStage>(source.setup, std::move(source.labels)));
    }
    auto segmenter = std::make_unique<scan::SegmenterStage>(source.setup);
    if (source.truth_of_frame) segmenter->score_against(source.truth_of_frame);
    return std::unique_ptr<scan::SegmentationStage>(std::move(segmenter));
  } catch (const std::exception& e) {
    return Status::error(e.what());
  }
}

// --resume: the journal's keyframes into the pipeline, and the journal reopened after them.
Status restore_journal(const ScanCommandOptions& options, const Resume& resume, bool playback,
                       scan::ScanPipeline& pipeline,
                       std::shared_ptr<scan::KeyframeJournal>& journal) {
  const scan::JournalContents& contents = resume.journal;
  remove_partial_files(options.out);
  if (Status restored = pipeline.restore(contents.keyframes); !restored)
    return Status::error("--resume " + options.out.string() + ": " + restored.message());
  const std::int64_t after =
      contents.keyframes.empty() ? -1 : contents.keyframes.back().frame_index;
  auto reopened = scan::KeyframeJournal::reopen(options.out / scan::kJournalName, contents, after);
  if (!reopened)
    return Status::error("--resume " + options.out.string() + ": " + reopened.message());
  journal = std::move(*reopened);
  log_info("scan: resuming " + options.out.string() + " with " +
           std::to_string(contents.keyframes.size()) + " journalled keyframes; " +
           (playback ? "the source goes on at frame " + std::to_string(after + 1)
                     : "a live source goes on from the frame it delivers now"));
  return Status::ok();
}

// The live outputs beside the files: the browser view (with the scan it follows) and the
// OpenIGTLink server.
struct LiveOutputs {
#ifdef SONOSHAPE_WITH_VIEWER
  std::unique_ptr<publish::StreamView> view;
  std::string published_scan;
#endif
  std::shared_ptr<scan::ScanSink> igtl;
};

// The mesh stream (--publish, or the default endpoint for --view) and the view that follows it.
Status add_stream_sinks(const ScanCommandOptions& options, scan::ScanPipeline& pipeline,
                        LiveOutputs& live) {
  const std::string publish_endpoint =
      options.publish.empty() && options.view ? "tcp://127.0.0.1:5556" : options.publish;
  if (publish_endpoint.empty()) return Status::ok();
  // The browser view shows the current frame on its plane: with --view, previews go out at
  // 5 a second unless told otherwise (a 256 px grey picture: about 50 KB each).
  FramePreviewOptions previews;
  previews.rate_hz = options.publish_frames_hz.value_or(options.view ? 5.0 : 0.0);
  StreamAccess access;
  access.allow_remote = options.allow_remote;
  if (!options.curve_secret_key.empty()) {
    Result<std::string> key = publish::read_curve_key(options.curve_secret_key, "secret");
    if (!key) return Status::error("--curve-secret-key: " + key.message());
    access.curve_secret_key = *key;
  }
  auto sink = PublishSink::bind(publish_endpoint, options.snapshot, previews, access);
  if (!sink) return sink.status();
  log_info("scan: publishing scan " + (*sink)->scan_id() + " on " + (*sink)->endpoint() +
           " (snapshot " + (*sink)->snapshot_endpoint() + ")");
  pipeline.add_sink(*sink);
#ifdef SONOSHAPE_WITH_VIEWER
  if (options.view) {
    const std::string address = options.view->empty() ? kDefaultViewAddress : *options.view;
    // The view is a subscriber like any other: a keyed stream needs the key's public half.
    std::string server_key;
    if (!access.curve_secret_key.empty())
      server_key = *publish::curve_public_key_of(access.curve_secret_key);
    auto started = start_view(address, **sink, server_key);
    if (!started) return Status::error("--view: " + started.message());
    live.view = std::move(*started);
    live.published_scan = (*sink)->scan_id();
    log_info("scan: live view at " + live.view->url());
  }
#else
  (void)live;
#endif
  return Status::ok();
}

// Runs the scan to its end (a Ctrl-C stops it) with a status line on stderr, and finishes it.
scan::ScanSummary run_to_end(scan::ScanPipeline& pipeline) {
  const bool live_line = log_level() >= LogLevel::kInfo && ::isatty(STDERR_FILENO);
  const bool periodic_line = log_level() >= LogLevel::kInfo && !live_line;
  bool stop_sent = false;
  Stopwatch since_line;
  // The first check does not wait: a Ctrl-C before the start stops the scan at once.
  while (!pipeline.wait_for(stop_sent || g_interrupts.load() == 0 ? 0.25 : 0.0)) {
    if (g_interrupts.load() > 0 && !stop_sent) {
      stop_sent = true;
      std::cerr << (live_line ? "\n" : "")
                << "scan: interrupted, finishing (Ctrl-C again to quit without saving)\n";
      pipeline.request_stop();
    }
    if (live_line) {
      std::cerr << '\r' << status_line(pipeline.counters()) << "\033[K" << std::flush;
    } else if (periodic_line && since_line.seconds() >= 2.0) {
      since_line.reset();
      std::cerr << status_line(pipeline.counters()) << '\n';
    }
  }
  if (live_line) std::cerr << '\r' << status_line(pipeline.counters()) << "\033[K\n";
  const scan::ScanSummary summary = pipeline.finish();
  log_info(summary_text(summary));
  return summary;
}

// The end: the view's last messages, the OpenIGTLink server's account, and whether what the
// scan says it wrote is all there (a full disk).
int end_scan(const ScanCommandOptions& options, const scan::ScanSummary& summary,
             LiveOutputs& live) {
#ifdef SONOSHAPE_WITH_VIEWER
  const bool hold_view = live.view && options.view_hold && g_interrupts.load() == 0;
  if (live.view) end_view(*live.view, live.published_scan, hold_view);
#endif
#ifdef SONOSHAPE_WITH_OPENIGTLINK
  if (live.igtl) log_info("scan: " + static_cast<const IgtlSink&>(*live.igtl).describe());
#endif
  // A full disk: the scan went on, but what it says it wrote must be true.
  if (!summary.incomplete_outputs.empty()) {
    std::cerr << "error: scan: the output in " << options.out.string() << " is incomplete:\n";
    for (const std::string& missing : summary.incomplete_outputs)
      std::cerr << "  " << missing << '\n';
    std::cerr << "free space on the disk of --out, then run `sonoshape scan --resume "
              << options.out.string() << "`: it rebuilds the scan from the journal's keyframes\n";
    return 1;
  }
  if (!options.out.empty())
    log_info("scan: meshes, slices.json and scan.json in " + options.out.string());
#ifdef SONOSHAPE_WITH_VIEWER
  if (hold_view)
    while (g_interrupts.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(100));
#endif
  return 0;
}

int run_scan(const ScanCommandOptions& options, const Resume* resume) {
  // From the start: a Ctrl-C while the source opens stops the scan as soon as it starts.
  const InterruptGuard interrupts;
  // (SIGXFSZ is ignored by main(): a file-size limit fails writes like a full disk.)
  if (!igtl_serve_available(options.igtl_serve)) return 1;
  std::shared_ptr<scan::KeyframeJournal> journal;
  if (!resume && !options.out.empty() && !create_journal(options.out, options.field, journal))
    return 1;
#ifndef SONOSHAPE_WITH_VIEWER
  if (options.view) return print_error(std::string("--view: ") + kViewerMissing);
#endif
  const auto request = source_request(options, resume);
  if (!request) return print_error(request.message());
  const scan::SourceRegistry sources = scan_sources(sim_source_options(options));
  auto source = sources.open(*request);
  if (!source) return print_error(source.message());
  // Hardware frame sources (v4l2:) bring no poses: those come from a tracker.
  if (!source->poses)
    return print_error("--source " + options.source +
                       ": the frames need probe poses from a tracker (--tracker)");
  log_info("scan: " + source->description);
  const scan::ScanOptions scan_options = pipeline_options(options, *source);
  const recon::ReconstructorOptions engine = engine_options(options, *source);
  auto segmentation = segmentation_stage(options, *source);
  if (!segmentation) return print_error(segmentation.message());
  const bool playback = sources.find(options.source)->playback;  // opened: a known kind
  scan::ScanPipeline pipeline(std::move(*source), std::move(*segmentation),
                              scan::make_reconstructor_stage(engine), scan_options);
  if (resume)
    if (Status restored = restore_journal(options, *resume, playback, pipeline, journal); !restored)
      return print_error(restored.message());
  pipeline.set_journal(journal);
  if (!options.out.empty())
    pipeline.add_sink(std::make_shared<FileSink>(options.out, options.save_every));
  LiveOutputs live;
  if (Status added = add_stream_sinks(options, pipeline, live); !added)
    return print_error(added.message());
  if (!add_igtl_sink(options.igtl_serve, pipeline, live.igtl)) return 1;
  if (Status started = pipeline.start(); !started) return print_error(started.message());
  const scan::ScanSummary summary = run_to_end(pipeline);
  return end_scan(options, summary, live);
}

// Where frames, poses and the calibration come from, or the scan to resume.
void add_source_options(CLI::App& app, ScanCommandOptions* options) {
  app.add_option("--resume", options->resume,
                 "Go on with the scan whose --out was DIR, after it was killed or stopped: its "
                 "options and keyframes come from DIR/scan.journal (docs/formats/scan-journal.md); "
                 "sim: and replay: sources go on at the frame after the last journalled one, "
                 "live sources from the frame they deliver now")
      ->check(CLI::ExistingDirectory);
  app.add_option("--source", options->source,
                 "Where frames and poses come from: sim:PHANTOM_SPEC (sim:default, or "
                 "LABEL:PATH[:NAME] meshes separated by commas), replay:FILE (a PLUS .igs.mha or "
                 ".igs.nrrd), igtl:HOST:PORT (an OpenIGTLink server such as PlusServer, port "
                 "18944 by default) or v4l2:/dev/videoN?size=WxH&format=F&fps=HZ&io=mmap|read&"
                 "crop=X,Y,W,H (a frame grabber; frames only, poses from --tracker; "
                 "`sonoshape devices` lists grabbers)")
      ->excludes("--resume");
  app.add_option("--tracker", options->tracker,
                 "A live tracker for the poses instead of the source's: usb:trakstar[:sensor=N,"
                 "rate=HZ,range=36|72,latency_ms=MS,product=0xID] (NDI/Ascension trakSTAR, "
                 "driveBAY over USB; defaults sensor=1, rate=80, range=36, latency_ms=0)");
  app.add_option("--calibration", options->calibration,
                 "ImageToProbe calibration: PLUS device-set XML, PLUS calibration result "
                 "(.results.xml) or JSON {\"ImageToProbe\": [16 numbers]}. Default: sim: the "
                 "simulated probe's; replay: the header's, else "
                 "<name>.plus.xml next to the file")
      ->check(CLI::ExistingFile);
  app.add_option("--pose-transform", options->pose_transform,
                 "replay: the probe's pose as PLUS names it, FROMToTO (e.g. ProbeToReference, "
                 "ToolToTracker), composed along any chain of the file's and the calibration "
                 "device set's transforms. Default: the header's DefaultFrameTransformName, "
                 "else Probe (or Tool) to Reference, Tracker, Template or StepperHome");
}

// How frames are segmented, or the site's own label maps.
void add_segmentation_options(CLI::App& app, ScanCommandOptions* options) {
  app.add_option("--segmentation", options->segmentation,
                 "Segmentation config JSON (docs/segmentation.md). Default: sim: models learnt "
                 "from simulated frames; replay: the header's, else a two-class split")
      ->check(CLI::ExistingFile);
  app.add_option("--preset", options->preset, preset_help())->check(CLI::IsMember(preset_names()));
  app.add_option("--method", options->method,
                 "Labelling: threshold, or graph-cut (refined by a multi-label graph cut whose "
                 "prior is the surfaces reconstructed so far, cut by each new frame's plane); "
                 "default: the configuration's `method`, else threshold")
      ->check(CLI::IsMember({"threshold", "graph-cut"}));
  app.add_option("--labels", options->labels,
                 "The site's own label maps instead of sonoshape's segmenter (0 background, "
                 "1..254 organs, --labels-unknown for unknown): replay: a label-map sequence "
                 "with one map per frame of the recording (3D Slicer .seq.nrrd, PLUS .mha; "
                 "Slicer's Segment<i>_Name keys name the organs); igtl: igtl:DEVICE, IMAGE "
                 "messages of that device beside the B-mode (--igtl-image), paired by "
                 "timestamp (docs/segmentation.md, \"Bring your own labels\")");
  app.add_option("--labels-unknown", options->labels_unknown,
                 "With --labels: the label value that marks unknown pixels (shadow, not "
                 "judged); 255 is sonoshape's own")
      ->check(number_in(1, 255))
      ->capture_default_str();
  app.add_option("--labels-wait-ms", options->labels_wait_ms,
                 "With --labels igtl:DEVICE: how long a frame waits for its label map (a "
                 "network's inference lags its input)")
      ->check(kFiniteNumber & number_in(0.0, 60000.0))
      ->capture_default_str();
  app.add_option("--organ-seed", options->seeds,
                 "LABEL:X,Y,Z (mm, reference frame; repeatable): a point inside that organ; with "
                 "--method graph-cut it tells apart organs whose grey models look alike");
}

// Where the results go, how long the scan runs and how recordings play.
void add_output_options(CLI::App& app, ScanCommandOptions* options) {
  // --out: the old spelling; every other command says -o,--output.
  app.add_option("-o,--output,--out", options->out,
                 "Directory for the meshes (label_<id>.ply), slices.json and scan.json, written "
                 "at the end (also after Ctrl-C or a failing source), and the journal of the "
                 "keyframes (scan.journal), written as they are accepted: see --resume");
  app.add_option("--save-every", options->save_every,
                 "Also write the meshes to --out every N slices (0: at the end only)")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
  app.add_option("--duration", options->duration_s, "Stop after this many seconds (0: no limit)")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
  auto* realtime = app.add_flag("--realtime", options->real_time,
                                "Play recorded and simulated sources at their frame rate; frames "
                                "the pipeline cannot take are dropped (default)");
  auto* fast = app.add_flag("--fast", options->fast,
                            "Play recorded and simulated sources as fast as the pipeline goes; "
                            "nothing is dropped for being late");
  realtime->excludes(fast);
  app.add_option("--playback-speed", options->speed,
                 "Real-time factor of --realtime playback (2: twice as fast as recorded)")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--max-slices", options->max_slices,
                 "Stop once this many keyframes are chosen (0: no limit)")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
}

// The live outputs: the mesh stream (ZeroMQ), the browser view and OpenIGTLink.
void add_stream_options(CLI::App& app, ScanCommandOptions* options) {
  app.add_option("--publish", options->publish,
                 "ZeroMQ PUB endpoint of the live mesh stream (docs/formats/mesh-stream.md), "
                 "e.g. tcp://127.0.0.1:5556");
  app.add_option("--snapshot", options->snapshot,
                 "Snapshot endpoint for late joiners (default: the --publish port + 1)");
  app.add_option("--curve-secret-key", options->curve_secret_key,
                 "The stream's CURVE secret key file (NAME.key from `sonoshape keys -o NAME`): "
                 "encrypts the stream, and only subscribers given NAME.pub (--server-key) can "
                 "read it; needed, with --allow-remote, for an endpoint other machines can reach");
  app.add_flag("--allow-remote", options->allow_remote,
               "Allow --publish/--snapshot on an endpoint other machines can reach (not "
               "127.0.0.0/8, ::1, ipc:// or inproc://); needs --curve-secret-key");
  app.add_option("--view", options->view,
                 "Show the scan live in the browser: serve the page on HOST:PORT (default " +
                     std::string(kDefaultViewAddress) +
                     ", loopback) and publish the mesh stream (on --publish, else "
                     "tcp://127.0.0.1:5556) for it")
      ->expected(0, 1);
  app.add_flag("--view-hold", options->view_hold,
               "With --view: after the scan, keep showing it until Ctrl-C");
  app.add_option("--publish-frames", options->publish_frames_hz,
                 "Publish at most this many B-mode frames a second on the mesh stream, as grey "
                 "pictures of at most 256 px a side on their planes (`frame` messages; default 5 "
                 "with --view, else 0: none)")
      ->check(kNonNegativeNumber);
  app.add_option("--igtl-serve", options->igtl_serve,
                 "Serve the scan over OpenIGTLink on [HOST:]PORT (host 127.0.0.1 unless given; "
                 "port 0 picks a free one): surfaces as POLYDATA named after the labels, the frame "
                 "as IMAGE with its pose, STATUS; for 3D Slicer's OpenIGTLinkIF (18944 is its "
                 "default port)");
}

// Pairing frames with tracker samples.
void add_sync_options(CLI::App& app, ScanCommandOptions* options) {
  app.add_option("--tracker-latency-ms", options->tracker_latency_ms,
                 "How late the tracker's timestamps are relative to the frames (ms). Default: "
                 "the source's (sim: the simulated latency; replay: 0; --tracker usb:trakstar: "
                 "0, as it subtracts its own latency_ms)")
      ->check(kFiniteNumber);
  app.add_option("--max-pose-gap-ms", options->max_pose_gap_ms,
                 "Tracker samples further apart than this do not interpolate a pose (ms)")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--max-extrapolation-ms", options->max_extrapolation_ms,
                 "How far beyond the tracker samples a pose may be extrapolated (ms)")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
  app.add_option("--pose-wait-ms", options->pose_wait_ms,
                 "How long a frame waits for the tracker sample after it (ms)")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
}

// Which frames become slices, and the queues between the stages.
void add_keyframe_options(CLI::App& app, ScanCommandOptions* options) {
  app.add_option("--keyframe-angle-deg", options->keyframe_angle_deg,
                 "A frame is a new slice when its plane turns by at least this much...")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
  app.add_option("--keyframe-distance-mm", options->keyframe_distance_mm,
                 "...or an image corner moves at least this far out of every slice's plane. "
                 "Default: 1.5 with the thin-plate field (more slices to average the "
                 "segmentation's error over), 2.5 with the mean-value field")
      ->check(kNonNegativeNumber);
  app.add_option("--slice-budget", options->slice_budget,
                 "Long examinations: past this many slices a frame must differ by twice both "
                 "keyframe thresholds, so that memory stops growing once the anatomy is covered "
                 "(0: no budget)")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
  app.add_option("--segmentation-queue", options->segmentation_queue,
                 "Keyframes waiting for segmentation")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--reconstruction-queue", options->reconstruction_queue,
                 "Slices waiting for the reconstruction")
      ->check(kPositiveNumber)
      ->capture_default_str();
}

// The reconstruction engine (shared with reconstruct) and the scan volume.
void add_scan_engine_options(CLI::App& app, ScanCommandOptions* options) {
  add_engine_options(app, {options->depth, options->smoothing, options->field, options->device});
  app.add_option(
         "--bounds", options->bounds,
         "Scan volume xmin ymin zmin xmax ymax zmax (mm, reference frame). Default: "
         "sim: the phantom's box + 10%; replay: the box of the recording's swept sectors + 10% "
         "(known before the first frame, so that updates stay incremental); igtl:, "
         "v4l2:: grown from the slices (each growth rebuilds every cell)")
      ->expected(6)
      ->check(kFiniteNumber);
}

// The options of one kind of source each.
void add_source_groups(CLI::App& app, ScanCommandOptions* options) {
  CLI::Option_group* sim = app.add_option_group("Simulated source (sim:)");
  add_sim_scenario_options(*sim, options->sim, SimOptionsFor::scan);
  sim->add_option("--sweep-s", options->sweep_s, "Length of the simulated sweep (s)")
      ->check(kPositiveNumber)
      ->capture_default_str();
  sim->add_option("--sim-fail-after-s", options->fail_after_s,
                  "Fault injection: the simulated probe vanishes after this many seconds")
      ->check(kNonNegativeNumber);
  CLI::Option_group* igtl = app.add_option_group("OpenIGTLink source (igtl:)");
  igtl->add_option("--igtl-image", options->igtl_image,
                   "IMAGE device name of the frames (default: any IMAGE)");
  igtl->add_option("--igtl-transform", options->igtl_transform,
                   "TRANSFORM device name holding the probe pose in the reference frame (PLUS: "
                   "ProbeToReference, or ProbeToTracker with the tracker as reference); "
                   "'tdata:NAME': the tool NAME of TDATA messages (streaming requested with "
                   "STT_TDATA); 'image': each IMAGE's own pose (then no --calibration is needed)")
      ->capture_default_str();
  igtl->add_option("--igtl-tracker", options->igtl_tracker,
                   "HOST:PORT of the server sending the TRANSFORMs (default: the --source one)");
}

void add_scan_options(CLI::App& app, ScanCommandOptions& o) {
  ScanCommandOptions* options = &o;
  options->sim.frame_rate_hz = 30.0;
  options->sim.width_px = 256;
  options->sim.height_px = 256;
  add_source_options(app, options);
  add_segmentation_options(app, options);
  add_output_options(app, options);
  add_stream_options(app, options);
  add_sync_options(app, options);
  add_keyframe_options(app, options);
  add_scan_engine_options(app, options);
  add_source_groups(app, options);
}

}  // namespace

CommandRunner add_scan_command(CLI::App& app) {
  auto options = std::make_shared<ScanCommandOptions>();
  add_scan_options(app, *options);
  return [options] {
    if (!options->resume.empty()) return resume_scan(options->resume);
    if (options->source.empty()) {
      std::cerr << "error: --source is required (or --resume DIR)\n";
      return 1;
    }
    return run_scan(*options, nullptr);
  };
}

}  // namespace sonoshape::apps
