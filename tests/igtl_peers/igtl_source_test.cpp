// OpenIGTLink in (`--source igtl:`): the frame and pose sources against Debian's ImagerServer and
// TrackerServer examples (built from their shipped sources), and against sonoshape's own server
// for the pose an IMAGE carries. Loopback only; every wait bounded.
#include <gtest/gtest.h>
#include <igtlTransformMessage.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "sonoshape/acquisition/igtl_frame_source.hpp"
#include "sonoshape/publish/igtl_server.hpp"
#include "sonoshape/testing/free_port.hpp"
#include "sonoshape/testing/sanitizer_slowdown.hpp"
#include "sonoshape/tracking/igtl_pose_source.hpp"

namespace sonoshape::igtl_source_test {
namespace {

// Whether something listens on `port` (from /proc/net/tcp, without connecting: the examples
// serve one client at a time, so a probing connection would take the test's place).
bool listening(int port) {
  std::ifstream in("/proc/net/tcp");
  std::string line;
  char hex[8];
  std::snprintf(hex, sizeof hex, ":%04X", port);
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string slot, local, remote, state;
    fields >> slot >> local >> remote >> state;
    if (local.size() > 5 && local.substr(local.size() - 5) == hex && state == "0A") return true;
  }
  return false;
}

// An example server as a child process, killed at the end of the test.
class Peer {
 public:
  Peer(const std::vector<std::string>& argv) : port_(testing::free_port()) {
    pid_ = fork();
    if (pid_ == 0) {
      std::vector<std::string> args = argv;
      args.insert(args.begin() + 1, std::to_string(port_));
      std::vector<char*> raw;
      for (auto& a : args) raw.push_back(a.data());
      raw.push_back(nullptr);
      std::freopen("/dev/null", "w", stdout);
      std::freopen("/dev/null", "w", stderr);
      execv(raw[0], raw.data());
      _exit(127);
    }
    for (int k = 0; k < 250 && !listening(port_); ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ~Peer() {
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
  }
  int port() const { return port_; }
  bool up() const { return listening(port_); }

 private:
  int port_;
  pid_t pid_ = -1;
};

double wall_clock_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

template <typename Source, typename Item>
std::vector<Item> take(Source& source, std::size_t count, double timeout_s) {
  std::vector<Item> items;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (items.size() < count && std::chrono::steady_clock::now() < end && !source.finished())
    if (auto r = source.next(0.1)) items.push_back(r->item);
  return items;
}

TEST(IgtlSources, FramesFromDebiansImagerServerArriveWholeAndInOrder) {
  Peer imager({IMAGER_SERVER, "50", IMAGER_IMAGES});  // 50 frames per second
  ASSERT_TRUE(imager.up());
  acquisition::IgtlFrameSource source(acquisition::IgtlEndpoint{"127.0.0.1", imager.port()}, "");
  const double before_s = wall_clock_s();
  ASSERT_TRUE(source.start());
  const std::vector<Frame> frames = take<acquisition::IgtlFrameSource, Frame>(source, 10, 10.0);
  const double after_s = wall_clock_s();
  ASSERT_EQ(frames.size(), 10u) << source.message();
  for (std::size_t k = 0; k < frames.size(); ++k) {
    EXPECT_EQ(frames[k].index, static_cast<std::int64_t>(k));
    EXPECT_EQ(frames[k].image.width, 256);
    EXPECT_EQ(frames[k].image.height, 256);
    // The example sets no timestamp: the arrival time on the wall clock stands in for it.
    EXPECT_GE(frames[k].timestamp_s, before_s);
    EXPECT_LE(frames[k].timestamp_s, after_s);
    if (k > 0) {
      EXPECT_GT(frames[k].timestamp_s, frames[k - 1].timestamp_s);
    }
  }
  // The test images differ: they are the example's files, not a constant.
  EXPECT_NE(frames[0].image.pixels, frames[1].image.pixels);
  EXPECT_EQ(source.dropped(), 0u);
}

TEST(IgtlSources, PosesFromDebiansTrackerServerAreItsMatricesInOrder) {
  Peer tracker({TRACKER_SERVER, "50"});
  ASSERT_TRUE(tracker.up());
  tracking::IgtlPoseSource source(acquisition::IgtlEndpoint{"127.0.0.1", tracker.port()}, "Tracker",
                                  tracking::IgtlPoseFrom::kTransform);
  ASSERT_TRUE(source.start());
  const std::vector<Pose> poses = take<tracking::IgtlPoseSource, Pose>(source, 5, 10.0);
  ASSERT_EQ(poses.size(), 5u) << source.message();
  const double now_s = wall_clock_s();
  for (std::size_t k = 0; k < poses.size(); ++k) {
    // The example's k-th sample (its sequence starts with the first connection): position
    // 50 (cos 0.2k, sin 0.2k, cos 0.2k) mm, sent every 20 ms without a timestamp (the arrival
    // time stands in; the round trip below shows a sender's timestamp is kept).
    const double phi = 0.2 * static_cast<double>(k);
    EXPECT_EQ(poses[k].status, TrackingStatus::kValid);
    EXPECT_TRUE(poses[k].T_reference_probe.translation().isApprox(
        50.0 * Eigen::Vector3d(std::cos(phi), std::sin(phi), std::cos(phi)), 1e-5))
        << poses[k].T_reference_probe.translation().transpose();
    EXPECT_NEAR(poses[k].timestamp_s, now_s, 5.0);
    if (k > 0) {
      EXPECT_GT(poses[k].timestamp_s, poses[k - 1].timestamp_s);
    }
  }
  // Non-rigid matrices are INVALID samples, not skewed poses.
  Eigen::Matrix4d skewed = Eigen::Matrix4d::Identity();
  skewed(0, 1) = 0.1;
  EXPECT_EQ(tracking::pose_from_matrix(skewed, 1.0).status, TrackingStatus::kInvalid);
  EXPECT_EQ(tracking::pose_from_matrix(Eigen::Matrix4d::Identity(), 1.0).status,
            TrackingStatus::kValid);
}

TEST(IgtlSources, PosesFromDebiansTrackingDataServerAreOneToolOfItsTdataStream) {
  Peer server({TRACKING_DATA_SERVER});
  ASSERT_TRUE(server.up());
  // It streams only after STT_TDATA, which the source sends on connection.
  tracking::IgtlPoseSource channel0(acquisition::IgtlEndpoint{"127.0.0.1", server.port()},
                                    "Channel 0", tracking::IgtlPoseFrom::kTrackingData);
  ASSERT_TRUE(channel0.start());
  const std::vector<Pose> poses = take<tracking::IgtlPoseSource, Pose>(channel0, 5, 10.0);
  ASSERT_EQ(poses.size(), 5u) << channel0.message();
  for (std::size_t k = 0; k < poses.size(); ++k) {
    EXPECT_EQ(poses[k].status, TrackingStatus::kValid);
    if (k > 0) {
      EXPECT_GT(poses[k].timestamp_s, poses[k - 1].timestamp_s);
      // Channel 0 moves (its phase steps 0.1 per message): consecutive samples differ.
      EXPECT_FALSE(poses[k].T_reference_probe.isApprox(poses[k - 1].T_reference_probe, 1e-6));
    }
  }
  EXPECT_EQ(channel0.dropped(), 0u);
}

// A sender whose timestamp field holds stray bytes (OpenIGTLink 1.11's servers send their message
// object's unset field: 0xbebebebe s, the year 2071, under AddressSanitizer's malloc fill) gets
// the arrival time; a plausible stamp, even an old one, is kept.
TEST(IgtlSources, AStampFromBeyondTomorrowIsReplacedByTheArrivalTime) {
  const int listener = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(listener, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(listener, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  ASSERT_EQ(::listen(listener, 1), 0);
  socklen_t length = sizeof address;
  ::getsockname(listener, reinterpret_cast<sockaddr*>(&address), &length);
  const int port = ntohs(address.sin_port);
  constexpr double kStray = 3200171710.0;  // 0xbebebebe s
  constexpr double kOld = 1.5e9;           // 2017: a recorded stream's stamp
  // Joined at the end of the test on every path; it gives up if no client comes within 10 s.
  std::jthread sender([listener] {
    pollfd waiting{listener, POLLIN, 0};
    const int peer = ::poll(&waiting, 1, 10000) == 1 ? ::accept(listener, nullptr, nullptr) : -1;
    ::close(listener);
    if (peer < 0) return;
    for (const double stamp : {kStray, kOld}) {
      igtl::TransformMessage::Pointer message = igtl::TransformMessage::New();
      message->SetDeviceName("Tracker");
      igtl::TimeStamp::Pointer time = igtl::TimeStamp::New();
      time->SetTime(stamp);
      message->SetTimeStamp(time);
      igtl::Matrix4x4 matrix;
      igtl::IdentityMatrix(matrix);
      message->SetMatrix(matrix);
      message->Pack();
      ::send(peer, message->GetPackPointer(), message->GetPackSize(), MSG_NOSIGNAL);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // until both are read
    ::close(peer);
  });
  const double before_s = wall_clock_s();
  tracking::IgtlPoseSource source(acquisition::IgtlEndpoint{"127.0.0.1", port}, "Tracker",
                                  tracking::IgtlPoseFrom::kTransform);
  ASSERT_TRUE(source.start());
  const std::vector<Pose> poses = take<tracking::IgtlPoseSource, Pose>(source, 2, 5.0);
  const double after_s = wall_clock_s();
  ASSERT_EQ(poses.size(), 2u) << source.message();
  EXPECT_GE(poses[0].timestamp_s, before_s);
  EXPECT_LE(poses[0].timestamp_s, after_s);
  EXPECT_NEAR(poses[1].timestamp_s, kOld, 1e-3);
}

TEST(IgtlSources, AnImagesOwnPoseAndPixelsSurviveTheRoundTripThroughOurServer) {
  publish::IgtlServerOptions options;
  options.port = 0;
  auto server = publish::IgtlServer::start(options);
  ASSERT_TRUE(server) << server.message();
  tracking::IgtlPoseSource poses(acquisition::IgtlEndpoint{"127.0.0.1", server->port()}, "Image",
                                 tracking::IgtlPoseFrom::kImage);
  acquisition::IgtlFrameSource frames(acquisition::IgtlEndpoint{"127.0.0.1", server->port()},
                                      "Image");
  ASSERT_TRUE(poses.start());
  ASSERT_TRUE(frames.start());
  for (int k = 0; k < 100 && server->stats().clients < 2; ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_EQ(server->stats().clients, 2u);

  GreyImage image(6, 4);
  for (std::size_t k = 0; k < image.pixels.size(); ++k)
    image.pixels[k] = static_cast<std::uint8_t>(k);
  Eigen::Isometry3d T_reference_probe = Eigen::Isometry3d::Identity();
  T_reference_probe.linear() =
      Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).matrix();
  T_reference_probe.translation() = Eigen::Vector3d(5, -7, 11);
  const Eigen::Matrix4d T_probe_image = Eigen::Vector4d(0.2, 0.3, 1.0, 1.0).asDiagonal();
  ASSERT_TRUE(server->publish_image(image, T_reference_probe.matrix() * T_probe_image));

  const auto pose = take<tracking::IgtlPoseSource, Pose>(poses, 1, 5.0);
  const auto frame = take<acquisition::IgtlFrameSource, Frame>(frames, 1, 5.0);
  ASSERT_EQ(pose.size(), 1u) << poses.message();
  ASSERT_EQ(frame.size(), 1u) << frames.message();
  EXPECT_EQ(pose[0].status, TrackingStatus::kValid);
  // Float on the wire: 1e-5 relative.
  EXPECT_TRUE(pose[0].T_reference_probe.matrix().isApprox(T_reference_probe.matrix(), 1e-5))
      << pose[0].T_reference_probe.matrix();
  EXPECT_EQ(frame[0].image.pixels, image.pixels);
  // One message read over two connections at different times: one timestamp, the sender's.
  EXPECT_EQ(frame[0].timestamp_s, pose[0].timestamp_s);
}

TEST(IgtlSources, AServerRestartedMidStreamIsReportedAndFramesAndPosesResume) {
  publish::IgtlServerOptions options;
  options.port = 0;
  auto server = publish::IgtlServer::start(options);
  ASSERT_TRUE(server) << server.message();
  options.port = server->port();  // the restarted server listens where the first did
  tracking::IgtlPoseSource poses(acquisition::IgtlEndpoint{"127.0.0.1", options.port}, "Image",
                                 tracking::IgtlPoseFrom::kImage);
  acquisition::IgtlFrameSource frames(acquisition::IgtlEndpoint{"127.0.0.1", options.port},
                                      "Image");
  ASSERT_TRUE(poses.start());
  ASSERT_TRUE(frames.start());
  auto wait_for_clients = [](const publish::IgtlServer& s, std::size_t n) {
    for (int k = 0; k < 300 && s.stats().clients < n; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return s.stats().clients;
  };
  ASSERT_EQ(wait_for_clients(*server, 2), 2u);
  const GreyImage image(6, 4, 7);
  const Eigen::Matrix4d T_reference_image = Eigen::Vector4d(0.2, 0.3, 1.0, 1.0).asDiagonal();
  ASSERT_TRUE(server->publish_image(image, T_reference_image));
  ASSERT_EQ((take<acquisition::IgtlFrameSource, Frame>(frames, 1, 5.0).size()), 1u)
      << frames.message();
  ASSERT_EQ((take<tracking::IgtlPoseSource, Pose>(poses, 1, 5.0).size()), 1u) << poses.message();

  // The server goes away: both sources keep running and say why.
  server = Status::error("stopped by the test");
  for (int k = 0; k < 300 && (frames.condition().empty() || poses.condition().empty()); ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_NE(frames.condition().find("connecting again"), std::string::npos) << frames.condition();
  EXPECT_NE(poses.condition().find("connecting again"), std::string::npos) << poses.condition();
  EXPECT_EQ(frames.state(), acquisition::SourceState::kRunning);
  EXPECT_EQ(poses.state(), acquisition::SourceState::kRunning);

  // Back on the same port: the sources connect again and the next image arrives.
  server = publish::IgtlServer::start(options);
  ASSERT_TRUE(server) << server.message();
  ASSERT_EQ(wait_for_clients(*server, 2), 2u);
  ASSERT_TRUE(server->publish_image(image, T_reference_image));
  const auto frame = take<acquisition::IgtlFrameSource, Frame>(frames, 1, 5.0);
  const auto pose = take<tracking::IgtlPoseSource, Pose>(poses, 1, 5.0);
  ASSERT_EQ(frame.size(), 1u) << frames.message();
  ASSERT_EQ(pose.size(), 1u) << poses.message();
  EXPECT_EQ(frame[0].image.pixels, image.pixels);
  EXPECT_EQ(pose[0].status, TrackingStatus::kValid);
  EXPECT_EQ(frames.condition(), "");
  EXPECT_EQ(poses.condition(), "");
}

TEST(IgtlSources, ANoServerIsAFailedSourceNamingTheAddress) {
  const int port = testing::free_port();
  acquisition::IgtlFrameSource source(acquisition::IgtlEndpoint{"127.0.0.1", port}, "");
  ASSERT_TRUE(source.start());
  EXPECT_TRUE((take<acquisition::IgtlFrameSource, Frame>(source, 1, 5.0).empty()));
  EXPECT_EQ(source.state(), acquisition::SourceState::kFailed);
  EXPECT_NE(source.message().find("127.0.0.1:" + std::to_string(port)), std::string::npos)
      << source.message();
  EXPECT_FALSE(acquisition::parse_igtl_endpoint("host:port", "--source igtl:"));
  EXPECT_EQ(acquisition::parse_igtl_endpoint("localhost", "--source igtl:")->port, 18944);
}

std::string run(const std::string& command, int& exit_code) {
  std::string output;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  char buffer[4096];
  while (std::size_t n = std::fread(buffer, 1, sizeof buffer, pipe)) output.append(buffer, n);
  const int status = ::pclose(pipe);
  exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return output;
}

// `scan --source igtl:` end to end: frames from Debian's ImagerServer, poses from its
// TrackerServer (a moving, rotating sensor), segmented and reconstructed.
TEST(IgtlSources, AScanReconstructsFromImagerServerFramesAndTrackerServerPoses) {
  Peer imager({IMAGER_SERVER, "30", IMAGER_IMAGES});
  Peer tracker({TRACKER_SERVER, "40"});  // 100 samples, then it drops the connection: 2.5 s
  ASSERT_TRUE(imager.up());
  ASSERT_TRUE(tracker.up());
  const std::string calibration = ::testing::TempDir() + "igtl_calibration.json";
  std::ofstream(calibration) << R"({"ImageToProbe": [0.5,0,0,0, 0,0.5,0,0, 0,0,1,0, 0,0,0,1]})";
  int code = 0;
  const std::string out = run(
      "timeout " + std::to_string(static_cast<int>(60 * sonoshape::testing::kSanitizerSlowdown)) +
          " " + std::string(SONOSHAPE_BINARY) +
          " scan --source igtl:127.0.0.1:" + std::to_string(imager.port()) +
          " --igtl-tracker 127.0.0.1:" + std::to_string(tracker.port()) +
          " --igtl-transform Tracker --calibration " + calibration + " --duration 1.5",
      code);
  ASSERT_EQ(code, 0) << out;
  EXPECT_NE(out.find("OpenIGTLink 127.0.0.1:" + std::to_string(imager.port()) + ": 256x256 frames"),
            std::string::npos)
      << out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(out, m, std::regex("frames received ([0-9]+)"))) << out;
  EXPECT_GE(std::stoi(m[1]), 20) << out;  // 30 per second for 1.5 s
  ASSERT_TRUE(std::regex_search(out, m, std::regex("\n  slices ([0-9]+),"))) << out;
  EXPECT_GT(std::stoi(m[1]), 0) << out;
}

TEST(IgtlSources, AScanWithoutItsServerSaysWhereItLookedAndWhatIsMissing) {
  int code = 0;
  const int port = testing::free_port();
  std::string out =
      run(std::string(SONOSHAPE_BINARY) + " scan --source igtl:127.0.0.1:" + std::to_string(port) +
              " --igtl-transform image",
          code);
  EXPECT_EQ(code, 1);
  EXPECT_NE(out.find("127.0.0.1:" + std::to_string(port)), std::string::npos) << out;
  EXPECT_NE(out.find("PlusServer"), std::string::npos) << out;
  out = run(std::string(SONOSHAPE_BINARY) + " scan --source igtl:127.0.0.1:" + std::to_string(port),
            code);
  EXPECT_EQ(code, 1);
  EXPECT_NE(out.find("--calibration"), std::string::npos) << out;
}

}  // namespace
}  // namespace sonoshape::igtl_source_test
