// IgtlServer against clients written with the OpenIGTLink library (Debian libopenigtlink 1.11):
// what Slicer's OpenIGTLinkIF would receive, GET_POLYDATA, several clients, vanishing and slow
// clients. All on loopback, on a port the system picks.
#include "sonoshape/publish/igtl_server.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "sonoshape/testing/igtl_client.hpp"

namespace sonoshape::publish::igtl_server_test {
namespace {

TriangleMesh tetrahedron(double size) {
  TriangleMesh mesh;
  mesh.vertices = {Vec3(0, 0, 0), Vec3(size, 0, 0), Vec3(0, size, 0), Vec3(0, 0, size)};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

MeshSet two_labels() {
  MeshSet meshes;
  meshes.meshes.push_back({1, "liver", tetrahedron(10.0)});
  meshes.meshes.push_back({2, "", tetrahedron(5.0)});
  return meshes;
}

using sonoshape::testing::IgtlClient;
using sonoshape::testing::Received;
using sonoshape::testing::triangles;
using Client = IgtlClient;

IgtlServer start_server(IgtlServerOptions options = {}) {
  options.port = 0;
  auto server = IgtlServer::start(options);
  if (!server) throw std::runtime_error(server.message());
  return std::move(*server);
}

TEST(IgtlServer, ANewClientGetsEverySurfaceTheImageWithItsPoseAndTheStatus) {
  IgtlServer server = start_server();
  ASSERT_GT(server.port(), 0);
  ASSERT_TRUE(server.publish_meshes(two_labels()));
  GreyImage image(4, 3);
  for (std::size_t k = 0; k < image.pixels.size(); ++k)
    image.pixels[k] = static_cast<std::uint8_t>(7 * k);
  // Pixels 0.5 mm wide and 0.25 mm high, turned 90 degrees about z, moved to (10, 20, 30).
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.block<3, 3>(0, 0) = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                        Eigen::Vector3d(0.5, 0.25, 1.0).asDiagonal();
  T.block<3, 1>(0, 3) = Eigen::Vector3d(10, 20, 30);
  ASSERT_TRUE(server.publish_image(image, T));
  StatusReport status;
  status.frames_received = 12;
  status.slices = 3;
  ASSERT_TRUE(server.publish_status(status));

  Client client(server.port());
  ASSERT_TRUE(client.connected());
  const Received liver = client.next(), second = client.next(), img = client.next(),
                 st = client.next();
  ASSERT_EQ(liver.type, "POLYDATA");
  EXPECT_EQ(liver.name, "liver");
  EXPECT_EQ(liver.polydata->GetPoints()->GetNumberOfPoints(), 4u);
  EXPECT_EQ(liver.polydata->GetPolygons()->GetNumberOfCells(), 4u);
  igtlFloat32 p[3];
  liver.polydata->GetPoints()->GetPoint(1, p);
  EXPECT_FLOAT_EQ(p[0], 10.0f);
  ASSERT_EQ(second.type, "POLYDATA");
  EXPECT_EQ(second.name, "label_2");  // a label without a name

  ASSERT_EQ(img.type, "IMAGE");
  EXPECT_EQ(img.name, "Image");
  int size[3];
  float spacing[3];
  img.image->GetDimensions(size);
  img.image->GetSpacing(spacing);
  EXPECT_EQ(size[0], 4);
  EXPECT_EQ(size[1], 3);
  EXPECT_EQ(size[2], 1);
  EXPECT_FLOAT_EQ(spacing[0], 0.5f);
  EXPECT_FLOAT_EQ(spacing[1], 0.25f);
  EXPECT_EQ(img.image->GetScalarType(), igtl::ImageMessage::TYPE_UINT8);
  igtl::Matrix4x4 m;
  img.image->GetMatrix(m);
  // Unit axes: i along +y, j along -x; the origin is the image centre (1.5, 1) px.
  EXPECT_NEAR(m[1][0], 1.0, 1e-6);
  EXPECT_NEAR(m[0][1], -1.0, 1e-6);
  EXPECT_NEAR(m[2][2], 1.0, 1e-6);
  EXPECT_NEAR(m[0][3], 10.0 - 0.25 * 1.0, 1e-5);
  EXPECT_NEAR(m[1][3], 20.0 + 0.5 * 1.5, 1e-5);
  EXPECT_NEAR(m[2][3], 30.0, 1e-5);
  const auto* pixels = static_cast<const std::uint8_t*>(img.image->GetScalarPointer());
  EXPECT_EQ(std::vector<std::uint8_t>(pixels, pixels + image.pixels.size()), image.pixels);

  ASSERT_EQ(st.type, "STATUS");
  EXPECT_EQ(st.name, "Scan");
  EXPECT_EQ(st.status->GetCode(), igtl::StatusMessage::STATUS_OK);
  EXPECT_STREQ(st.status->GetErrorName(), "scanning");
  EXPECT_NE(std::string(st.status->GetStatusString()).find("slices 3"), std::string::npos);
}

TEST(IgtlServer, AnswersGetPolyDataWithTheNamedSurfaceOrAllOfThem) {
  IgtlServer server = start_server();
  ASSERT_TRUE(server.publish_meshes(two_labels()));
  Client client(server.port());
  ASSERT_TRUE(client.connected());
  ASSERT_EQ(client.next().name, "liver");  // the state sent on connection
  ASSERT_EQ(client.next().name, "label_2");
  client.get_polydata("label_2");
  const Received one = client.next();
  EXPECT_EQ(one.type, "POLYDATA");
  EXPECT_EQ(one.name, "label_2");
  client.get_polydata("Client");  // names none: every surface
  EXPECT_EQ(client.next().name, "liver");
  EXPECT_EQ(client.next().name, "label_2");
  EXPECT_EQ(server.stats().requests_answered, 2u);
}

TEST(IgtlServer, TwoClientsReceiveUpdatesAndOneThatVanishesChangesNothing) {
  IgtlServer server = start_server();
  Client a(server.port()), b(server.port());
  ASSERT_TRUE(a.connected());
  ASSERT_TRUE(b.connected());
  for (int k = 0; k < 100 && server.stats().clients < 2; ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_EQ(server.stats().clients, 2u);
  a.close();
  MeshSet meshes = two_labels();
  for (int k = 0; k < 5; ++k) ASSERT_TRUE(server.publish_meshes(meshes));
  // A vanished label goes out as an empty surface.
  meshes.meshes.pop_back();
  ASSERT_TRUE(server.publish_meshes(meshes));
  Received last;
  for (int k = 0; k < 20; ++k) {
    const Received r = b.next();
    ASSERT_EQ(r.type, "POLYDATA");
    last = r;
    if (r.name == "label_2" && triangles(r) == 0) break;
  }
  EXPECT_EQ(last.name, "label_2");
  EXPECT_EQ(triangles(last), 0u);
  for (int k = 0; k < 100 && server.stats().clients > 1; ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(server.stats().clients, 1u);
  EXPECT_EQ(server.stats().clients_accepted, 2u);
}

TEST(IgtlServer, AClientThatDoesNotReadNeverBlocksPublishing) {
  IgtlServerOptions options;
  options.max_queued_messages = 4;
  options.linger_ms = 100;
  IgtlServer server = start_server(options);
  Client stalled(server.port());  // connects and never reads
  ASSERT_TRUE(stalled.connected());
  for (int k = 0; k < 100 && server.stats().clients < 1; ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const GreyImage image(512, 512, 100);
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  const auto start = std::chrono::steady_clock::now();
  StatusReport status;
  for (int k = 0; k < 300; ++k) {
    ASSERT_TRUE(server.publish_image(image, T));
    status.frames_received = static_cast<std::uint64_t>(k);
    ASSERT_TRUE(server.publish_status(status));
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // 300 images of 256 KiB are 75 MiB, far beyond the socket buffers: they were dropped, not waited
  // for.
  EXPECT_LT(seconds, 5.0);
  EXPECT_GT(server.stats().messages_dropped, 0u);
}

TEST(IgtlServer, RefusesBadInputWithoutSending) {
  IgtlServer server = start_server();
  MeshSet bad = two_labels();
  bad.meshes[0].mesh.triangles.push_back({0, 1, 9});
  const Status refused = server.publish_meshes(bad);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.message().find("liver"), std::string::npos);
  EXPECT_FALSE(server.publish_image(GreyImage(2, 2), Eigen::Matrix4d::Zero()));
  StatusReport error;
  error.state = ScanState::kError;
  EXPECT_FALSE(server.publish_status(error));
  EXPECT_EQ(server.stats().messages_sent, 0u);
}

TEST(IgtlServer, APortInUseIsReportedWithTheOptionAndAFix) {
  IgtlServer first = start_server();
  IgtlServerOptions options;
  options.port = first.port();
  const auto second = IgtlServer::start(options);
  ASSERT_FALSE(second);
  EXPECT_NE(second.message().find("--igtl-serve"), std::string::npos);
  EXPECT_NE(second.message().find(std::to_string(first.port())), std::string::npos);
  options.host = "localhost:1";
  EXPECT_FALSE(IgtlServer::start(options));
}

}  // namespace
}  // namespace sonoshape::publish::igtl_server_test
