#include "sonoshape/scan/sources.hpp"

#include <algorithm>

#include "sonoshape/core/log.hpp"
#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::scan {
namespace {

// --tracker: a live tracker instead of the source's poses. Its samples are stamped with
// CLOCK_MONOTONIC minus its own latency option, so the scan adds no latency of its own.
Status open_tracker(const std::string& spec, ScanSource& source) {
  const std::string trakstar = "usb:trakstar";
  if (spec.compare(0, trakstar.size(), trakstar) != 0 ||
      (spec.size() > trakstar.size() && spec[trakstar.size()] != ':'))
    return Status::error("--tracker '" + spec +
                         "': unknown tracker; use usb:trakstar[:sensor=N,rate=HZ,range=36|72,"
                         "latency_ms=MS,product=0xID]");
  auto options = tracking::parse_trakstar_options(
      spec.size() > trakstar.size() ? std::string_view(spec).substr(trakstar.size() + 1) : "");
  if (!options) return options.status();
  source.poses = std::make_unique<tracking::TrakstarPoseSource>(*options);
  source.tracker_latency_s = 0.0;
  source.description += "; poses from " + source.poses->describe();
  return Status::ok();
}

// The text before the first ':' of a spec.
std::string_view prefix_of(std::string_view spec) { return spec.substr(0, spec.find(':')); }

}  // namespace

void SourceRegistry::add(SourceKind kind) {
  const auto same = std::find_if(kinds_.begin(), kinds_.end(),
                                 [&](const SourceKind& k) { return k.prefix == kind.prefix; });
  if (same != kinds_.end())
    *same = std::move(kind);
  else
    kinds_.push_back(std::move(kind));
}

const SourceKind* SourceRegistry::find(std::string_view spec) const {
  const std::string_view prefix = prefix_of(spec);
  for (const SourceKind& kind : kinds_)
    if (kind.prefix == prefix) return &kind;
  return nullptr;
}

Result<ScanSource> SourceRegistry::open(const SourceRequest& request) const {
  const SourceKind* kind = find(request.spec);
  if (!request.labels.empty() && (!kind || kind->label_maps == LabelMapsFrom::kNone))
    return Status::error("--labels with --source " + request.spec +
                         ": label maps come from a file beside a recording (--source "
                         "replay:FILE --labels LABELS.seq.nrrd) or over OpenIGTLink (--source "
                         "igtl:HOST:PORT --labels igtl:DEVICE)");
  if (kind && kind->label_maps == LabelMapsFrom::kFile && request.labels.rfind("igtl:", 0) == 0)
    return Status::error("--labels " + request.labels +
                         ": a recording's label maps come from a file (--labels "
                         "LABELS.seq.nrrd or .mha, one label map per frame)");
  if (!kind) {
    std::string usages;
    for (const SourceKind& known : kinds_) usages += (usages.empty() ? "" : ", ") + known.usage;
    return Status::error("--source '" + request.spec + "': unknown source; use " + usages);
  }
  if (!kind->not_built.empty() || !kind->open)
    return Status::error("--source " + kind->prefix + ": " + kind->not_built);
  const std::size_t colon = request.spec.find(':');
  auto source =
      kind->open(request, colon == std::string::npos ? "" : request.spec.substr(colon + 1));
  if (!source || request.tracker.empty()) return source;
  if (Status opened = open_tracker(request.tracker, *source); !opened) return opened;
  // A grabber stamps frames with CLOCK_MONOTONIC, as the tracker does its samples; recorded
  // and simulated frames carry their own clock.
  if (kind->monotonic_clock) return source;
  log_warning("--tracker with --source " + request.spec +
              ": the frames are not stamped with CLOCK_MONOTONIC, so the tracker's poses will "
              "not pair with them; use a live frame source");
  return source;
}
}  // namespace sonoshape::scan
