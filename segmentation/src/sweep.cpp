#include "sonoshape/segmentation/sweep.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/acquisition/probe.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/input_file.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/segmentation/contours.hpp"
#include "sonoshape/segmentation/labeller.hpp"

namespace sonoshape::segmentation {
namespace {

// Frames sampled for an automatic sector and for the two-class model (every frame would cost
// time and add nothing).
constexpr std::size_t kMaxSampledFrames = 32;
// Pixel stride of the samples of the two-class model.
constexpr int kSampleStridePx = 3;
// Planes closer than this (mm, and in normal direction) are one plane for the slice set.
constexpr double kCoincidentMm = 1e-6;

// "1:70.5 2:171" -> {1: 70.5, 2: 171}; names keep their text.
std::map<int, std::string> parse_items(const std::string& text) {
  std::map<int, std::string> items;
  std::istringstream in(text);
  std::string item;
  while (in >> item) {
    const std::size_t colon = item.find(':');
    if (colon == std::string::npos) continue;
    int key = 0;
    const auto [end, ec] = std::from_chars(item.data(), item.data() + colon, key);
    if (ec != std::errc() || end != item.data() + colon) continue;
    items[key] = item.substr(colon + 1);
  }
  return items;
}

std::optional<double> to_number(const std::string& text) {
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
    return std::nullopt;
  return value;
}

// The label models the simulator writes in the header; none when it has none.
std::optional<std::pair<LabelModel, std::vector<LabelModel>>> header_models(
    const acquisition::SequenceFile& file) {
  const auto means = file.field("SonoshapeLabelGreyMean");
  const auto stds = file.field("SonoshapeLabelGreyStd");
  if (!means || !stds) return std::nullopt;
  const auto mean_items = parse_items(*means);
  const auto std_items = parse_items(*stds);
  const auto names = parse_items(file.field("SonoshapeLabels").value_or(""));
  const auto thicknesses = parse_items(file.field("SonoshapeLabelThicknessMm").value_or(""));
  LabelModel background{0, "background", 120.0, 28.0};
  std::vector<LabelModel> materials;
  bool have_background = false;
  for (const auto& [label, text] : mean_items) {
    const auto mean = to_number(text);
    const auto it = std_items.find(label);
    const auto spread = it == std_items.end() ? std::nullopt : to_number(it->second);
    if (!mean || !spread || label < 0 || label > kMaxPixelLabel) continue;
    LabelModel m{label, "", *mean, std::max(*spread, 1.0)};
    if (label == 0) {
      m.name = "background";
      background = m;
      have_background = true;
    } else {
      const auto name = names.find(label);
      m.name = name != names.end() ? name->second : "label_" + std::to_string(label);
      if (const auto t = thicknesses.find(label); t != thicknesses.end())
        m.thickness_mm = std::max(0.0, to_number(t->second).value_or(0.0));
      materials.push_back(m);
    }
  }
  if (!have_background || materials.empty()) return std::nullopt;
  return std::make_pair(background, materials);
}

std::filesystem::path sidecar_path(const std::filesystem::path& sequence) {
  std::string name = sequence.filename().string();
  for (const std::string ext : {".igs.mha", ".seq.mha", ".mha", ".igs.mhd", ".mhd", ".igs.nrrd",
                                ".seq.nrrd", ".nrrd", ".nhdr"})
    if (name.size() > ext.size() && name.ends_with(ext)) {
      name.resize(name.size() - ext.size());
      break;
    }
  return sequence.parent_path() / (name + ".plus.xml");
}

// Frames smaller than this hold no image to segment.
constexpr int kMinFramePx = 8;

bool has_extension(const std::filesystem::path& path, std::string_view wanted) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext == wanted;
}

bool is_xml(const std::filesystem::path& path) { return has_extension(path, ".xml"); }

double calibration_spacing_mm(const Eigen::Matrix4d& T_probe_image) {
  return std::sqrt(T_probe_image.block<3, 1>(0, 0).norm() * T_probe_image.block<3, 1>(0, 1).norm());
}

// The sector of a simulated sweep from its probe.
ImageGeometry probe_geometry(const acquisition::Probe& probe) {
  ImageGeometry g;
  g.width_px = probe.width_px();
  g.height_px = probe.height_px();
  g.sector = probe.sector_mask();
  for (const Vec2& p : probe.sector_ring_mm(128)) g.sector_px.push_back(probe.mm_to_pixel(p));
  g.spacing_mm = probe.spacing_mm();
  g.depth_mm.resize(g.sector.pixels.size());
  for (int j = 0; j < g.height_px; ++j)
    for (int i = 0; i < g.width_px; ++i) {
      const Vec2 beam = probe.mm_to_beam(probe.pixel_to_mm(i, j));
      g.depth_mm[static_cast<std::size_t>(j) * g.width_px + i] =
          static_cast<float>(std::max(0.0, probe.sample_depth_mm(beam.y())));
    }
  return g;
}

std::vector<const GreyImage*> sampled_frames(const acquisition::SequenceFile& file) {
  std::vector<const GreyImage*> frames;
  const std::size_t n = file.frame_count();
  const std::size_t step = std::max<std::size_t>(1, n / kMaxSampledFrames);
  for (std::size_t k = 0; k < n; k += step) frames.push_back(&file.image(k));
  return frames;
}

// "dropped 2 regions (invalid_region unknown 0.4 mm²: ...; ...)" for a frame's warning.
std::string describe(const std::vector<Repair>& repairs) {
  std::ostringstream text;
  text << repairs.size() << (repairs.size() == 1 ? " repair: " : " repairs: ");
  for (std::size_t k = 0; k < repairs.size(); ++k) {
    const Repair& r = repairs[k];
    text << (k ? "; " : "") << r.kind << " (" << r.where << ", " << r.area_changed_mm2
         << " mm^2): " << r.detail;
  }
  return text.str();
}

std::size_t unknown_in_sector(const LabelImage& labels, const ImageGeometry& geometry) {
  std::size_t count = 0;
  for (std::size_t p = 0; p < labels.pixels.size(); ++p)
    count += geometry.sector.pixels[p] && labels.pixels[p] == kLabelPixelUnknown ? 1 : 0;
  return count;
}

// Median-filtered grey levels of the sector's pixels (every kSampleStridePx-th row and column)
// of the sampled frames: what the label models are learnt from.
std::vector<std::uint8_t> sector_samples(const acquisition::SequenceFile& file,
                                         const SweepSetup& setup) {
  std::vector<std::uint8_t> samples;
  cv::Mat filtered;
  for (const GreyImage* frame : sampled_frames(file)) {
    const cv::Mat image(frame->height, frame->width, CV_8U,
                        const_cast<std::uint8_t*>(frame->pixels.data()));
    cv::medianBlur(image, filtered, setup.config.median_px);
    for (int j = 0; j < image.rows; j += kSampleStridePx)
      for (int i = 0; i < image.cols; i += kSampleStridePx)
        if (setup.geometry.sector.at(i, j)) samples.push_back(filtered.at<std::uint8_t>(j, i));
  }
  return samples;
}

}  // namespace

