#include "sonoshape/scan/publish_sink.hpp"

#include "sonoshape/publish/publisher.hpp"
#include "status_report.hpp"

namespace sonoshape::scan {

struct PublishSink::Impl {
  publish::MeshPublisher publisher;
};

publish::StatusReport report_of(const ScanStatus& status) {
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
  report.state = status.state;
  report.message = status.message;
  return report;
}

Result<std::shared_ptr<PublishSink>> PublishSink::bind(const std::string& endpoint,
                                                       const std::string& snapshot_endpoint) {
  publish::PublisherOptions options;
  options.endpoint = endpoint;
  options.snapshot_endpoint = snapshot_endpoint;
  Result<publish::MeshPublisher> publisher = publish::MeshPublisher::bind(options);
  if (!publisher) return publisher.status();
  auto impl = std::make_unique<Impl>(Impl{std::move(*publisher)});
  return std::shared_ptr<PublishSink>(new PublishSink(std::move(impl)));
}

PublishSink::PublishSink(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PublishSink::~PublishSink() = default;

Status PublishSink::on_slice(const LabeledSlice& slice, std::size_t index) {
  return impl_->publisher.publish_slice(slice, index);
}

Status PublishSink::on_meshes(const MeshSet& meshes, const MeshUpdateInfo& info) {
  return impl_->publisher.publish_meshes(meshes, info.timestamp_s, info.slices);
}

Status PublishSink::on_status(const ScanStatus& status) {
  return impl_->publisher.publish_status(report_of(status));
}

Status PublishSink::on_finish(const MeshSet&, const SliceSet&, const ScanSummary&) {
  // The last on_meshes and the final (idle) status already went out; the snapshot server keeps
  // answering until the sink is destroyed.
  return Status::ok();
}

std::string PublishSink::endpoint() const { return impl_->publisher.endpoint(); }
std::string PublishSink::snapshot_endpoint() const { return impl_->publisher.snapshot_endpoint(); }
std::string PublishSink::scan_id() const { return impl_->publisher.scan(); }

}  // namespace sonoshape::scan
