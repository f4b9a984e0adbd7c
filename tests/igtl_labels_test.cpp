// Bring your own labels over OpenIGTLink (issue 39, point 3): `scan --source igtl: --labels
// igtl:LabelMap` against a server written with the OpenIGTLink library that sends, as PlusServer
// beside a segmentation network would, the probe's TRANSFORM, the B-mode IMAGE and a label-map
// IMAGE of another device name, the label map one frame late (the network's lag), all stamped
// with the frame's time. The slices must hold each frame's own label rectangles.
#include <gtest/gtest.h>
#include <igtlImageMessage.h>
#include <igtlServerSocket.h>
#include <igtlTransformMessage.h>
#include <igtl_util.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/free_port.hpp"
#include "sonoshape/testing/sanitizer_slowdown.hpp"
#include "sonoshape/testing/slicer_labels.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::igtl_labels_test {
namespace {

using testing::contains;

constexpr int kW = 120, kH = 90, kFrames = 30;
constexpr double kPixelMm = 0.3, kFramePeriodS = 0.05, kStepMm = 1.0;
constexpr int kLiver = 3, kKidney = 7;

double wall_clock_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// Every client gets the whole stream from frame 0, paced at 20 frames per second.
class LibraryServer {
 public:
  /// `label_type`: the label maps' scalar type (igtl::ImageMessage::TYPE_*), sent in the
  /// host's byte order as 3D Slicer does.
  LibraryServer(std::string label_device, int label_width,
                int label_type = igtl::ImageMessage::TYPE_UINT8)
      : label_device_(std::move(label_device)),
        label_width_(label_width),
        label_type_(label_type),
        port_(testing::free_port()),
        t0_s_(std::floor(wall_clock_s())) {
    server_ = igtl::ServerSocket::New();
    EXPECT_GE(server_->CreateServer(port_), 0);
    accept_ = std::thread([this] {
      while (!done_) {
        igtl::ClientSocket::Pointer client = server_->WaitForConnection(50);
        if (client.IsNotNull()) clients_.emplace_back([this, client] { serve(client); });
      }
    });
  }
  ~LibraryServer() {
    done_ = true;
    accept_.join();
    for (std::thread& t : clients_) t.join();
    server_->CloseSocket();
  }
  int port() const { return port_; }
  double time_s(int k) const { return t0_s_ + kFramePeriodS * k; }

 private:
  igtl::TimeStamp::Pointer stamp(int k) const {
    igtl::TimeStamp::Pointer ts = igtl::TimeStamp::New();
    ts->SetTime(time_s(k));
    return ts;
  }
  void send_image(const igtl::ClientSocket::Pointer& client, const std::string& device, int k,
                  const std::vector<std::uint8_t>& pixels, int width,
                  int type = igtl::ImageMessage::TYPE_UINT8) const {
    igtl::ImageMessage::Pointer image = igtl::ImageMessage::New();
    image->SetDeviceName(device.c_str());
    image->SetDimensions(width, kH, 1);
    image->SetSpacing(static_cast<float>(kPixelMm), static_cast<float>(kPixelMm), 1.0f);
    image->SetScalarType(type);
    image->SetEndian(igtl_is_little_endian() ? igtl::ImageMessage::ENDIAN_LITTLE
                                             : igtl::ImageMessage::ENDIAN_BIG);
    igtl::TimeStamp::Pointer ts = stamp(k);
    image->SetTimeStamp(ts);
    image->AllocateScalars();
    if (type == igtl::ImageMessage::TYPE_INT16) {
      auto* values = static_cast<std::int16_t*>(image->GetScalarPointer());
      std::copy(pixels.begin(), pixels.end(), values);
    } else {
      std::copy(pixels.begin(), pixels.end(),
                static_cast<std::uint8_t*>(image->GetScalarPointer()));
    }
    image->Pack();
    client->Send(image->GetPackPointer(), image->GetPackSize());
  }
  void send_label_map(const igtl::ClientSocket::Pointer& client, int k) const {
    const LabelImage map = testing::label_rectangles(
        label_width_, kH, testing::fixture_rectangles(k, label_width_, kH, kLiver, kKidney, 255));
    send_image(client, label_device_, k, map.pixels, label_width_, label_type_);
  }
  void serve(const igtl::ClientSocket::Pointer& client) const {
    std::mt19937 rng(5);
    for (int k = 0; k < kFrames && !done_; ++k) {
      igtl::TransformMessage::Pointer pose = igtl::TransformMessage::New();
      pose->SetDeviceName("ProbeToReference");
      igtl::Matrix4x4 m;
      igtl::IdentityMatrix(m);
      m[2][3] = static_cast<float>(kStepMm * k);
      pose->SetMatrix(m);
      igtl::TimeStamp::Pointer ts = stamp(k);
      pose->SetTimeStamp(ts);
      pose->Pack();
      client->Send(pose->GetPackPointer(), pose->GetPackSize());
      std::vector<std::uint8_t> bmode(static_cast<std::size_t>(kW * kH));
      for (auto& p : bmode) p = static_cast<std::uint8_t>(40 + rng() % 120);
      send_image(client, "Image", k, bmode, kW);
      if (k > 0) send_label_map(client, k - 1);
      std::this_thread::sleep_for(std::chrono::duration<double>(kFramePeriodS));
    }
    if (!done_) send_label_map(client, kFrames - 1);
    while (!done_) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    client->CloseSocket();
  }

  std::string label_device_;
  int label_width_;
  int label_type_;
  int port_;
  double t0_s_;
  igtl::ServerSocket::Pointer server_;
  std::atomic<bool> done_{false};
  std::thread accept_;
  std::vector<std::thread> clients_;
};

struct ScanRun {
  testing::TempDir dir;
  int code = -1;
  std::string log;
  std::filesystem::path out = dir.path() / "scan";