Result<ImageGeometry> geometry_from_header(const acquisition::FieldList& fields) {
  auto probe = acquisition::probe_from_fields(fields);
  if (!probe) return probe.status();
  return probe_geometry(*probe);
}

Result<Eigen::Matrix4d> read_calibration(const std::filesystem::path& path) {
  if (is_xml(path)) return acquisition::read_image_to_probe(path);
  if (!has_extension(path, ".json"))
    return Status::error("calibration " + path.string() +
                         ": give a PLUS device-set .xml or calibration result .results.xml "
                         "(Transform From=\"Image\" To=\"Probe\") or a .json {\"ImageToProbe\": "
                         "[16 numbers, row-major]}");
  Result<std::string> text = read_input_file(path, "the calibration");
  if (!text) return text.status();
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(*text);
  } catch (const nlohmann::json::exception& e) {
    return Status::error("calibration " + path.string() + ": not valid JSON (" + e.what() + ")");
  }
  const auto it = doc.find("ImageToProbe");
  if (it == doc.end() || !it->is_array() || it->size() != 16)
    return Status::error("calibration " + path.string() +
                         ": expected {\"ImageToProbe\": [16 numbers, row-major]} (pixels to mm)");
  Eigen::Matrix4d m;
  for (int k = 0; k < 16; ++k) {
    const auto& x = (*it)[static_cast<std::size_t>(k)];
    if (!x.is_number() || !std::isfinite(x.get<double>()))
      return Status::error("calibration " + path.string() + ": ImageToProbe[" + std::to_string(k) +
                           "] is not a finite number");
    m(k / 4, k % 4) = x.get<double>();
  }
  return m;
}

