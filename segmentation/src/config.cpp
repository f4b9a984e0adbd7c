#include "sonoshape/segmentation/config.hpp"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <utility>
#include <vector>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/input_file.hpp"

namespace sonoshape::segmentation {
namespace {

using nlohmann::json;

constexpr const char* kFormat = "sonoshape-segmentation";
constexpr int kVersion = 1;

// Problems are thrown as InputError (element: the key path) inside the parser only;
// parse_segmentation_config turns them into a Status.

double number_at(const json& j, const std::string& where) {
  if (!j.is_number()) throw InputError(where, "expected a number, got " + j.dump());
  const double value = j.get<double>();
  if (!std::isfinite(value)) throw InputError(where, "not a finite number");
  return value;
}

// Sets the number field called `name` among `fields` from `value`; any other name is an error at
// `where`.
void set_number_field(std::initializer_list<std::pair<std::string_view, double*>> fields,
                      const std::string& name, const json& value, const std::string& where) {
  for (const auto& [field, target] : fields)
    if (field == name) {
      *target = number_at(value, where);
      return;
    }
  throw InputError(where, "unknown key; see docs/segmentation.md for the fields");
}

// An integer field as int: a value beyond int's range would otherwise wrap into a valid one.
int integer_at(const json& j, const std::string& where) {
  if (!j.is_number_integer()) throw InputError(where, "expected an integer");
  const bool in_range = j.is_number_unsigned()
                            ? j.get<std::uint64_t>() <= std::uint64_t{INT_MAX}
                            : j.get<std::int64_t>() >= INT_MIN && j.get<std::int64_t>() <= INT_MAX;
  if (!in_range) throw InputError(where, "integer " + j.dump() + " is out of range");
  return j.get<int>();
}

LabelModel read_model(const json& j, const std::string& where, bool is_background) {
  if (!j.is_object()) throw InputError(where, "expected an object");
  LabelModel model;
  model.label = 0;
  for (const auto& [key, value] : j.items()) {
    if (key == "id" && !is_background) {
      model.label = integer_at(value, where + ".id");
    } else if (key == "name") {
      if (!value.is_string()) throw InputError(where + ".name", "expected a string");
      model.name = value.get<std::string>();
    } else if (key == "grey_mean") {
      model.grey_mean = number_at(value, where + ".grey_mean");
    } else if (key == "grey_std") {
      model.grey_std = number_at(value, where + ".grey_std");
    } else if (key == "thickness_mm" && !is_background) {
      model.thickness_mm = number_at(value, where + ".thickness_mm");
    } else if (key == "seed_mm" && !is_background) {
      if (!value.is_array() || value.size() != 3)
        throw InputError(where + ".seed_mm", "expected [x, y, z] in mm, got " + value.dump());
      model.seed_mm = Vec3(number_at(value[0], where + ".seed_mm[0]"),
                           number_at(value[1], where + ".seed_mm[1]"),
                           number_at(value[2], where + ".seed_mm[2]"));
    } else {
      throw InputError(where, "unknown key '" + key + "' (known: " + (is_background ? "" : "id, ") +
                                  "name, grey_mean, grey_std" +
                                  (is_background ? "" : ", thickness_mm, seed_mm") + ")");
    }
  }
  if (!is_background && !j.contains("id")) throw InputError(where, "missing 'id'");
  if (!j.contains("grey_mean")) throw InputError(where, "missing 'grey_mean'");
  if (is_background && model.name.empty()) model.name = "background";
  return model;
}

json model_json(const LabelModel& m, bool with_id) {
  json j;
  if (with_id) j["id"] = m.label;
  j["name"] = m.name;
  j["grey_mean"] = m.grey_mean;
  j["grey_std"] = m.grey_std;
  if (with_id && m.thickness_mm > 0.0) j["thickness_mm"] = m.thickness_mm;
  if (with_id && m.seed_mm) j["seed_mm"] = {m.seed_mm->x(), m.seed_mm->y(), m.seed_mm->z()};
  return j;
}

}  // namespace

double SegmentationConfig::effective_shadow_grey() const {
  if (shadow_grey >= 0.0) return shadow_grey;
  double darkest = background.grey_mean;
  for (const LabelModel& m : materials) darkest = std::min(darkest, m.grey_mean);
  return std::clamp(0.4 * darkest, 6.0, 50.0);
}

Status GraphCutOptions::validate() const {
  if (!(cell_mm > 0.0) || !std::isfinite(cell_mm))
    return Status::error("graph_cut.cell_mm must be a length in mm > 0");
  for (const auto& [name, value] :
       std::array<std::pair<const char*, double>, 3>{{{"smoothness", smoothness},
                                                      {"prior_weight", prior_weight},
                                                      {"prior_margin_mm", prior_margin_mm}}})
    if (!(value >= 0.0) || !std::isfinite(value))
      return Status::error(std::string("graph_cut.") + name + " must be a finite number >= 0");
  if (!(model_update >= 0.0 && model_update <= 1.0))
    return Status::error("graph_cut.model_update must be in 0..1");
  if (cycles < 1) return Status::error("graph_cut.cycles must be >= 1");
  return Status::ok();
}

Status SegmentationConfig::validate() const {
  std::set<int> ids;
  for (const LabelModel& m : materials) {
    if (m.label < 1 || m.label > kMaxPixelLabel)
      return Status::error("segmentation config: material id " + std::to_string(m.label) +
                           " is outside 1.." + std::to_string(kMaxPixelLabel) +
                           " (0 is the background, give it as \"background\")");
    if (!ids.insert(m.label).second)
      return Status::error("segmentation config: material id " + std::to_string(m.label) +
                           " is given twice; give each label one model");
  }
  for (const LabelModel* m : [&] {
         std::vector<const LabelModel*> all{&background};
         for (const LabelModel& x : materials) all.push_back(&x);
         return all;
       }())
    if (!(m->grey_std > 0.0) || m->grey_mean < 0.0 || m->grey_mean > 255.0)
      return Status::error("segmentation config: label " + std::to_string(m->label) +
                           " needs grey_mean in 0..255 and grey_std > 0");
  for (const LabelModel& m : materials)
    if (!(m.thickness_mm >= 0.0) || !std::isfinite(m.thickness_mm))
      return Status::error("segmentation config: label " + std::to_string(m.label) +
                           " has thickness_mm " + std::to_string(m.thickness_mm) +
                           "; give a length in mm >= 0 (0: unknown)");
  if (Status valid = graph_cut.validate(); !valid)
    return Status::error("segmentation config: " + valid.message());
  if (median_px < 1 || median_px % 2 == 0 || median_px > 31)
    return Status::error("segmentation config: median_px must be odd, 1..31 (got " +
                         std::to_string(median_px) + ")");
  for (const auto& [name, value] : std::array<std::pair<const char*, double>, 11>{
           {{"smoothing_mm", smoothing_mm},
            {"boundary_echo_contrast", boundary_echo_contrast},
            {"dynamic_range_db", dynamic_range_db},
            {"confidence_window_mm", confidence_window_mm},
            {"shadow_fraction", shadow_fraction},
            {"shadow_margin_mm", shadow_margin_mm},
            {"max_depth_mm", max_depth_mm},
            {"opening_mm", opening_mm},
            {"min_region_mm2", min_region_mm2},
            {"simplify_mm", simplify_mm},
            {"outline_sd_mm", outline_sd_mm}}})
    if (!(value >= 0.0) || !std::isfinite(value))
      return Status::error(std::string("segmentation config: ") + name +
                           " must be a finite number >= 0");
  if (!std::isfinite(psf_sigma_mm))
    return Status::error(
        "segmentation config: psf_sigma_mm must be a finite number (mm; "
        "negative: from the sweep's header; 0: no blooming correction)");
  if (shadow_fraction > 1.0)
    return Status::error("segmentation config: shadow_fraction must be in 0..1");
  if (!(confidence_window_mm > 0.0))
    return Status::error("segmentation config: confidence_window_mm must be > 0");
  if (sector == SectorSource::kPolygon && sector_polygon_px.size() < 3)
    return Status::error("segmentation config: a sector polygon needs at least 3 points");
  return Status::ok();
}

namespace {

// "sector": "default", "auto", "full" or a polygon [[column, row], ...].
void read_sector(const json& value, SegmentationConfig& config) {
  if (value.is_string()) {
    const std::string s = value.get<std::string>();
    if (s == "auto")
      config.sector = SectorSource::kAuto;
    else if (s == "full")
      config.sector = SectorSource::kFull;
    else if (s == "default")
      config.sector = SectorSource::kDefault;
    else
      throw InputError("sector", "expected \"default\", \"auto\", \"full\" or a polygon");
  } else if (value.is_array()) {
    config.sector = SectorSource::kPolygon;
    for (std::size_t k = 0; k < value.size(); ++k) {
      const std::string where = "sector[" + std::to_string(k) + "]";
      if (!value[k].is_array() || value[k].size() != 2)
        throw InputError(where, "expected [column, row]");
      config.sector_polygon_px.emplace_back(number_at(value[k][0], where),
                                            number_at(value[k][1], where));
    }
  } else {
    throw InputError("sector", "expected a string or a polygon [[column, row], ...]");
  }
}

// One top-level key of the config (any but format and version).
void read_config_key(const std::string& key, const json& value, SegmentationConfig& config) {
  if (key == "background") {
    config.background = read_model(value, key, true);
  } else if (key == "labels") {
    if (!value.is_array()) throw InputError(key, "expected an array of label models");
    for (std::size_t k = 0; k < value.size(); ++k)
      config.materials.push_back(read_model(value[k], "labels[" + std::to_string(k) + "]", false));
  } else if (key == "median_px") {
    config.median_px = integer_at(value, key);
  } else if (key == "depth_compensation" || key == "learn_models") {
    if (!value.is_boolean()) throw InputError(key, "expected true or false");
    (key == "learn_models" ? config.learn_models : config.depth_compensation) = value.get<bool>();
  } else if (key == "sector") {
    read_sector(value, config);
  } else if (key == "graph_cut") {
    if (!value.is_object()) throw InputError(key, "expected an object of graph-cut weights");
    GraphCutOptions& g = config.graph_cut;
    for (const auto& [name, weight] : value.items()) {
      set_number_field({{"cell_mm", &g.cell_mm},
                        {"smoothness", &g.smoothness},
                        {"prior_weight", &g.prior_weight},
                        {"prior_margin_mm", &g.prior_margin_mm},
                        {"model_update", &g.model_update}},
                       name, weight, key + "." + name);
    }
  } else if (key == "method") {
    const std::string name = value.is_string() ? value.get<std::string>() : "";
    if (name == "threshold")
      config.method = LabellingMethod::kThreshold;
    else if (name == "graph_cut")
      config.method = LabellingMethod::kGraphCut;
    else
      throw InputError(key, "expected \"threshold\" or \"graph_cut\"");
  } else {
    set_number_field({{"smoothing_mm", &config.smoothing_mm},
                      {"boundary_echo_contrast", &config.boundary_echo_contrast},
                      {"confidence_window_mm", &config.confidence_window_mm},
                      {"shadow_grey", &config.shadow_grey},
                      {"shadow_fraction", &config.shadow_fraction},
                      {"shadow_margin_mm", &config.shadow_margin_mm},
                      {"max_depth_mm", &config.max_depth_mm},
                      {"opening_mm", &config.opening_mm},
                      {"min_region_mm2", &config.min_region_mm2},
                      {"simplify_mm", &config.simplify_mm},
                      {"outline_sd_mm", &config.outline_sd_mm},
                      {"sector_signal_grey", &config.sector_signal_grey},
                      {"psf_sigma_mm", &config.psf_sigma_mm},
                      {"dynamic_range_db", &config.dynamic_range_db}},
                     key, value, key);
  }
}

}  // namespace

Result<SegmentationConfig> parse_segmentation_config(const std::string& json_text,
                                                     const std::string& source_name) {
  json doc;
  try {
    doc = json::parse(json_text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for a number overflow
    return Status::error(source_name + ": not valid JSON (" + e.what() + ")");
  }
  SegmentationConfig config;
  try {
    if (!doc.is_object()) throw InputError("top level", "expected an object");
    // find, not value(): value() throws when the key holds another type.
    const auto format = doc.find("format");
    if (format == doc.end() || !format->is_string() || *format != kFormat)
      throw InputError("format", std::string("must be \"") + kFormat + "\"");
    const auto version = doc.find("version");
    if (version == doc.end() || !version->is_number_integer() || *version != kVersion)
      throw InputError("version", "must be " + std::to_string(kVersion));
    for (const auto& [key, value] : doc.items())
      if (key != "format" && key != "version") read_config_key(key, value, config);
  } catch (const InputError& p) {
    return Status::error(p.message_in(source_name));
  }
  if (Status valid = config.validate(); !valid)
    return Status::error(source_name + ": " + valid.message());
  return config;
}

namespace {

// The presets' settings. Water (and gel) gives no echo: the water presets call it background
// (outside every organ) and turn the no-signal rule off (shadow_fraction 1), which would
// otherwise swallow echoes of a millimetre in the margin of the water around them. Wires and a
// tank's floor are specular reflectors: their echo varies several-fold with the angle of
// incidence (16..200 grey within one recording), so the boundary between water and echo stays
// low, well above the water's noise, instead of midway to a mean learnt from the recording
// (which lost the weaker echoes: 6-8 of the 9 wires of fCal's validation frames 76-92). A wire is
// far brighter than the water (more than detail::kReflectorGapGrey), so the median decides for
// it: a Gaussian of smoothing_mm would spread a wire of a millimetre below the boundary. What
// these presets look for (a wire, a floor, a bone's surface) is itself a thin line brighter than
// both its sides, no boundary echo to fill (boundary_echo_contrast 0), and a section too thin for
// the thin-plate field's smoothing fit, which would thin it away between sparse keyframes: their
// outlines are interpolated (outline_sd_mm 0; fCal's calibration recording with --every 4, 202
// parts of wire with 0.6 against 61). A wire struck at a steep
// angle echoes in a spot of 0.3-0.5 mm^2, which water's noise never makes: a smallest region of
// 0.5 mm^2 lost one wire in 25 of the 188 frames of fCal's calibration recording, 0.3 in 4.
const char* const kWiresJson = R"({
  "background": {"name": "water", "grey_mean": 2, "grey_std": 3},
  "labels": [{"id": 1, "name": "wire", "grey_mean": 90, "grey_std": 40}],
  "shadow_fraction": 1.0, "min_region_mm2": 0.3, "opening_mm": 0.2,
  "boundary_echo_contrast": 0, "outline_sd_mm": 0})";
// The floor is a band of a few pixels: the default opening and smoothing would wipe it out, and
// the closer classes classify the smoothed grey (30 - 2 is no reflector gap).
const char* const kWaterTankJson = R"({
  "background": {"name": "water", "grey_mean": 2, "grey_std": 3},
  "labels": [{"id": 1, "name": "floor", "grey_mean": 30, "grey_std": 20}],
  "shadow_fraction": 1.0, "min_region_mm2": 4, "opening_mm": 0.1, "smoothing_mm": 0.3,
  "boundary_echo_contrast": 0, "outline_sd_mm": 0})";
