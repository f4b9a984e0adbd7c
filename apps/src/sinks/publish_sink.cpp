#include "sonoshape/apps/publish_sink.hpp"

#include <chrono>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "sonoshape/publish/publisher.hpp"
#include "status_report.hpp"

namespace sonoshape::apps {

struct PublishSink::Impl {
  publish::MeshPublisher publisher;
  FramePreviewOptions previews;
  std::optional<std::chrono::steady_clock::time_point> last_preview;
  publish::StatusReport last_report;  // repeated, finished, as the scan's last message
};

namespace {

// The frame as a preview of at most `max_side_px` a side, on the plane its pixels lie in:
// `T_reference_image` maps pixel centres (column, row, 0) to mm, so the picture's corner is
// pixel (-0.5, -0.5).
Result<publish::FrameImage> frame_preview(const TrackedFrame& tracked,
                                          const Eigen::Matrix4d& T_reference_image,
                                          int max_side_px) {
  const GreyImage& image = tracked.frame.image;
  const Vec3 column = T_reference_image.block<3, 1>(0, 0);
  const Vec3 row = T_reference_image.block<3, 1>(0, 1);
  const double spacing_u = column.norm();
  const double spacing_v = row.norm();
  if (!(spacing_u > 0.0) || !(spacing_v > 0.0) || !std::isfinite(spacing_u) ||
      !std::isfinite(spacing_v) || !T_reference_image.allFinite())
    return Status::error("frame " + std::to_string(tracked.frame.index) +
                         ": its image-to-reference transform has no usable pixel spacing");
  publish::FrameImage out;
  out.index = tracked.frame.index;
  out.timestamp_s = tracked.frame.timestamp_s;
  out.plane.u = column / spacing_u;
  // A calibration is rigid up to spacing; take v orthogonal to u all the same (a preview).
  out.plane.v = (row - out.plane.u * out.plane.u.dot(row)).normalized();
  out.plane.origin_mm = (T_reference_image * Eigen::Vector4d(-0.5, -0.5, 0.0, 1.0)).head<3>();
  out.size_mm = Vec2(image.width * spacing_u, image.height * spacing_v);

  const double scale =
      std::min(1.0, static_cast<double>(max_side_px) / std::max(image.width, image.height));
  const int width = std::max(1, static_cast<int>(std::lround(image.width * scale)));
  const int height = std::max(1, static_cast<int>(std::lround(image.height * scale)));
  const cv::Mat source(image.height, image.width, CV_8UC1,
                       const_cast<std::uint8_t*>(image.pixels.data()));
  out.image = GreyImage(width, height);
  cv::Mat target(height, width, CV_8UC1, out.image.pixels.data());
  // Area averaging: a downsampled B-mode picture without aliasing speckle into stripes.
  cv::resize(source, target, target.size(), 0.0, 0.0, cv::INTER_AREA);
  return out;
}

}  // namespace

publish::StatusReport report_of(const scan::ScanStatus& status) {
  publish::StatusReport report;
  report.frames_received = status.counters.frames_received;
  report.frames_dropped = status.counters.dropped.total();
  report.slices = status.counters.slices;
  report.arrangement_ms = 1e3 * status.last_update.arrangement_s;
  // The face images (and the completion of unknown regions) are part of the field's cost.
  report.field_ms = 1e3 * (status.last_update.face_images_s + status.last_update.field_s);
  report.smoothing_ms = 1e3 * status.last_update.smoothing_s;
  report.mesh_ms = 1e3 * status.last_update.mesh_s;
  report.total_ms = 1e3 * status.last_update.total_s;
  if (status.counters.updates > 0) {
    report.update_ms = status.counters.last_update_ms;
    report.latency_ms = 1e3 * status.counters.last_latency_s;
  }
  report.state = status.state;
  report.message = status.message;
  return report;
}

Result<std::shared_ptr<PublishSink>> PublishSink::bind(const std::string& endpoint,
                                                       const std::string& snapshot_endpoint,
                                                       const FramePreviewOptions& previews,
                                                       const StreamAccess& access) {
  if (!(previews.rate_hz >= 0.0) || previews.max_side_px < 1 ||
      previews.max_side_px > publish::kMaxFrameImageSide)
    return Status::error("frame previews: the rate must be >= 0 per second and the side 1 to " +
                         std::to_string(publish::kMaxFrameImageSide) + " px");
  publish::PublisherOptions options;
  options.endpoint = endpoint;
  options.snapshot_endpoint = snapshot_endpoint;
  options.curve_secret_key = access.curve_secret_key;
  options.allow_remote = access.allow_remote;
  Result<publish::MeshPublisher> publisher = publish::MeshPublisher::bind(options);
  if (!publisher) return publisher.status();
  auto impl = std::make_unique<Impl>(Impl{std::move(*publisher), previews, std::nullopt, {}});
  return std::shared_ptr<PublishSink>(new PublishSink(std::move(impl)));
}

PublishSink::PublishSink(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PublishSink::~PublishSink() = default;

Status PublishSink::on_frame(const TrackedFrame& frame, const Eigen::Matrix4d& T_reference_image) {
  const FramePreviewOptions& previews = impl_->previews;
  if (previews.rate_hz <= 0.0 || frame.frame.image.empty()) return Status::ok();
  const auto now = std::chrono::steady_clock::now();
  const std::chrono::duration<double> period(1.0 / previews.rate_hz);
  if (impl_->last_preview && now - *impl_->last_preview < period) return Status::ok();
  impl_->last_preview = now;
  Result<publish::FrameImage> preview =
      frame_preview(frame, T_reference_image, previews.max_side_px);
  if (!preview) return preview.status();
  return impl_->publisher.publish_frame(*preview);
}

Status PublishSink::on_slice(const LabeledSlice& slice, std::size_t index) {
  return impl_->publisher.publish_slice(slice, index);
}

Status PublishSink::on_meshes(const MeshSet& meshes, const scan::MeshUpdateInfo& info) {
  return impl_->publisher.publish_meshes(meshes, info.timestamp_s, info.slices);
}

Status PublishSink::on_status(const scan::ScanStatus& status) {
  impl_->last_report = report_of(status);
  impl_->last_report.frame_rate_hz = impl_->previews.rate_hz;
  return impl_->publisher.publish_status(impl_->last_report);
}

Status PublishSink::on_finish(const MeshSet&, const SliceSet&, const scan::ScanSummary& summary) {
  // The last on_meshes went out before: the scan's last message says it is over, with the final
  // counts, so that a view shows "finished" instead of a lost stream (docs/formats/mesh-stream.md).
  // The snapshot server keeps answering with it until the sink is destroyed.
  publish::StatusReport report = impl_->last_report;
  report.frames_received = summary.counters.frames_received;
  report.frames_dropped = summary.counters.dropped.total();
  report.slices = summary.counters.slices;
  if (report.state == ScanState::kScanning) report.state = ScanState::kIdle;
  if (report.message.empty())
    report.message = "scan finished (" + std::string(to_string(summary.stop_reason)) + ")";
  report.finished = true;
  return impl_->publisher.publish_status(report);
}

std::string PublishSink::endpoint() const { return impl_->publisher.endpoint(); }
std::string PublishSink::snapshot_endpoint() const { return impl_->publisher.snapshot_endpoint(); }
std::string PublishSink::scan_id() const { return impl_->publisher.scan(); }

}  // namespace sonoshape::apps