Result<SweepSetup> prepare_sweep(const acquisition::SequenceFile& file,
                                 const std::filesystem::path& sequence_path,
                                 const std::optional<std::filesystem::path>& config_path,
                                 const std::optional<std::filesystem::path>& calibration_path,
                                 std::string_view pose_transform, std::string_view preset) {
  std::optional<SegmentationConfig> config;
  if (config_path || !preset.empty()) {
    auto read = load_segmentation_config(config_path, preset);
    if (!read) return read.status();
    config = std::move(*read);
  }
  std::optional<Eigen::Matrix4d> calibration;
  acquisition::PlusConfig coordinates;
  if (calibration_path) {
    auto read = read_calibration(*calibration_path);
    if (!read) return read.status();
    calibration = *read;
    if (is_xml(*calibration_path))
      if (auto device_set = acquisition::read_plus_config(*calibration_path))
        coordinates = *device_set;
  }
  auto setup = prepare_sweep(file, sequence_path, config, calibration, pose_transform, coordinates);
  // "config" from the in-memory overload: name the file and the preset.
  if (setup && (config_path || !preset.empty()) && setup->models_from.starts_with("config"))
    setup->models_from.insert(
        6, " (" +
               (config_path ? config_path->string() + (preset.empty() ? "" : " over ")
                            : std::string()) +
               (preset.empty() ? "" : "preset " + std::string(preset)) + ")");
  // "given" (and a crop note) from the in-memory overload: name the file instead.
  if (setup && calibration_path)
    setup->calibration_from = calibration_path->string() + setup->calibration_from.substr(5);
  return setup;
}