const char* const kBoneJson = R"({
  "background": {"name": "soft tissue", "grey_mean": 40, "grey_std": 25},
  "labels": [{"id": 1, "name": "bone", "grey_mean": 200, "grey_std": 40}],
  "learn_models": true, "min_region_mm2": 3, "opening_mm": 0.3, "boundary_echo_contrast": 0,
  "outline_sd_mm": 0})";

}  // namespace

Result<SegmentationConfig> read_segmentation_config(const std::filesystem::path& path) {
  Result<std::string> text = read_input_file(path, "the segmentation config");
  if (!text) return text.status();
  return parse_segmentation_config(*text, path.string());
}

const std::vector<SegmentationPreset>& segmentation_presets() {
  static const std::vector<SegmentationPreset> presets{
      {"soft-tissue",
       "the defaults: two classes (background, echogenic) found in the recording; anechoic "
       "areas (water, gel, shadows) unknown",
       "{}"},
      {"wires", "wire phantoms in water (N-wire, fCal): water background, wires of ~1 mm^2",
       kWiresJson},
      {"water-tank", "a water tank's floor or another large flat reflector in water",
       kWaterTankJson},
      {"bone", "bone surfaces (or a bone enhancer's output) in soft tissue: bright bands",
       kBoneJson},
  };
  return presets;
}