  ScanRun(const LibraryServer& server, const std::string& extra) {
    const auto calibration = dir.path() / "calibration.json";
    std::ofstream(calibration) << R"({"ImageToProbe": [0.3,0,0,0, 0,0.3,0,0, 0,0,1,0, 0,0,0,1]})";
    const auto config = dir.path() / "exact.json";
    std::ofstream(config)
        << R"({"format": "sonoshape-segmentation", "version": 1, "simplify_mm": 0})";
    const int limit_s = static_cast<int>(60 * sonoshape::testing::kSanitizerSlowdown);
    const auto result = testing::run_command(
        "timeout " + std::to_string(limit_s) + " " + std::string(SONOSHAPE_BINARY),
        "scan --source igtl:127.0.0.1:" + std::to_string(server.port()) + " --calibration " +
            calibration.string() + " --segmentation " + config.string() +
            " --keyframe-distance-mm 0.5 --depth 5 --duration 3 --out " + out.string() + " " +
            extra,
        dir.path() / "scan.log");
    code = result.exit_code;
    log = result.output;
  }
};

// The slices of `run` hold each frame's own label rectangles, where its pose puts them.
void expect_each_frames_rectangles(const ScanRun& run, const LibraryServer& server) {
  ASSERT_EQ(run.code, 0) << run.log;
  EXPECT_TRUE(contains(run.log, "label maps from IMAGE 'LabelMap' of igtl:127.0.0.1:" +
                                    std::to_string(server.port())));
  const auto slices = read_slice_set(run.out / "slices.json");
  ASSERT_TRUE(slices) << slices.message() << run.log;
  // 30 frames 1 mm apart; the first few may pass while the scan's three connections open.
  EXPECT_GE(slices->slices.size(), 15u) << run.log;
  std::cout << "scan --labels igtl:LabelMap: " << slices->slices.size() << " slices of " << kFrames
            << " frames\n";
  const double px2 = kPixelMm * kPixelMm;
  for (const LabeledSlice& slice : slices->slices) {
    // The pose puts frame k at z = k mm: the slice's plane says which frame it is, its
    // timestamp must agree.
    const int k = static_cast<int>(std::lround(slice.origin_mm.z() / kStepMm));
    ASSERT_GE(k, 0);
    ASSERT_LT(k, kFrames);
    EXPECT_NEAR(slice.timestamp_s.value_or(0.0), server.time_s(k), 1e-3);
    const auto found = testing::label_shapes(slice);
    const auto rects = testing::fixture_rectangles(k, kW, kH, kLiver, kKidney, 255);
    ASSERT_EQ(found.size(), 3u) << "frame " << k;
    ASSERT_TRUE(found.count(kLiver)) << "frame " << k;
    for (const testing::LabelRect& rect : rects) {
      const int label = rect.label == 255 ? kUnknownLabel : rect.label;
      ASSERT_TRUE(found.count(label)) << "frame " << k << ", label " << label;
      EXPECT_NEAR(found.at(label).area_mm2, rect.w * rect.h * px2, (rect.w + rect.h) * px2)
          << "frame " << k << ", label " << label;
      // Pixel (i, j) of frame k is at (0.3 i, 0.3 j, k) mm: the slice's (u, v) are x and y.
      const Vec2 centre_mm = testing::rect_centre_px(rect) * kPixelMm;
      const Vec2 centroid_mm = (slice.origin_mm + found.at(label).centroid_mm.x() * slice.u +
                                found.at(label).centroid_mm.y() * slice.v)
                                   .head<2>();
      EXPECT_LT((centroid_mm - centre_mm).norm(), 0.5 * kPixelMm)
          << "frame " << k << ", label " << label << ": " << centroid_mm.transpose() << " vs "
          << centre_mm.transpose();
    }
  }
}

TEST(IgtlLabels, LabelMapImagesBesideTheBModeGiveEachFramesOwnRectangles) {
  LibraryServer server("LabelMap", kW);
  ScanRun run(server, "--igtl-image Image --labels igtl:LabelMap");
  expect_each_frames_rectangles(run, server);
}

// 3D Slicer sends a labelmap volume in its own scalar type, often 16-bit.
TEST(IgtlLabels, SixteenBitLabelMapsAsSlicerSendsThemAreRead) {
  LibraryServer server("LabelMap", kW, igtl::ImageMessage::TYPE_INT16);
  ScanRun run(server, "--igtl-image Image --labels igtl:LabelMap");
  expect_each_frames_rectangles(run, server);
}

TEST(IgtlLabels, LabelMapsOfAnotherSizeOrAnAbsentDeviceGiveNoSliceAndSayWhy) {
  {
    LibraryServer server("LabelMap", kW / 2);
    ScanRun run(server, "--igtl-image Image --labels igtl:LabelMap");
    EXPECT_TRUE(contains(run.log, "is 60x90 pixels but the frame is 120x90"));
    EXPECT_TRUE(contains(run.log, "\n  slices 0,"));
  }
  {
    LibraryServer server("Segmentation", kW);
    ScanRun run(server, "--igtl-image Image --labels igtl:LabelMap --labels-wait-ms 100");
    EXPECT_TRUE(contains(run.log, "no label map stamped within 1 ms of frame"));
    EXPECT_TRUE(contains(run.log, "\n  slices 0,"));
  }
  LibraryServer server("LabelMap", kW);
  ScanRun run(server, "--labels igtl:LabelMap");
  EXPECT_EQ(run.code, 1);
  EXPECT_TRUE(contains(run.log, "needs --igtl-image NAME"));
}

}  // namespace
}  // namespace sonoshape::igtl_labels_test
