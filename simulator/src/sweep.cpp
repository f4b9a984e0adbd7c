#include "sonoshape/simulator/sweep.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>

#include "sonoshape/simulator/sim_source.hpp"

namespace sonoshape::simulator {
namespace {

// Frames rendered between progress reports (and the unit of parallel work).
constexpr std::size_t kChunkFrames = 16;

std::string number(double value) {
  std::array<char, 32> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  return ec == std::errc() ? std::string(buffer.data(), end) : "nan";
}

std::string trajectory_name(SweepMotion motion) {
  switch (motion) {
    case SweepMotion::kTranslate:
      return "sweep";
    case SweepMotion::kFan:
      return "fan";
    case SweepMotion::kRock:
      return "rock";
    case SweepMotion::kRotate:
      return "rotate";
  }
  return "sweep";
}

// Appends "key:value" to a space-separated list. (Written out rather than with `a + b + c`,
// which trips GCC 12's -Wrestrict false positive.)
void append_item(std::string& list, int key, const std::string& value) {
  if (!list.empty()) list += ' ';
  list += std::to_string(key);
  list += ':';
  list += value;
}

std::string no_spaces(std::string text) {
  std::replace(text.begin(), text.end(), ' ', '_');
  return text;
}

// Grey-level sums per label value over the known pixels of one frame.
struct GreyStats {
  std::array<double, 256> sum{}, sum_sq{}, count{};
  void add(const GreyStats& o) {
    for (std::size_t l = 0; l < 256; ++l) {
      sum[l] += o.sum[l];
      sum_sq[l] += o.sum_sq[l];
      count[l] += o.count[l];
    }
  }
};

}  // namespace

std::array<int, 256> shadow_caster_runs_px(const SimulatedFrame& f) {
  std::array<bool, 256> caster{};
  for (std::size_t p = 0; p < f.truth.pixels.size(); ++p)
    if (f.shadow.pixels[p] && f.truth.pixels[p] != kLabelPixelUnknown)
      caster[f.truth.pixels[p]] = true;
  std::array<int, 256> longest{};
  for (int i = 0; i < f.truth.width; ++i) {
    int run = 0;
    std::uint8_t previous = kLabelPixelUnknown;
    for (int j = 0; j < f.truth.height; ++j) {
      const std::uint8_t l = f.truth.at(i, j);
      run = l == previous ? run + 1 : 1;
      previous = l;
      if (caster[l]) longest[l] = std::max(longest[l], run);
    }
  }
  return longest;
}

std::map<int, double> shadow_caster_thickness_mm(const std::vector<std::array<int, 256>>& runs_px,
                                                 double spacing_mm) {
  std::map<int, double> thickness;
  for (int l = 1; l < 255; ++l) {
    std::vector<int> runs;
    for (const auto& r : runs_px)
      if (r[static_cast<std::size_t>(l)] > 0) runs.push_back(r[static_cast<std::size_t>(l)]);
    if (runs.empty()) continue;
    std::nth_element(runs.begin(), runs.begin() + static_cast<std::ptrdiff_t>(runs.size() / 2),
                     runs.end());
    thickness[l] = runs[runs.size() / 2] * spacing_mm;
  }
  return thickness;
}

namespace {

// The frames of a sweep, rendered in parallel (chunks of kChunkFrames, `progress` after each),
// with each frame's grey statistics per label (what the probe sees: not a bone's shadowed
// inside) and its shadow casters' runs.
struct RenderedFrames {
  std::vector<SimulatedFrame> frames;
  std::vector<GreyStats> stats;
  std::vector<std::array<int, 256>> caster_runs_px;
};
RenderedFrames render_frames(const BModeSimulator& simulator,
                             const SimulatedAcquisition& acquisition, std::uint64_t seed,
                             const SweepProgress& progress) {
  const std::size_t n = acquisition.frame_times_s.size();
  RenderedFrames out{std::vector<SimulatedFrame>(n), std::vector<GreyStats>(n),
                     std::vector<std::array<int, 256>>(n)};
  for (std::size_t first = 0; first < n; first += kChunkFrames) {
    const std::size_t last = std::min(n, first + kChunkFrames);
    tbb::parallel_for(first, last, [&](std::size_t k) {
      // Seeds independent of the order frames run in (shared with SimFrameSource).
      out.frames[k] = simulator.render(acquisition.true_poses[k], frame_seed(seed, k));
      const SimulatedFrame& f = out.frames[k];
      for (std::size_t p = 0; p < f.truth.pixels.size(); ++p) {
        const std::uint8_t l = f.truth.pixels[p];
        if (l == kLabelPixelUnknown || f.shadow.pixels[p]) continue;
        const double grey = f.bmode.pixels[p];
        out.stats[k].sum[l] += grey;
        out.stats[k].sum_sq[l] += grey * grey;
        out.stats[k].count[l] += 1.0;
      }
      out.caster_runs_px[k] = shadow_caster_runs_px(f);
    });
    if (progress) progress(last);
  }
  return out;
}

// The header fields of the labels: names, echogenicity, the grey models learnt from the frames
// (`total`) and the thickness of organs that shadow their own inside.
void add_label_fields(const BModeSimulator& simulator, const GreyStats& total,
                      const std::vector<std::array<int, 256>>& caster_runs_px,
                      acquisition::FieldList& global) {
  const Phantom& phantom = simulator.phantom();
  std::string names, echogenicity, means, stds;
  append_item(echogenicity, 0, number(phantom.background.echogenicity));
  for (const int label : phantom.labels()) {
    std::string name;
    for (const auto& m : phantom.meshes)
      if (m.label == label) {
        name = m.name;
        break;
      }
    append_item(names, label, no_spaces(name));
    append_item(echogenicity, label, number(phantom.tissue(label).echogenicity));
  }
  for (int l = 0; l < 255; ++l) {
    const double count = total.count[static_cast<std::size_t>(l)];
    if (count == 0.0) continue;
    const double mean = total.sum[static_cast<std::size_t>(l)] / count;
    const double variance =
        std::max(0.0, total.sum_sq[static_cast<std::size_t>(l)] / count - mean * mean);
    append_item(means, l, number(std::round(mean * 100.0) / 100.0));
    append_item(stds, l, number(std::round(std::sqrt(variance) * 100.0) / 100.0));
  }
  // A segmenter sees only the surface of an organ that shadows its own inside (bone) and needs
  // its thickness to fill its cross-section.
  std::string thicknesses;
  for (const auto& [label, mm] :
       shadow_caster_thickness_mm(caster_runs_px, simulator.probe().spacing_mm()))
    append_item(thicknesses, label, number(std::round(mm * 100.0) / 100.0));
  global.emplace_back("SonoshapeLabels", names);
  global.emplace_back("SonoshapeLabelEchogenicity", echogenicity);
  global.emplace_back("SonoshapeLabelGreyMean", means);
  global.emplace_back("SonoshapeLabelGreyStd", stds);
  if (!thicknesses.empty()) global.emplace_back("SonoshapeLabelThicknessMm", thicknesses);
}

// The header fields of a simulated sweep: image, probe, labels, simulator and tracker.
acquisition::FieldList sweep_fields(const BModeSimulator& simulator,
                                    const SimulatedAcquisition& acquisition, std::uint64_t seed,
                                    const GreyStats& total,
                                    const std::vector<std::array<int, 256>>& caster_runs_px) {
  const acquisition::Probe& probe = simulator.probe();
  acquisition::FieldList global;
  global.emplace_back("UltrasoundImageOrientation", "MFA");
  global.emplace_back("UltrasoundImageType", "BRIGHTNESS");
  global.emplace_back("ElementSpacing", "1 1 1");
  global.emplace_back("ImageToProbeTransform",
                      acquisition::format_matrix(probe.T_probe_image().matrix()));
  for (auto& field : acquisition::probe_fields(probe)) global.push_back(std::move(field));
  add_label_fields(simulator, total, caster_runs_px, global);
  global.emplace_back("SonoshapeUnknownLabel", std::to_string(kLabelPixelUnknown));
  global.emplace_back("SonoshapePsfSigmaMm",
                      number(std::round(simulator.psf_sigma_mm() * 1000.0) / 1000.0));
  global.emplace_back("SonoshapeDynamicRangeDb", number(simulator.options().dynamic_range_db));
  global.emplace_back("SonoshapeShadowThresholdDb",
                      number(simulator.options().shadow_threshold_db));
  global.emplace_back("SonoshapeSeed", std::to_string(seed));
  global.emplace_back("SonoshapeTrajectory", trajectory_name(acquisition.trajectory.motion));
  global.emplace_back("SonoshapeFrameRateHz", number(acquisition.frame_rate_hz));
  global.emplace_back("SonoshapeTrackerRateHz", number(acquisition.tracker.rate_hz));
  global.emplace_back("SonoshapeTrackerLatencySec", number(acquisition.tracker.latency_s));
  global.emplace_back("SonoshapeTrackerPositionNoiseMm",
                      number(acquisition.tracker.position_noise_mm));
  global.emplace_back("SonoshapeTrackerAngleNoiseDeg", number(acquisition.tracker.angle_noise_deg));
  return global;
}

}  // namespace

SimulatedSweep simulate_sweep(const BModeSimulator& simulator,
                              const SimulatedAcquisition& acquisition, std::uint64_t seed,
                              const SweepProgress& progress) {
  const std::size_t n = acquisition.frame_times_s.size();
  RenderedFrames rendered = render_frames(simulator, acquisition, seed, progress);
  SimulatedSweep sweep;
  GreyStats total;
  double shadow_sum = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    total.add(rendered.stats[k]);
    shadow_sum += rendered.frames[k].shadow_fraction;
  }
  sweep.mean_shadow_fraction = n ? shadow_sum / static_cast<double>(n) : 0.0;
  const acquisition::FieldList global =
      sweep_fields(simulator, acquisition, seed, total, rendered.caster_runs_px);
  for (auto& [key, value] : global) sweep.bmode.set_field(key, value);
  for (auto& [key, value] : global) sweep.truth.set_field(key, value);
  sweep.truth.set_field("UltrasoundImageType", "LABELS");
  sweep.truth.set_field("SonoshapeContent",
                        "ground-truth labels: 0 background, label ids, 255 "
                        "unknown (outside the sector, shadow)");
  const Eigen::Matrix4d identity = Eigen::Matrix4d::Identity();
  sweep.slices.reserve(n);
  for (std::size_t k = 0; k < n; ++k) {
    acquisition::FieldList fields;
    fields.emplace_back("Timestamp", number(acquisition.frame_times_s[k]));
    fields.emplace_back("ImageStatus", "OK");
    SimulatedFrame& f = rendered.frames[k];
    sweep.bmode.add_frame(std::move(f.bmode), fields);
    sweep.truth.add_frame(std::move(f.truth), fields);
    for (acquisition::SequenceFile* file : {&sweep.bmode, &sweep.truth}) {
      const Pose& tracked = acquisition.tracked_poses[k];
      file->set_transform("ProbeToTracker", k, tracked.T_reference_probe.matrix(), tracked.status);
      file->set_transform("ReferenceToTracker", k, identity, TrackingStatus::kValid);
      file->set_transform("TrueProbeToReference", k, acquisition.true_poses[k].matrix(),
                          TrackingStatus::kValid);
    }
    f.slice.timestamp_s = acquisition.frame_times_s[k];
    sweep.slices.push_back(std::move(f.slice));
  }
  return sweep;
}

}  // namespace sonoshape::simulator
