#include "sonoshape/scan/label_maps.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "sonoshape/acquisition/frame_source.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/segmentation/contours.hpp"
#ifdef SONOSHAPE_WITH_OPENIGTLINK
#include "sonoshape/acquisition/igtl_frame_source.hpp"
#endif

namespace sonoshape::scan {
namespace {

std::string seconds(double s) {
  std::ostringstream out;
  out.precision(15);
  out << s;
  return out.str();
}

class SequenceLabelFeed final : public LabelMapFeed {
 public:
  SequenceLabelFeed(std::shared_ptr<const acquisition::SequenceFile> maps, std::string description)
      : maps_(std::move(maps)), description_(std::move(description)) {}
  Result<LabelImage> label_map(const Frame& frame) override {
    if (frame.index < 0 || static_cast<std::size_t>(frame.index) >= maps_->frame_count())
      return Status::error("frame " + std::to_string(frame.index) + " has no label map (" +
                           std::to_string(maps_->frame_count()) + " label maps)");
    return maps_->image(static_cast<std::size_t>(frame.index));
  }
  std::string describe() const override { return description_; }

 private:
  std::shared_ptr<const acquisition::SequenceFile> maps_;
  std::string description_;
};

}  // namespace

std::unique_ptr<LabelMapFeed> sequence_label_feed(
    std::shared_ptr<const acquisition::SequenceFile> maps, std::string description) {
  return std::make_unique<SequenceLabelFeed>(std::move(maps), std::move(description));
}

LabelMapMatcher::LabelMapMatcher(double tolerance_s, std::size_t capacity)
    : tolerance_s_(tolerance_s), capacity_(std::max<std::size_t>(capacity, 1)) {}

void LabelMapMatcher::offer(double timestamp_s, LabelImage labels) {
  held_[timestamp_s] = std::move(labels);
  while (held_.size() > capacity_) held_.erase(held_.begin());
}

std::optional<LabelImage> LabelMapMatcher::take(double timestamp_s) {
  // Older label maps belong to frames already segmented or skipped as keyframes.
  held_.erase(held_.begin(), held_.lower_bound(timestamp_s - tolerance_s_));
  const auto it = held_.begin();
  if (it == held_.end() || it->first > timestamp_s + tolerance_s_) return std::nullopt;
  LabelImage labels = std::move(it->second);
  held_.erase(it);
  return labels;
}

bool LabelMapMatcher::passed(double timestamp_s) const {
  return !held_.empty() && held_.rbegin()->first > timestamp_s + tolerance_s_;
}

std::optional<double> LabelMapMatcher::nearest(double timestamp_s) const {
  std::optional<double> best;
  for (const auto& entry : held_)
    if (!best || std::abs(entry.first - timestamp_s) < std::abs(*best - timestamp_s))
      best = entry.first;
  return best;
}

StreamLabelFeed::StreamLabelFeed(std::unique_ptr<acquisition::FrameSource> source, std::string name,
                                 int unknown_value, double wait_s)
    : source_(std::move(source)),
      name_(std::move(name)),
      unknown_value_(unknown_value),
      wait_s_(wait_s) {}

StreamLabelFeed::~StreamLabelFeed() {
  if (source_) source_->stop();
}

Status StreamLabelFeed::start() {
  acquisition::SourceOptions options;
  options.buffer_capacity = 64;  // a couple of seconds of label maps between two keyframes
  return source_->start(options);
}

std::string StreamLabelFeed::describe() const {
  return "label maps from " + name_ + ", paired with the frames by timestamp";
}

void StreamLabelFeed::take_available(double timeout_s) {
  auto received = source_->next(timeout_s);
  while (received) {
    matcher_.offer(received->item.timestamp_s, std::move(received->item.image));
    received = source_->next(0.0);
  }
}

Result<LabelImage> StreamLabelFeed::label_map(const Frame& frame) {
  const double deadline_s = acquisition::monotonic_s() + wait_s_;
  take_available(0.0);
  std::optional<LabelImage> labels = matcher_.take(frame.timestamp_s);
  while (!labels && !matcher_.passed(frame.timestamp_s) && !source_->finished()) {
    const double left_s = deadline_s - acquisition::monotonic_s();
    if (left_s <= 0.0) break;
    take_available(std::min(left_s, 0.05));
    labels = matcher_.take(frame.timestamp_s);
  }
  if (!labels) {
    std::string why = "no label map stamped within 1 ms of frame " + std::to_string(frame.index) +
                      " (" + seconds(frame.timestamp_s) + " s) from " + name_;
    if (const auto near = matcher_.nearest(frame.timestamp_s))
      why += "; the nearest is stamped " + seconds(*near) + " s";
    else if (!source_->condition().empty() || source_->finished())
      why += ": " + (source_->condition().empty() ? source_->message() : source_->condition());
    else
      why += " within " + seconds(wait_s_) + " s";
    return Status::error(why + " (the sender must stamp each label map with its frame's time)");
  }
  const std::string where = name_ + ", label map of frame " + std::to_string(frame.index);
  if (labels->width != frame.image.width || labels->height != frame.image.height)
    return Status::error(
        where + " is " + std::to_string(labels->width) + "x" + std::to_string(labels->height) +
        " pixels but the frame is " + std::to_string(frame.image.width) + "x" +
        std::to_string(frame.image.height) + "; send label maps on the B-mode image's pixel grid");
  if (const Status mapped = acquisition::to_label_pixels(*labels, unknown_value_, where); !mapped)
    return mapped;
  return std::move(*labels);
}

#ifdef SONOSHAPE_WITH_OPENIGTLINK
Result<std::unique_ptr<LabelMapFeed>> igtl_label_feed(const std::string& spec,
                                                      const std::string& frames_endpoint,
                                                      int unknown_value, double wait_s) {
  const std::string prefix = "igtl:";
  const std::string rest = spec.substr(prefix.size());
  const std::size_t at = rest.find('@');
  const std::string device = rest.substr(0, at);
  if (device.empty())
    return Status::error("--labels " + spec +
                         ": no device name; give the IMAGE device of the label maps, e.g. "
                         "--labels igtl:LabelMap (or igtl:LabelMap@HOST:PORT for another server)");
  auto endpoint = acquisition::parse_igtl_endpoint(
      at == std::string::npos ? frames_endpoint : rest.substr(at + 1), "--labels igtl:" + device);
  if (!endpoint) return endpoint.status();
  return Result<std::unique_ptr<LabelMapFeed>>(std::make_unique<StreamLabelFeed>(
      std::make_unique<acquisition::IgtlFrameSource>(*endpoint, device,
                                                     acquisition::IgtlPixels::kLabels),
      "IMAGE '" + device + "' of igtl:" + endpoint->text(), unknown_value, wait_s));
}
#endif

LabelMapStage::LabelMapStage(ScanSetup setup, std::unique_ptr<LabelMapFeed> feed)
    : setup_(std::move(setup)), feed_(std::move(feed)) {
  setup_.geometry.check();
  if (!feed_) throw std::invalid_argument("LabelMapStage: no label-map feed");
}

Result<LabeledSlice> LabelMapStage::segment(const TrackedFrame& frame) {
  repairs_.clear();
  auto labels = feed_->label_map(frame.frame);
  if (!labels) {
    if (!std::exchange(warned_, true))
      log_warning("scan --labels: " + labels.message() +
                  "; frames without a label map give no slice (later ones counted as "
                  "'segmentation failed')");
    return labels.status();
  }
  const segmentation::ImageGeometry& g = setup_.geometry;
  if (labels->width != g.width_px || labels->height != g.height_px)
    return Status::error("the label map of frame " + std::to_string(frame.frame.index) + " is " +
                         std::to_string(labels->width) + "x" + std::to_string(labels->height) +
                         " but the frames are " + std::to_string(g.width_px) + "x" +
                         std::to_string(g.height_px));
  const Eigen::Matrix4d T_reference_probe = frame.T_reference_probe.matrix();
  const segmentation::ImagePlane plane = segmentation::image_plane(
      T_reference_probe * setup_.T_probe_image, T_reference_probe.block<3, 1>(0, 3));
  // The site's label maps are taken as drawn: their pixels' outlines, exact (no outline_sd_mm).
  auto slice = segmentation::make_slice(*labels, g.sector, g.sector_px, plane,
                                        setup_.segmentation.simplify_mm, &repairs_,
                                        segmentation::OutlineForm::kPixelEdges);
  if (!slice) return slice.status();
  slice->timestamp_s = frame.frame.timestamp_s;
  return slice;
}

std::vector<Repair> LabelMapStage::take_repairs() { return std::exchange(repairs_, {}); }

std::vector<LabelInfo> declared_labels(const std::map<int, std::string>& names,
                                       const std::vector<LabelInfo>& fallback) {
  if (names.empty()) return fallback;
  std::vector<LabelInfo> labels;
  for (const auto& [value, name] : names) labels.push_back({value, name});
  return labels;
}

}  // namespace sonoshape::scan