Result<SegmentationConfig> load_segmentation_config(
    const std::optional<std::filesystem::path>& path, std::string_view preset) {
  json doc = json::object();
  std::string source;
  if (!preset.empty()) {
    const auto& presets = segmentation_presets();
    const auto it = std::find_if(presets.begin(), presets.end(),
                                 [&](const SegmentationPreset& p) { return p.name == preset; });
    if (it == presets.end()) {
      std::string known;
      for (const SegmentationPreset& p : presets) known += (known.empty() ? "" : ", ") + p.name;
      return Status::error("unknown segmentation preset '" + std::string(preset) +
                           "'; the presets are " + known + " (docs/segmentation.md)");
    }
    doc = json::parse(it->json);
    source = "preset " + it->name;
  }
  if (path) {
    Result<std::string> text = read_input_file(*path, "the segmentation config");
    if (!text) return text.status();
    json file;
    try {
      file = json::parse(*text);
    } catch (const json::exception& e) {
      return Status::error(path->string() + ": not valid JSON (" + e.what() + ")");
    }
    if (!file.is_object()) return Status::error(path->string() + ": top level: expected an object");
    for (const auto& [key, value] : file.items())
      if (key == "graph_cut" && value.is_object() && doc.contains(key))
        doc[key].update(value);
      else
        doc[key] = value;
    source = source.empty() ? path->string() : path->string() + " over " + source;
  } else {
    doc["format"] = kFormat;
    doc["version"] = kVersion;
  }
  return parse_segmentation_config(doc.dump(), source.empty() ? "the defaults" : source);
}