namespace {

// The calibration: given, in the header, or in the sidecar PLUS configuration (whose
// coordinate definitions then replace `coordinates`).
Status find_calibration(const acquisition::SequenceFile& file,
                        const std::filesystem::path& sequence_path,
                        const std::optional<Eigen::Matrix4d>& T_probe_image, SweepSetup& setup,
                        acquisition::PlusConfig& coordinates) {
  if (T_probe_image) {
    setup.T_probe_image = *T_probe_image;
    setup.calibration_from = "given";
  } else if (const auto text = file.field("ImageToProbeTransform");
             text && acquisition::parse_matrix(*text)) {
    setup.T_probe_image = *acquisition::parse_matrix(*text);
    setup.calibration_from = "header ImageToProbeTransform";
  } else if (const auto sidecar = sidecar_path(sequence_path); std::filesystem::exists(sidecar)) {
    auto read = acquisition::read_image_to_probe(sidecar);
    if (!read) return read.status();
    setup.T_probe_image = *read;
    setup.calibration_from = sidecar.string();
    if (auto device_set = acquisition::read_plus_config(sidecar)) coordinates = *device_set;
  } else {
    return Status::error(sequence_path.string() +
                         ": no calibration (no ImageToProbeTransform in the header and no " +
                         sidecar.string() +
                         "); give one with --calibration PLUS.xml or a JSON {\"ImageToProbe\": "
                         "[16 numbers]}");
  }
  return Status::ok();
}

// The pose (the chain of transforms from the probe to the reconstruction's frame) and the crop:
// a cropped recording's pixels start at the crop's corner (PLUS ImageToCroppedImage).
Status find_pose_and_crop(const acquisition::SequenceFile& file,
                          const std::filesystem::path& sequence_path,
                          std::string_view pose_transform,
                          const acquisition::PlusConfig& coordinates, SweepSetup& setup) {
  auto chain = acquisition::find_pose_chain(file, sequence_path, pose_transform, coordinates);
  if (!chain) return chain.status();
  setup.pose_chain = std::move(*chain);
  auto crop = acquisition::image_to_cropped_image(file, sequence_path);
  if (!crop) return crop.status();
  if (*crop) {
    setup.T_probe_image = setup.T_probe_image * (*crop)->inverse();
    setup.calibration_from += " * ImageToCroppedImage^-1 (the crop)";
  }
  return Status::ok();
}

// The sector of the simulator's probe that the header names (SonoshapeProbeType).
Status sector_of_header_probe(const acquisition::SequenceFile& file,
                              const std::filesystem::path& sequence_path, SweepSetup& setup) {
  auto probe = acquisition::probe_from_fields(file.fields());
  if (!probe) return probe.status();
  const int w = file.width(), h = file.height();
  if (probe->width_px() != w || probe->height_px() != h)
    return Status::error(sequence_path.string() + ": the header's probe image is " +
                         std::to_string(probe->width_px()) + "x" +
                         std::to_string(probe->height_px()) + " but the frames are " +
                         std::to_string(w) + "x" + std::to_string(h));
  setup.geometry = probe_geometry(*probe);
  setup.sector_from = "header probe (" + acquisition::to_string(probe->type()) + ")";
  return Status::ok();
}

// The sector: the header's probe, the pixels with signal, the full image or the config's polygon.
Status choose_sector(const acquisition::SequenceFile& file,
                     const std::filesystem::path& sequence_path, double spacing_mm,
                     SweepSetup& setup) {
  const int w = file.width(), h = file.height();
  SectorSource source = setup.config.sector;
  if (source == SectorSource::kDefault) {
    if (file.field("SonoshapeProbeType")) return sector_of_header_probe(file, sequence_path, setup);
    source = SectorSource::kAuto;
  }
  if (source == SectorSource::kAuto) {
    setup.geometry =
        auto_geometry(sampled_frames(file), spacing_mm, setup.config.sector_signal_grey);
    setup.sector_from = "auto (pixels with signal)";
  } else if (source == SectorSource::kFull) {
    setup.geometry = full_image_geometry(w, h, spacing_mm);
    setup.sector_from = "full image";
  } else if (source == SectorSource::kPolygon) {
    // Every slice's fov is this polygon: a self-crossing one would fail every frame.
    SliceSet check;
    check.slices.emplace_back().fov = setup.config.sector_polygon_px;
    if (const Status valid = validate_slice_set(check, "the config's sector polygon"); !valid)
      return Status::error(valid.message() +
                           " (the \"sector\" of the segmentation config, in "
                           "pixels; give a simple polygon)");
    setup.geometry = polygon_geometry(w, h, spacing_mm, setup.config.sector_polygon_px);
    setup.sector_from = "config polygon";
  }
  return Status::ok();
}

// The imaging system's blur, when the configuration does not give it: the header's.
void take_header_psf(const acquisition::SequenceFile& file, SegmentationConfig& config) {
  if (config.psf_sigma_mm >= 0.0) return;
  if (const auto sigma = file.field("SonoshapePsfSigmaMm")) {
    config.psf_sigma_mm = std::max(0.0, to_number(*sigma).value_or(0.0));
    if (const auto range = file.field("SonoshapeDynamicRangeDb"))
      config.dynamic_range_db = to_number(*range).value_or(config.dynamic_range_db);
  }
}

// Label models: the config's (refined on the frames when it says so), the header's, or two
// classes found in the data.
void choose_label_models(const acquisition::SequenceFile& file, SweepSetup& setup) {
  if (setup.config.materials.empty()) {
    if (const auto models = header_models(file)) {
      setup.config.background = models->first;
      setup.config.materials = models->second;
      setup.models_from = "header (SonoshapeLabelGreyMean/Std)";
    } else {
      setup.config = auto_two_class(sector_samples(file, setup), setup.config);
      setup.models_from = "two-class k-means on the frames";
    }
  } else if (setup.config.learn_models) {
    setup.config = learn_models_from_samples(sector_samples(file, setup), setup.config);
    setup.models_from += ", learnt from the frames (k-means from the given means)";
  }
}

}  // namespace

