#include "sonoshape/scan/stages.hpp"

#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

#include "sonoshape/core/log.hpp"
#include "sonoshape/scan/label_prior.hpp"
#include "sonoshape/segmentation/contours.hpp"

namespace sonoshape::scan {

namespace {
// Frames segmented before the scan judges whether one label fills most sectors.
constexpr std::size_t kShareCheckFrames = 10;
}  // namespace

SegmenterStage::SegmenterStage(ScanSetup setup)
    : setup_(std::move(setup)), shares_(setup_.geometry.sector) {
  setup_.geometry.check();
  if (const Status valid = setup_.segmentation.validate(); !valid)
    throw std::invalid_argument("segmentation configuration: " + valid.message());
  if (setup_.segmentation.method == segmentation::LabellingMethod::kGraphCut)
    labeller_ = std::make_unique<segmentation::GraphCutLabeller>(
        setup_.segmentation, setup_.geometry, setup_.segmentation.graph_cut);
}

SegmenterStage::~SegmenterStage() = default;

void SegmenterStage::on_meshes(const MeshSet& meshes) {
  if (!labeller_) return;
  auto copy = std::make_shared<const MeshSet>(meshes);
  std::lock_guard lock(meshes_mutex_);
  meshes_ = std::move(copy);
}

Result<LabeledSlice> SegmenterStage::segment(const TrackedFrame& frame) {
  const segmentation::ImageGeometry& g = setup_.geometry;
  const GreyImage& image = frame.frame.image;
  if (image.width != g.width_px || image.height != g.height_px)
    return Status::error("frame " + std::to_string(frame.frame.index) + " is " +
                         std::to_string(image.width) + "x" + std::to_string(image.height) +
                         " but the setup expects " + std::to_string(g.width_px) + "x" +
                         std::to_string(g.height_px) + " (wrong probe preset?)");
  const Eigen::Matrix4d T_reference_probe = frame.T_reference_probe.matrix();
  const segmentation::ImagePlane plane = segmentation::image_plane(
      T_reference_probe * setup_.T_probe_image, T_reference_probe.block<3, 1>(0, 3));
  segmentation::Segmentation segmentation;
  if (labeller_) {
    std::shared_ptr<const MeshSet> meshes;
    {
      std::lock_guard lock(meshes_mutex_);
      meshes = meshes_;
    }
    std::optional<LabelImage> prior;
    if (meshes && !meshes->meshes.empty()) prior = predict_label_map(*meshes, plane, g);
    segmentation = labeller_->segment(image, prior ? &*prior : nullptr, &plane);
  } else {
    segmentation = segmentation::segment_frame(image, g, setup_.segmentation);
  }
  if (truth_of_frame_)
    if (const auto truth = truth_of_frame_(frame.frame.index)) {
      scores_.add(segmentation::compare_labels(*truth, segmentation.labels, g.sector));
      ++scored_frames_;
    }
  shares_.add(segmentation.labels);
  if (!shares_warned_ && shares_.frames() >= kShareCheckFrames)
    if (const auto warning = shares_.warning(label_names())) {
      log_warning("scan: " + *warning);
      shares_warned_ = true;
    }
  repairs_.clear();
  auto slice = segmentation::make_slice(segmentation.labels, g.sector, g.sector_px, plane,
                                        setup_.segmentation.simplify_mm, &repairs_);
  if (!slice) return slice.status();
  slice->timestamp_s = frame.frame.timestamp_s;
  slice->outline_sd_mm = setup_.segmentation.outline_sd_mm;
  return slice;
}

void SegmenterStage::score_against(
    std::function<std::optional<LabelImage>(std::int64_t)> truth_of_frame) {
  truth_of_frame_ = std::move(truth_of_frame);
}

std::optional<segmentation::LabelComparison> SegmenterStage::scores() const {
  if (scored_frames_ == 0) return std::nullopt;
  return scores_;
}

std::map<int, std::string> SegmenterStage::label_names() const {
  std::map<int, std::string> names;
  for (const segmentation::LabelModel& m : setup_.segmentation.materials) names[m.label] = m.name;
  return names;
}

std::vector<Repair> SegmenterStage::take_repairs() { return std::exchange(repairs_, {}); }

}  // namespace sonoshape::scan