std::string to_json(const SegmentationConfig& c) {
  json doc;
  doc["format"] = kFormat;
  doc["version"] = kVersion;
  doc["background"] = model_json(c.background, false);
  doc["labels"] = json::array();
  for (const LabelModel& m : c.materials) doc["labels"].push_back(model_json(m, true));
  doc["median_px"] = c.median_px;
  doc["smoothing_mm"] = c.smoothing_mm;
  doc["boundary_echo_contrast"] = c.boundary_echo_contrast;
  doc["confidence_window_mm"] = c.confidence_window_mm;
  doc["shadow_grey"] = c.shadow_grey;
  doc["shadow_fraction"] = c.shadow_fraction;
  doc["shadow_margin_mm"] = c.shadow_margin_mm;
  doc["max_depth_mm"] = c.max_depth_mm;
  doc["depth_compensation"] = c.depth_compensation;
  doc["learn_models"] = c.learn_models;
  doc["psf_sigma_mm"] = c.psf_sigma_mm;
  doc["dynamic_range_db"] = c.dynamic_range_db;
  doc["method"] = c.method == LabellingMethod::kGraphCut ? "graph_cut" : "threshold";
  doc["graph_cut"] = {{"cell_mm", c.graph_cut.cell_mm},
                      {"smoothness", c.graph_cut.smoothness},
                      {"prior_weight", c.graph_cut.prior_weight},
                      {"prior_margin_mm", c.graph_cut.prior_margin_mm},
                      {"model_update", c.graph_cut.model_update}};
  doc["opening_mm"] = c.opening_mm;
  doc["min_region_mm2"] = c.min_region_mm2;
  doc["simplify_mm"] = c.simplify_mm;
  doc["outline_sd_mm"] = c.outline_sd_mm;
  doc["sector_signal_grey"] = c.sector_signal_grey;
  switch (c.sector) {
    case SectorSource::kDefault:
      doc["sector"] = "default";
      break;
    case SectorSource::kAuto:
      doc["sector"] = "auto";
      break;
    case SectorSource::kFull:
      doc["sector"] = "full";
      break;
    case SectorSource::kPolygon: {
      json ring = json::array();
      for (const Vec2& p : c.sector_polygon_px) ring.push_back({p.x(), p.y()});
      doc["sector"] = ring;
      break;
    }
  }
  return doc.dump(2);
}