Result<SweepSetup> prepare_sweep(const acquisition::SequenceFile& file,
                                 const std::filesystem::path& sequence_path,
                                 const std::optional<SegmentationConfig>& config,
                                 const std::optional<Eigen::Matrix4d>& T_probe_image,
                                 std::string_view pose_transform,
                                 const acquisition::PlusConfig& coordinates) {
  if (file.frame_count() == 0)
    return Status::error(sequence_path.string() + ": the sequence has no frames");
  SweepSetup setup;
  acquisition::PlusConfig fixed = coordinates;
  setup.config = config.value_or(SegmentationConfig{});
  setup.models_from = config ? "config" : "defaults";
  if (Status found = find_calibration(file, sequence_path, T_probe_image, setup, fixed); !found)
    return found;
  if (Status found = find_pose_and_crop(file, sequence_path, pose_transform, fixed, setup); !found)
    return found;
  const double spacing_mm = calibration_spacing_mm(setup.T_probe_image);
  if (!(spacing_mm > 0.0) || !std::isfinite(spacing_mm))
    return Status::error(setup.calibration_from + ": the ImageToProbe calibration is degenerate");
  if (Status chosen = choose_sector(file, sequence_path, spacing_mm, setup); !chosen) return chosen;
  take_header_psf(file, setup.config);
  choose_label_models(file, setup);
  if (const Status valid = setup.config.validate(); !valid) return valid;
  return setup;
}

std::optional<Eigen::Matrix4d> reference_from_probe(const acquisition::SequenceFile& file,
                                                    std::size_t k) {
  if (file.transform_status("ProbeToTracker", k) != TrackingStatus::kValid) return std::nullopt;
  const auto probe = file.transform("ProbeToTracker", k);
  if (!probe) return std::nullopt;
  const auto names = file.transform_names();
  if (std::find(names.begin(), names.end(), "ReferenceToTracker") == names.end()) return *probe;
  if (file.transform_status("ReferenceToTracker", k) != TrackingStatus::kValid) return std::nullopt;
  const auto reference = file.transform("ReferenceToTracker", k);
  if (!reference) return std::nullopt;
  return Eigen::Matrix4d(reference->inverse() * *probe);
}

Status normalise_recording(acquisition::SequenceFile& file, const std::filesystem::path& path) {
  // PLUS saves a tracker's buffer with 1x1 dummy images: poses, no B-mode.
  if (file.frame_count() && (file.width() < kMinFramePx || file.height() < kMinFramePx))
    return Status::error("sequence file " + path.string() + ": the frames are " +
                         std::to_string(file.width()) + "x" + std::to_string(file.height()) +
                         " pixels, no B-mode images (a tracker-only buffer); give the recording "
                         "of the video (PLUS saves tracker and video buffers separately)");
  const std::string orientation = file.field("UltrasoundImageOrientation").value_or("MF");
  auto flipped = acquisition::reorient_to_mf(file, path);
  if (!flipped) return flipped.status();
  if (*flipped)
    log_info(path.string() + ": UltrasoundImageOrientation = " + orientation +
             ": frames flipped to MF as PLUS does on reading");
  if (const auto rate_hz = acquisition::fill_missing_timestamps(file)) {
    std::ostringstream text;
    text << path.string() << ": no frame has a Timestamp; frame k is taken at k / " << *rate_hz
         << " s (" << *rate_hz << " Hz, "
         << (file.field("AcquisitionFrameRate") ? "the header's AcquisitionFrameRate"
                                                : "a nominal rate")
         << ") so that every frame is replayed; give the frames their Timestamp (or the header "
            "an AcquisitionFrameRate) for the real timing";
    log_warning(text.str());
  }
  return Status::ok();
}

std::optional<Eigen::Matrix4d> reference_from_probe(const acquisition::SequenceFile& file,
                                                    std::size_t k, const SweepSetup& setup) {
  if (!setup.pose_chain) return reference_from_probe(file, k);
  return setup.pose_chain->pose(file, k);
}

