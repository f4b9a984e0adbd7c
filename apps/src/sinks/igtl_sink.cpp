#include "sonoshape/apps/igtl_sink.hpp"

#include "sonoshape/publish/igtl_server.hpp"
#include "status_report.hpp"

namespace sonoshape::apps {

struct IgtlSink::Impl {
  publish::IgtlServer server;
};

Result<std::shared_ptr<IgtlSink>> IgtlSink::start(const std::string& host, int port) {
  publish::IgtlServerOptions options;
  options.host = host;
  options.port = port;
  Result<publish::IgtlServer> server = publish::IgtlServer::start(options);
  if (!server) return server.status();
  auto impl = std::make_unique<Impl>(Impl{std::move(*server)});
  return std::shared_ptr<IgtlSink>(new IgtlSink(std::move(impl)));
}

IgtlSink::IgtlSink(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
IgtlSink::~IgtlSink() = default;

Status IgtlSink::on_frame(const TrackedFrame& frame, const Eigen::Matrix4d& T_reference_image) {
  return impl_->server.publish_image(frame.frame.image, T_reference_image);
}

Status IgtlSink::on_slice(const LabeledSlice&, std::size_t) {
  return Status::ok();  // the surfaces show the slices' effect; Slicer has no contour message
}

Status IgtlSink::on_meshes(const MeshSet& meshes, const scan::MeshUpdateInfo&) {
  return impl_->server.publish_meshes(meshes);
}

Status IgtlSink::on_status(const scan::ScanStatus& status) {
  return impl_->server.publish_status(report_of(status));
}

Status IgtlSink::on_finish(const MeshSet&, const SliceSet&, const scan::ScanSummary&) {
  // The last meshes and the final status already went out; closing the server delivers what is
  // still queued (up to a second) before it disconnects the clients.
  return Status::ok();
}

int IgtlSink::port() const { return impl_->server.port(); }

std::string IgtlSink::describe() const {
  const publish::IgtlServerStats s = impl_->server.stats();
  return "OpenIGTLink: " + std::to_string(s.clients_accepted) + " clients served, " +
         std::to_string(s.messages_sent) + " messages sent, " + std::to_string(s.messages_dropped) +
         " dropped for slow clients, " + std::to_string(s.requests_answered) + " requests answered";
}

}  // namespace sonoshape::apps