namespace {

// For each pixel, whether every pixel within `radius_px` (a disk) holds its label (outside the
// image counts as another label); all pixels when the radius is under half a pixel.
std::vector<std::uint8_t> interior_pixels(const LabelImage& labels, double radius_px) {
  std::vector<std::uint8_t> interior(labels.pixels.size(), 1);
  const int r = static_cast<int>(std::lround(radius_px));
  if (r < 1) return interior;
  const cv::Mat map(labels.height, labels.width, CV_8U,
                    const_cast<std::uint8_t*>(labels.pixels.data()));
  const cv::Mat disk = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1));
  cv::Mat lowest, highest;
  cv::erode(map, lowest, disk, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::dilate(map, highest, disk, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(255));
  const cv::Mat same = (lowest == highest);
  for (int j = 0; j < labels.height; ++j)
    std::copy(same.ptr<std::uint8_t>(j), same.ptr<std::uint8_t>(j) + labels.width,
              interior.begin() + static_cast<std::ptrdiff_t>(j) * labels.width);
  return interior;
}

}  // namespace

SegmentationConfig learn_label_models(const GreyImage& image, const LabelImage& labels,
                                      const SegmentationConfig& base, double interior_px) {
  if (image.width != labels.width || image.height != labels.height ||
      image.pixels.size() != labels.pixels.size())
    throw std::invalid_argument("learn_label_models: image and label map differ in size");
  const std::vector<std::uint8_t> interior = interior_pixels(labels, interior_px);
  std::array<double, 256> sum{}, sum_sq{}, count{}, all{};
  for (std::size_t p = 0; p < image.pixels.size(); ++p)
    all[labels.pixels[p]] += interior[p] ? 1.0 : 0.0;
  for (std::size_t p = 0; p < image.pixels.size(); ++p) {
    const std::uint8_t l = labels.pixels[p];
    // A label with no interior pixel (a sliver) is learnt from all of its pixels.
    if (l == kLabelPixelUnknown || (all[l] > 0.0 && !interior[p])) continue;
    const double g = image.pixels[p];
    sum[l] += g;
    sum_sq[l] += g * g;
    count[l] += 1.0;
  }
  SegmentationConfig config = base;
  config.materials.clear();
  for (int l = 0; l <= kMaxPixelLabel; ++l) {
    const auto k = static_cast<std::size_t>(l);
    if (count[k] == 0.0) continue;
    LabelModel m;
    m.label = l;
    m.grey_mean = sum[k] / count[k];
    m.grey_std =
        std::max(1.0, std::sqrt(std::max(0.0, sum_sq[k] / count[k] - m.grey_mean * m.grey_mean)));
    if (l == 0) {
      m.name = "background";
      config.background = m;
    } else {
      // Keep names the base configuration gives.
      m.name = "label_" + std::to_string(l);
      for (const LabelModel& b : base.materials)
        if (b.label == l && !b.name.empty()) m.name = b.name;
      config.materials.push_back(m);
    }
  }
  return config;
}