namespace {

void check_sweep_inputs(const acquisition::SequenceFile& file, const SweepSetup& setup, int every,
                        const SweepLabels& labels) {
  if (every < 1) throw std::invalid_argument("segment_sweep: every must be >= 1");
  if (file.frame_count() &&
      (file.width() != setup.geometry.width_px || file.height() != setup.geometry.height_px))
    throw std::invalid_argument("segment_sweep: the frames do not match the setup's geometry");
  for (const acquisition::SequenceFile* other : {labels.perfect, labels.truth})
    if (other)
      if (const Status same = check_truth_labels(file, "the sweep", *other, "the label frames");
          !same)
        throw std::invalid_argument("segment_sweep: " + same.message());
}

// A slice in the plane of one already kept (a frozen probe repeats its plane; the slice-set
// format allows one slice per plane).
bool coincides_with_one_of(const LabeledSlice& slice, const std::vector<LabeledSlice>& kept) {
  const Vec3 n = slice.normal();
  return std::any_of(kept.begin(), kept.end(), [&](const LabeledSlice& s) {
    return std::abs(std::abs(s.normal().dot(n)) - 1.0) < 1e-12 &&
           std::abs(n.dot(slice.origin_mm - s.origin_mm)) < kCoincidentMm;
  });
}

// Perfect label frames may show a label the models lack (a bone whose every pixel lies in its
// own shadow has no grey model): declares it, named as the header names it, casting a shadow
// where the header gives it a thickness (a bone, drawn whole).
void declare_labels_of_regions(const acquisition::SequenceFile& file, SliceSet& slices) {
  const auto names = parse_items(file.field("SonoshapeLabels").value_or(""));
  const auto thicknesses = parse_items(file.field("SonoshapeLabelThicknessMm").value_or(""));
  for (const LabeledSlice& slice : slices.slices)
    for (const Region& r : slice.regions) {
      if (r.label == kUnknownLabel) continue;
      auto& declared = slices.labels;
      if (std::any_of(declared.begin(), declared.end(),
                      [&](const LabelInfo& l) { return l.id == r.label; }))
        continue;
      const auto name = names.find(r.label);
      const auto thickness = thicknesses.find(r.label);
      declared.push_back(
          {r.label, name != names.end() ? name->second : "label_" + std::to_string(r.label),
           thickness != thicknesses.end() && to_number(thickness->second).value_or(0.0) > 0.0});
    }
}

// One sweep's segmentation, frame by frame: pose and plane, label map, its tallies, the slice
// (with its repairs), and the slice kept unless its plane is already there.
class SweepRun {
 public:
  SweepRun(const acquisition::SequenceFile& file, const SweepSetup& setup,
           const SweepProgress& progress, const ReadOptions& options, const SweepLabels& labels)
      : file_(file),
        setup_(setup),
        progress_(progress),
        options_(options),
        labels_(labels),
        shares_(setup.geometry.sector) {
    out_.frames = file.frame_count();
    for (const LabelModel& m : setup.config.materials) out_.slices.labels.push_back(slice_label(m));
    for (const std::uint8_t v : setup.geometry.sector.pixels) sector_px_ += v ? 1 : 0;
    if (!labels.perfect && setup.config.method == LabellingMethod::kGraphCut)
      labeller_.emplace(setup.config, setup.geometry, setup.config.graph_cut);
  }

  // Segments frame k; false when --strict refuses its repairs (the sweep stops there).
  bool segment_frame_at(std::size_t k) {
    ++out_.considered;
    const auto pose = reference_from_probe(file_, k, setup_);
    if (!pose) {
      ++out_.invalid_pose;
      report_progress();
      return true;
    }
    const ImagePlane plane = image_plane(*pose * setup_.T_probe_image, pose->block<3, 1>(0, 3));
    const LabelImage frame_labels = label_frame(k, plane);
    tally_labels(k, frame_labels);
    std::vector<Repair> repairs;
    // Label maps that replace the segmenter are taken as drawn: their pixels' outlines, exact.
    const OutlineForm form = labels_.perfect ? OutlineForm::kPixelEdges : OutlineForm::kSmooth;
    auto slice = make_slice(frame_labels, setup_.geometry.sector, setup_.geometry.sector_px, plane,
                            setup_.config.simplify_mm, &repairs, form);
    if (!take_repairs(k, repairs)) return false;
    if (!slice) {
      ++out_.failed;
      log_warning("segment: frame " + std::to_string(k) + " skipped: " + slice.message());
      report_progress();
      return true;
    }
    slice->timestamp_s = file_.timestamp_s(k);
    if (!labels_.perfect) slice->outline_sd_mm = setup_.config.outline_sd_mm;  // maps: as drawn
    keep_slice(std::move(*slice));
    report_progress();
    return true;
  }

