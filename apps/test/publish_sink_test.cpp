// PublishSink: B-mode previews (`frame` messages) downsampled on their plane and rate-limited,
// and the status's update time and frame-to-mesh latency, as a subscriber receives them.
#include "sonoshape/apps/publish_sink.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "sonoshape/publish/subscriber.hpp"

namespace sonoshape::scan::publish_sink_test {
namespace {

using apps::FramePreviewOptions;
using apps::PublishSink;
using namespace std::chrono_literals;

// A subscriber that has the sink's (empty) snapshot: its subscription has reached the sink.
publish::MeshSubscriber subscribe(const PublishSink& sink) {
  publish::SubscriberOptions options;
  options.endpoint = sink.endpoint();
  options.snapshot_endpoint = sink.snapshot_endpoint();
  Result<publish::MeshSubscriber> subscriber = publish::MeshSubscriber::connect(options);
  if (!subscriber) throw std::runtime_error(subscriber.message());
  auto end = subscriber->receive(2s);
  if (!end || !*end || !std::holds_alternative<publish::SnapshotEnd>((*end)->body))
    throw std::runtime_error("no snapshot end");
  return std::move(*subscriber);
}

std::shared_ptr<PublishSink> bind_sink(const FramePreviewOptions& previews) {
  auto sink = PublishSink::bind("tcp://127.0.0.1:*", "tcp://127.0.0.1:*", previews);
  if (!sink) throw std::runtime_error(sink.message());
  return *sink;
}

// A 512 x 256 frame, its left half black and its right half grey 200.
TrackedFrame half_grey_frame() {
  TrackedFrame frame;
  frame.frame.index = 7;
  frame.frame.timestamp_s = 1.5;
  frame.frame.image = GreyImage(512, 256);
  for (int row = 0; row < 256; ++row)
    for (int column = 256; column < 512; ++column) frame.frame.image.at(column, row) = 200;
  return frame;
}

TEST(PublishSinkPreviews, AFrameGoesOutDownsampledOnItsPlaneAtMostAtTheRate) {
  FramePreviewOptions previews;
  previews.rate_hz = 2.0;
  previews.max_side_px = 128;
  const auto sink = bind_sink(previews);
  publish::MeshSubscriber subscriber = subscribe(*sink);

  // Columns run along y (0.2 mm a pixel), rows along z (0.3 mm), pixel (0, 0) at (10, 20, 30).
  Eigen::Matrix4d T_reference_image = Eigen::Matrix4d::Zero();
  T_reference_image.block<3, 1>(0, 0) = Eigen::Vector3d(0, 0.2, 0);
  T_reference_image.block<3, 1>(0, 1) = Eigen::Vector3d(0, 0, 0.3);
  T_reference_image.block<3, 1>(0, 2) = Eigen::Vector3d(1, 0, 0);
  T_reference_image.block<4, 1>(0, 3) = Eigen::Vector4d(10, 20, 30, 1);
  const TrackedFrame frame = half_grey_frame();
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(sink->on_frame(frame, T_reference_image));

  auto received = subscriber.receive(2s);
  ASSERT_TRUE(received && *received) << (received ? "no message" : received.message());
  const auto& preview = std::get<publish::FrameImage>((*received)->body);
  EXPECT_EQ(preview.index, 7);
  EXPECT_EQ(preview.timestamp_s, 1.5);
  ASSERT_EQ(preview.image.width, 128);
  ASSERT_EQ(preview.image.height, 64);
  EXPECT_EQ(preview.image.at(63, 10), 0);  // area averaging of whole 4 x 4 blocks
  EXPECT_EQ(preview.image.at(64, 10), 200);
  EXPECT_NEAR(preview.size_mm.x(), 512 * 0.2, 1e-9);
  EXPECT_NEAR(preview.size_mm.y(), 256 * 0.3, 1e-9);
  EXPECT_TRUE(preview.plane.u.isApprox(Vec3(0, 1, 0)));
  EXPECT_TRUE(preview.plane.v.isApprox(Vec3(0, 0, 1)));
  // The picture's corner: half a pixel before pixel (0, 0)'s centre on both axes.
  EXPECT_TRUE(preview.plane.origin_mm.isApprox(Vec3(10, 19.9, 29.85)));

  // The two frames right after it fell within the same half second: not sent.
  auto none = subscriber.receive(200ms);
  ASSERT_TRUE(none);
  EXPECT_FALSE(none->has_value());
  std::this_thread::sleep_for(600ms);
  ASSERT_TRUE(sink->on_frame(frame, T_reference_image));
  auto next = subscriber.receive(2s);
  ASSERT_TRUE(next && *next);
  EXPECT_TRUE(std::holds_alternative<publish::FrameImage>((*next)->body));
}

TEST(PublishSinkPreviews, NoPreviewsUnlessAskedAndNoneOfAFrameWithoutSpacing) {
  const auto quiet = bind_sink(FramePreviewOptions{});
  publish::MeshSubscriber subscriber = subscribe(*quiet);
  ASSERT_TRUE(quiet->on_frame(half_grey_frame(), Eigen::Matrix4d::Identity()));
  auto none = subscriber.receive(300ms);
  ASSERT_TRUE(none);
  EXPECT_FALSE(none->has_value());

  FramePreviewOptions previews;
  previews.rate_hz = 5.0;
  const auto sink = bind_sink(previews);
  Eigen::Matrix4d flat = Eigen::Matrix4d::Identity();
  flat(1, 1) = 0.0;  // rows collapse onto one line: no plane to show the picture on
  const Status refused = sink->on_frame(half_grey_frame(), flat);
  EXPECT_FALSE(refused);
  EXPECT_NE(refused.message().find("frame 7"), std::string::npos) << refused.message();
  EXPECT_FALSE(PublishSink::bind("tcp://127.0.0.1:*", "", FramePreviewOptions{1.0, 0}));
}

TEST(PublishSinkStatus, UpdateTimeAndLatencyFromTheFirstUpdateOn) {
  const auto sink = bind_sink(FramePreviewOptions{});
  publish::MeshSubscriber subscriber = subscribe(*sink);
  ScanStatus status;
  status.counters.frames_received = 3;
  ASSERT_TRUE(sink->on_status(status));
  status.counters.updates = 2;
  status.counters.last_update_ms = 40.0;
  status.counters.last_latency_s = 0.25;
  ASSERT_TRUE(sink->on_status(status));

  auto before = subscriber.receive(2s);
  ASSERT_TRUE(before && *before);
  const auto& first = std::get<publish::StatusReport>((*before)->body);
  EXPECT_FALSE(first.latency_ms.has_value());
  EXPECT_FALSE(first.update_ms.has_value());
  auto after = subscriber.receive(2s);
  ASSERT_TRUE(after && *after);
  const auto& second = std::get<publish::StatusReport>((*after)->body);
  EXPECT_EQ(second.latency_ms, 250.0);
  EXPECT_EQ(second.update_ms, 40.0);
}

// Issue 40, "a finished scan reads as finished": after the final (idle) status, the sink's last
// message is a status with "finished": true and the summary's final counts, so that a view tells
// a finished scan from a lost one; every status says how many frames a second go out (0: none).
TEST(PublishSinkStatus, TheLastMessageSaysTheScanFinishedWithTheFinalCounts) {
  const auto sink = bind_sink(FramePreviewOptions{});
  publish::MeshSubscriber subscriber = subscribe(*sink);
  ScanStatus idle;
  idle.state = ScanState::kIdle;
  idle.message = "scan finished (source ended): 4 slices";
  idle.counters.frames_received = 10;
  idle.counters.slices = 4;
  ASSERT_TRUE(sink->on_status(idle));
  ScanSummary summary;
  summary.counters.frames_received = 12;
  summary.counters.slices = 5;
  ASSERT_TRUE(sink->on_finish(MeshSet{}, SliceSet{}, summary));

  auto first = subscriber.receive(2s);
  ASSERT_TRUE(first && *first);
  const auto& said = std::get<publish::StatusReport>((*first)->body);
  EXPECT_FALSE(said.finished);
  EXPECT_EQ(said.frame_rate_hz, 0.0);  // no previews asked for
  auto last = subscriber.receive(2s);
  ASSERT_TRUE(last && *last);
  const auto& finished = std::get<publish::StatusReport>((*last)->body);
  EXPECT_TRUE(finished.finished);
  EXPECT_EQ(finished.state, ScanState::kIdle);
  EXPECT_EQ(finished.message, idle.message);
  EXPECT_EQ(finished.frames_received, 12u);
  EXPECT_EQ(finished.slices, 5u);
  EXPECT_EQ((*last)->seq, (*first)->seq + 1);
}

}  // namespace
}  // namespace sonoshape::scan::publish_sink_test