SegmentationConfig learn_models_from_samples(const std::vector<std::uint8_t>& samples,
                                             const SegmentationConfig& base) {
  std::vector<LabelModel*> models{nullptr};
  SegmentationConfig config = base;
  models.front() = &config.background;
  for (LabelModel& m : config.materials) models.push_back(&m);
  std::array<double, 256> histogram{};
  for (const std::uint8_t g : samples) histogram[g] += 1.0;
  // Lloyd's k-means in one dimension, over the histogram (cv::kmeans moves a class that loses
  // every sample to a random one: the roles given must stay).
  std::vector<double> means;
  for (const LabelModel* m : models) means.push_back(m->grey_mean);
  std::vector<double> sum(means.size()), sum_sq(means.size()), count(means.size());
  for (int iteration = 0; iteration < 100; ++iteration) {
    std::fill(sum.begin(), sum.end(), 0.0);
    std::fill(sum_sq.begin(), sum_sq.end(), 0.0);
    std::fill(count.begin(), count.end(), 0.0);
    for (int g = 0; g < 256; ++g) {
      std::size_t best = 0;
      for (std::size_t k = 1; k < means.size(); ++k)
        if (std::abs(g - means[k]) < std::abs(g - means[best])) best = k;
      sum[best] += histogram[static_cast<std::size_t>(g)] * g;
      sum_sq[best] += histogram[static_cast<std::size_t>(g)] * g * g;
      count[best] += histogram[static_cast<std::size_t>(g)];
    }
    bool moved = false;
    for (std::size_t k = 0; k < means.size(); ++k) {
      if (count[k] == 0.0) continue;
      moved |= std::abs(sum[k] / count[k] - means[k]) > 1e-9;
      means[k] = sum[k] / count[k];
    }
    if (!moved) break;
  }
  for (std::size_t k = 0; k < models.size(); ++k) {
    if (count[k] == 0.0) continue;
    models[k]->grey_mean = means[k];
    models[k]->grey_std =
        std::max(1.0, std::sqrt(std::max(0.0, sum_sq[k] / count[k] - means[k] * means[k])));
  }
  return config;
}