  // The sweep's summary figures, its dominant-label warning and the declared labels.
  SweepSegmentation finish() {
    out_.unknown_fraction = segmented_ ? unknown_sum_ / static_cast<double>(segmented_) : 0.0;
    out_.dominant_label = shares_.dominant_label();
    if (out_.dominant_label && !labels_.perfect) {
      std::map<int, std::string> names;
      for (const LabelModel& m : setup_.config.materials) names[m.label] = m.name;
      out_.dominant_warning = shares_.warning(names).value_or("");
      log_warning("segment: " + out_.dominant_warning);
    }
    declare_labels_of_regions(file_, out_.slices);
    return std::move(out_);
  }

 private:
  void report_progress() const {
    if (progress_) progress_(out_.considered);
  }

  // The perfect label frame, or the graph cut's (with the reconstruction's prior), or the
  // segmenter's.
  LabelImage label_frame(std::size_t k, const ImagePlane& plane) {
    if (labels_.perfect) return labels_.perfect->image(k);
    if (!labeller_) return segment_frame(file_.image(k), setup_.geometry, setup_.config).labels;
    std::optional<LabelImage> prior;
    if (labels_.predictor) prior = labels_.predictor->predict(plane, setup_.geometry);
    return labeller_->segment(file_.image(k), prior ? &*prior : nullptr, &plane).labels;
  }

  // The label map's share of the sector, its labels, its comparison with the truth.
  void tally_labels(std::size_t k, const LabelImage& frame_labels) {
    if (labels_.on_label_map) labels_.on_label_map(k, frame_labels);
    shares_.add(frame_labels);
    std::array<bool, 256> present{};
    for (const std::uint8_t v : frame_labels.pixels) present[v] = true;
    for (const LabelModel& m : setup_.config.materials)
      if (present[static_cast<std::size_t>(m.label)]) ++out_.frames_with_label[m.label];
    if (labels_.truth) {
      out_.comparisons.push_back(
          {k, compare_labels(labels_.truth->image(k), frame_labels, setup_.geometry.sector)});
      out_.comparison_total.add(out_.comparisons.back().comparison);
    }
    unknown_sum_ += sector_px_
                        ? static_cast<double>(unknown_in_sector(frame_labels, setup_.geometry)) /
                              static_cast<double>(sector_px_)
                        : 0.0;
    ++segmented_;
  }

  // Records the repairs frame k's slice needed; false when --strict refuses them.
  bool take_repairs(std::size_t k, std::vector<Repair>& repairs) {
    if (repairs.empty()) return true;
    const std::string what = "frame " + std::to_string(k) + ": " + describe(repairs);
    if (options_.strict) {
      out_.refused = what;
      return false;
    }
    log_warning("segment: " + what);
    for (Repair& r : repairs) {
      r.where = "frame " + std::to_string(k) + ", " + r.where;
      out_.repairs.push_back({k, std::move(r)});
    }
    return true;
  }

  void keep_slice(LabeledSlice slice) {
    if (coincides_with_one_of(slice, out_.slices.slices)) {
      ++out_.coincident;
      return;
    }
    if (labeller_ && labels_.predictor) labels_.predictor->add(slice);
    std::set<int> in_slice;
    for (const Region& r : slice.regions)
      if (r.label != kUnknownLabel) in_slice.insert(r.label);
    for (const int l : in_slice) ++out_.slices_with_label[l];
    out_.slices.slices.push_back(std::move(slice));
  }

  const acquisition::SequenceFile& file_;
  const SweepSetup& setup_;
  const SweepProgress& progress_;
  const ReadOptions& options_;
  const SweepLabels& labels_;
  SweepSegmentation out_;
  std::size_t sector_px_ = 0;
  double unknown_sum_ = 0.0;  // sum over segmented frames of their unknown share of the sector
  std::size_t segmented_ = 0;
  SectorShareCheck shares_;
  std::optional<GraphCutLabeller> labeller_;
};

}  // namespace

SweepSegmentation segment_sweep(const acquisition::SequenceFile& file, const SweepSetup& setup,
                                int every, const SweepProgress& progress,
                                const ReadOptions& options, const SweepLabels& labels) {
  check_sweep_inputs(file, setup, every, labels);
  SweepRun run(file, setup, progress, options, labels);
  for (std::size_t k = 0; k < file.frame_count(); k += static_cast<std::size_t>(every))
    if (!run.segment_frame_at(k)) break;
  return run.finish();
}

}  // namespace sonoshape::segmentation
