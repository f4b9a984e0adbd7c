// The trakSTAR pose source driven through a fake bulk transport and the Bird emulator: known
// poses in millimetres, the setup it sends, INVALID poses counted by reason, stalls, garbage,
// unplug and replug, and the option parser. (The libusb path is tested under umockdev in
// trakstar_usb_test.cpp.)
#include "sonoshape/tracking/trakstar_source.hpp"

#include <gtest/gtest.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>

#include "bird_emulator.hpp"
#include "pose_samples.hpp"

namespace sonoshape::tracking::trakstar_source_test {
namespace {

using test::FakeDevice;
using test::opener;
using test::PointFault;

TrakstarOptions fast_options() {
  TrakstarOptions options;
  options.rate_hz = 255.0;
  options.reply_timeout_s = 0.05;
  options.reopen_interval_s = 0.01;
  return options;
}

using test::count_valid;
using test::take;
using test::take_then_stop;
using test::within_one;

double now_s() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

void expect_near(const Pose& pose, const Eigen::Isometry3d& expected, std::size_t k) {
  // One position step at 36 in is 0.11 mm; matrix elements 1 / 8192.
  EXPECT_LT((pose.T_reference_probe.translation() - expected.translation()).cwiseAbs().maxCoeff(),
            0.12)
      << k;
  EXPECT_LT((pose.T_reference_probe.linear() - expected.linear()).cwiseAbs().maxCoeff(), 1e-3) << k;
}

TEST(TrakstarPoseSource, DeliversTheEmulatorsPosesInMillimetresStampedOnReception) {
  FakeDevice device;
  TrakstarOptions options = fast_options();
  options.sensor = 3;
  options.rate_hz = 200.0;
  options.latency_s = 0.004;
  TrakstarPoseSource source(options, opener(device));
  const double before_s = now_s();
  ASSERT_TRUE(source.start());
  const auto poses = take_then_stop(source, 20);
  const double after_s = now_s();
  ASSERT_GE(poses.size(), 20u) << source.message();
  // The setup: range 36 in, 200 Hz x 256, POSITION/MATRIX, sent to sensor 3.
  EXPECT_EQ(device.emulator.value(bird::kParamPositionScaling), 0);
  EXPECT_EQ(device.emulator.value(bird::kParamMeasurementRate), 200 * 256);
  EXPECT_EQ(device.emulator.last_address(), 3);
  const auto sent = device.emulator.sent();
  for (std::size_t k = 0; k < poses.size(); ++k) {
    ASSERT_EQ(poses[k].status, TrackingStatus::kValid) << k;
    expect_near(poses[k], sent[k], k);
    EXPECT_GT(poses[k].timestamp_s, before_s - options.latency_s);
    EXPECT_LT(poses[k].timestamp_s, after_s - options.latency_s);
    if (k > 0) {
      EXPECT_GT(poses[k].timestamp_s, poses[k - 1].timestamp_s);
    }
  }
  // POINTs are paced at the measurement rate: 20 samples at 200 Hz take at least 95 ms.
  EXPECT_GT(poses.back().timestamp_s - poses.front().timestamp_s, 19 / 200.0 - 0.005);
  within_one(source.backend().counts().valid, poses.size());
  EXPECT_EQ(source.backend().status_line(), "connected");
}

TEST(TrakstarPoseSource, LongRangeReadsPositionsBeyond36Inches) {
  for (const bool long_range : {false, true}) {
    FakeDevice device;
    device.emulator.pose_of = [](std::size_t) {
      Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
      t.translation() = Eigen::Vector3d(1500.0, -300.0, 200.0);  // 59 in
      return t;
    };
    TrakstarOptions options = fast_options();
    options.long_range = long_range;
    TrakstarPoseSource source(options, opener(device));
    ASSERT_TRUE(source.start());
    const auto poses = take_then_stop(source, 3);
    ASSERT_GE(poses.size(), 3u);
    EXPECT_EQ(device.emulator.value(bird::kParamPositionScaling), long_range ? 1 : 0);
    for (const Pose& p : poses) {
      EXPECT_EQ(p.status, long_range ? TrackingStatus::kValid : TrackingStatus::kInvalid);
      if (long_range) {
        EXPECT_NEAR(p.T_reference_probe.translation().x(), 1500.0, 0.25);
      }
    }
    within_one(source.backend().counts().out_of_range, long_range ? 0u : poses.size());
  }
}

TEST(TrakstarPoseSource, FaultScriptGivesInvalidPosesCountedByReasonAndRecovers) {
  FakeDevice device;
  device.emulator.faults = {{1, PointFault::kGarbage},    {2, PointFault::kStall},
                            {3, PointFault::kDetached},   {4, PointFault::kDetached},
                            {5, PointFault::kOutOfRange}, {6, PointFault::kCutRecord},
                            {7, PointFault::kStall}};
  TrakstarPoseSource source(fast_options(), opener(device));
  ASSERT_TRUE(source.start());
  // POINTs 0..9 answered except the two stalls: 8 samples.
  const auto poses = take_then_stop(source, 8);
  ASSERT_GE(poses.size(), 8u);
  const std::vector<TrackingStatus> expected = {TrackingStatus::kValid,   TrackingStatus::kValid,
                                                TrackingStatus::kInvalid, TrackingStatus::kInvalid,
                                                TrackingStatus::kInvalid, TrackingStatus::kValid,
                                                TrackingStatus::kValid,   TrackingStatus::kValid};
  const auto sent = device.emulator.sent();
  std::size_t valid = 0;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    ASSERT_EQ(poses[k].status, k < expected.size() ? expected[k] : TrackingStatus::kValid) << k;
    if (poses[k].status == TrackingStatus::kValid) expect_near(poses[k], sent[valid++], k);
  }
  const TrakstarCounts c = source.backend().counts();
  within_one(c.valid, count_valid(poses));
  EXPECT_EQ(count_valid(poses), poses.size() - 3);
  EXPECT_EQ(c.not_attached, 2u);
  EXPECT_EQ(c.out_of_range, 1u);
  EXPECT_EQ(c.timeouts, 2u);
  EXPECT_EQ(c.skipped_bytes, 3u + 7u);  // the garbage and the cut record
  EXPECT_EQ(c.unplugged, 0u);
}

TEST(TrakstarPoseSource, UnplugMidStreamIsReportedAndPosesContinueAfterReplug) {
  FakeDevice device;
  TrakstarPoseSource source(fast_options(), opener(device));
  ASSERT_TRUE(source.start());
  ASSERT_EQ(take(source, 5).size(), 5u);
  device.plugged = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (source.backend().connected() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  ASSERT_FALSE(source.backend().connected());
  EXPECT_NE(source.backend().status_line().find("waiting for the tracker to come back"),
            std::string::npos)
      << source.backend().status_line();
  EXPECT_EQ(source.condition(), source.backend().status_line());
  // Tries to reopen while unplugged, and the source keeps running.
  const int opens = device.opens;
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_GT(device.opens, opens);
  EXPECT_EQ(source.state(), acquisition::SourceState::kRunning);
  while (source.next(0.0)) {
  }  // samples received before the unplug
  device.plugged = true;
  const auto after = take_then_stop(source, 5);
  ASSERT_GE(after.size(), 5u);
  for (const Pose& p : after) EXPECT_EQ(p.status, TrackingStatus::kValid);
  EXPECT_EQ(source.backend().counts().unplugged, 1u);
  EXPECT_EQ(source.backend().counts().reopened, 1u);
  EXPECT_EQ(source.backend().status_line(), "connected (reopened after an unplug)");
  EXPECT_EQ(source.condition(), "");
}

TEST(TrakstarPoseSource, NoTrackerAtStartFailsTheSourceWithTheReason) {
  FakeDevice device;
  device.plugged = false;
  TrakstarPoseSource source(fast_options(), opener(device));
  ASSERT_TRUE(source.start());
  EXPECT_FALSE(source.next(5.0));
  EXPECT_EQ(source.state(), acquisition::SourceState::kFailed);
  EXPECT_NE(source.message().find("no tracker"), std::string::npos) << source.message();
}

TEST(TrakstarPoseSource, ADeviceThatDoesNotAnswerTheProtocolIsRefused) {
  FakeDevice device;
  TrakstarPoseSource source(fast_options(), [&device](std::string&) {
    struct Silent final : BirdTransport {
      UsbIo write(std::span<const std::uint8_t>, double) override { return UsbIo::kOk; }
      UsbIo read(std::span<std::uint8_t>, std::size_t& received, double) override {
        received = 0;
        return UsbIo::kTimeout;
      }
    };
    return std::unique_ptr<BirdTransport>(std::make_unique<Silent>());
  });
  ASSERT_TRUE(source.start());
  EXPECT_FALSE(source.next(5.0));
  EXPECT_EQ(source.state(), acquisition::SourceState::kFailed);
  EXPECT_NE(source.message().find("does not answer the Bird protocol"), std::string::npos)
      << source.message();
}

TEST(TrakstarOptions, ParsesEveryKeyAndRefusesBadValues) {
  const auto options =
      parse_trakstar_options("sensor=2,rate=120,range=72,latency_ms=8,product=0x0007");
  ASSERT_TRUE(options) << options.message();
  EXPECT_EQ(options->sensor, 2);
  EXPECT_DOUBLE_EQ(options->rate_hz, 120.0);
  EXPECT_TRUE(options->long_range);
  EXPECT_DOUBLE_EQ(options->latency_s, 0.008);
  EXPECT_EQ(options->product_id, 7);
  EXPECT_TRUE(parse_trakstar_options(""));
  for (const char* bad : {"sensor=0", "sensor=1.5", "rate=300", "range=48", "latency_ms=-1",
                          "product=0xZZ", "colour=red", "sensor"}) {
    const auto parsed = parse_trakstar_options(bad);
    EXPECT_FALSE(parsed) << bad;
    EXPECT_NE(parsed.message().find("usb:trakstar"), std::string::npos) << parsed.message();
  }
}

}  // namespace
}  // namespace sonoshape::tracking::trakstar_source_test