SegmentationConfig auto_two_class(const std::vector<std::uint8_t>& samples,
                                  const SegmentationConfig& base) {
  SegmentationConfig config = base;
  config.materials.clear();
  if (samples.size() < 2) {
    config.materials.push_back({1, "echogenic", 200.0, 25.0});
    return config;
  }
  cv::Mat data(static_cast<int>(samples.size()), 1, CV_32F);
  for (std::size_t k = 0; k < samples.size(); ++k) data.at<float>(static_cast<int>(k)) = samples[k];
  cv::Mat assignment, centres;
  cv::setRNGSeed(1);  // k-means++ seeding: deterministic runs
  cv::kmeans(data, 2, assignment,
             cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 0.1), 3,
             cv::KMEANS_PP_CENTERS, centres);
  std::array<double, 2> sum{}, sum_sq{}, count{};
  for (int k = 0; k < data.rows; ++k) {
    const auto c = static_cast<std::size_t>(assignment.at<int>(k));
    const double g = data.at<float>(k);
    sum[c] += g;
    sum_sq[c] += g * g;
    count[c] += 1.0;
  }
  std::array<LabelModel, 2> models;
  for (std::size_t c = 0; c < 2; ++c) {
    const double n = std::max(count[c], 1.0);
    models[c].grey_mean = sum[c] / n;
    models[c].grey_std = std::max(
        1.0, std::sqrt(std::max(0.0, sum_sq[c] / n - models[c].grey_mean * models[c].grey_mean)));
  }
  if (models[0].grey_mean > models[1].grey_mean) std::swap(models[0], models[1]);
  config.background = {0, "background", models[0].grey_mean, models[0].grey_std};
  config.materials.push_back({1, "echogenic", models[1].grey_mean, models[1].grey_std});
  return config;
}

LabelInfo slice_label(const LabelModel& model) {
  return {model.label, model.name, model.thickness_mm > 0.0};
}

}  // namespace sonoshape::segmentation
