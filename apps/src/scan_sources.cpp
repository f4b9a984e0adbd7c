// The composition of `sonoshape scan`'s sources: one entry per kind, each backend under its
// one build option. `sonoshape scan` opens through this registry and `sonoshape devices` lists
// its devices from it.
#include "sonoshape/apps/scan_sources.hpp"

#include <ostream>
#ifdef SONOSHAPE_WITH_V4L2
#include "sonoshape/acquisition/v4l2_devices.hpp"
#endif

namespace sonoshape::apps {
namespace {

scan::SourceKind sim_kind(const SimSourceOptions& sim) {
  scan::SourceKind kind;
  kind.prefix = "sim";
  kind.usage = "sim:PHANTOM_SPEC (e.g. sim:default)";
  kind.playback = true;
  kind.open = [sim](const scan::SourceRequest& request, const std::string& phantom_spec) {
    return open_sim_source(request, sim, phantom_spec);
  };
  return kind;
}

scan::SourceKind replay_kind() {
  scan::SourceKind kind;
  kind.prefix = "replay";
  kind.usage = "replay:FILE.igs.mha";
  kind.playback = true;
  kind.label_maps = scan::LabelMapsFrom::kFile;
  kind.open = scan::open_replay_source;
  return kind;
}

scan::SourceKind igtl_kind() {
  scan::SourceKind kind;
  kind.prefix = "igtl";
  kind.usage = "igtl:HOST:PORT";
  kind.label_maps = scan::LabelMapsFrom::kStream;
#ifdef SONOSHAPE_WITH_OPENIGTLINK
  kind.open = scan::open_igtl_source;
#else
  kind.not_built =
      "this sonoshape was built without OpenIGTLink; install libopenigtlink-dev "
      "(scripts/install-deps) and configure with -DSONOSHAPE_WITH_OPENIGTLINK=ON";
#endif
  return kind;
}

scan::SourceKind v4l2_kind() {
  scan::SourceKind kind;
  kind.prefix = "v4l2";
  kind.usage = "v4l2:/dev/videoN (`sonoshape devices` lists them)";
  kind.monotonic_clock = true;
#ifdef SONOSHAPE_WITH_V4L2
  kind.open = scan::open_v4l2_source;
  kind.list_devices = [](std::ostream& out) {
    std::vector<std::string> unreadable;
    const auto devices = acquisition::list_v4l2_devices(*acquisition::system_v4l2_device(),
                                                        "/sys/class/video4linux", &unreadable);
    out << acquisition::v4l2_devices_report(devices, unreadable);
  };
#else
  kind.not_built =
      "this sonoshape was built without V4L2 frame grabbers; configure with "
      "-DSONOSHAPE_WITH_V4L2=ON on Linux";
  kind.list_devices = [](std::ostream& out) {
    out << "Frame grabbers (V4L2): not built (configure with -DSONOSHAPE_WITH_V4L2=ON on "
           "Linux)\n";
  };
#endif
  return kind;
}

}  // namespace

scan::SourceRegistry scan_sources(const SimSourceOptions& sim) {
  scan::SourceRegistry registry;
  registry.add(sim_kind(sim));
  registry.add(replay_kind());
  registry.add(igtl_kind());
  registry.add(v4l2_kind());
  return registry;
}

Result<scan::ScanSource> open_scan_source(const scan::SourceRequest& request,
                                          const SimSourceOptions& sim) {
  return scan_sources(sim).open(request);
}

}  // namespace sonoshape::apps
