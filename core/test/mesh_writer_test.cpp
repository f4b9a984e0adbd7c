// Mesh files: each format is written and parsed back by the small readers below.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::mesh_writer_test {
namespace {

using sonoshape::testing::TempDir;

std::string read_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

// A tetrahedron with coordinates that are not exact in float.
TriangleMesh tetra() {
  TriangleMesh mesh;
  mesh.vertices = {Vec3(0.1, 0, 0), Vec3(1, 0, 0), Vec3(0, 1.0 / 3.0, 0), Vec3(0, 0, -2.5e3)};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

std::uint32_t le32(const std::string& bytes, std::size_t at) {
  std::uint32_t value = 0;
  for (int k = 3; k >= 0; --k)
    value = (value << 8) | static_cast<unsigned char>(bytes.at(at + static_cast<std::size_t>(k)));
  return value;
}

// Binary little-endian PLY with float x y z and uchar/int face lists, nothing else.
TriangleMesh parse_ply(const std::string& bytes) {
  const std::string end_marker = "end_header\n";
  const std::size_t header_end = bytes.find(end_marker);
  EXPECT_NE(header_end, std::string::npos);
  std::istringstream header(bytes.substr(0, header_end));
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(header, line)) lines.push_back(line);
  EXPECT_EQ(lines.at(0), "ply");
  EXPECT_EQ(lines.at(1), "format binary_little_endian 1.0");
  std::size_t vertices = 0, faces = 0;
  std::vector<std::string> properties;
  for (const std::string& l : lines) {
    std::istringstream words(l);
    std::string word, kind;
    words >> word;
    if (word == "element") {
      words >> kind;
      (kind == "vertex" ? vertices : faces) = std::stoul(l.substr(l.rfind(' ') + 1));
    } else if (word == "property") {
      properties.push_back(l);
    }
  }
  EXPECT_EQ(properties,
            (std::vector<std::string>{"property float x", "property float y", "property float z",
                                      "property list uchar int vertex_indices"}));
  TriangleMesh mesh;
  std::size_t at = header_end + end_marker.size();
  for (std::size_t k = 0; k < vertices; ++k) {
    Vec3 p;
    for (int c = 0; c < 3; ++c) {
      const std::uint32_t bits = le32(bytes, at);
      float value = 0;
      std::memcpy(&value, &bits, 4);
      p[c] = value;
      at += 4;
    }
    mesh.vertices.push_back(p);
  }
  for (std::size_t k = 0; k < faces; ++k) {
    EXPECT_EQ(static_cast<unsigned char>(bytes.at(at)), 3u);
    at += 1;
    std::array<std::uint32_t, 3> t{};
    for (auto& index : t) {
      index = le32(bytes, at);
      at += 4;
    }
    mesh.triangles.push_back(t);
  }
  EXPECT_EQ(at, bytes.size());
  return mesh;
}

TriangleMesh parse_obj(const std::string& text) {
  TriangleMesh mesh;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream words(line);
    std::string tag;
    words >> tag;
    if (tag == "v") {
      Vec3 p;
      words >> p.x() >> p.y() >> p.z();
      mesh.vertices.push_back(p);
    } else if (tag == "f") {
      std::array<std::uint32_t, 3> t{};
      words >> t[0] >> t[1] >> t[2];
      for (auto& index : t) index -= 1;
      mesh.triangles.push_back(t);
    }
  }
  return mesh;
}

TriangleMesh parse_off(const std::string& text) {
  std::istringstream in(text);
  std::string magic;
  std::size_t vertices = 0, faces = 0, edges = 0;
  in >> magic >> vertices >> faces >> edges;
  EXPECT_EQ(magic, "OFF");
  TriangleMesh mesh;
  for (std::size_t k = 0; k < vertices; ++k) {
    Vec3 p;
    in >> p.x() >> p.y() >> p.z();
    mesh.vertices.push_back(p);
  }
  for (std::size_t k = 0; k < faces; ++k) {
    int count = 0;
    std::array<std::uint32_t, 3> t{};
    in >> count >> t[0] >> t[1] >> t[2];
    EXPECT_EQ(count, 3);
    mesh.triangles.push_back(t);
  }
  EXPECT_TRUE(static_cast<bool>(in));
  return mesh;
}

void expect_same(const TriangleMesh& a, const TriangleMesh& b, double tol) {
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  for (std::size_t k = 0; k < a.vertices.size(); ++k)
    EXPECT_NEAR((a.vertices[k] - b.vertices[k]).norm(), 0.0, tol) << k;
  EXPECT_EQ(a.triangles, b.triangles);
}

TEST(MeshWriter, PlyRoundTrip) {
  TempDir dir;
  const auto path = dir.path() / "t.ply";
  ASSERT_TRUE(write_mesh(tetra(), path).is_ok());
  const TriangleMesh back = parse_ply(read_bytes(path));
  expect_same(tetra(), back, 1e-4);  // float precision
  EXPECT_EQ(static_cast<float>(back.vertices[2].y()), static_cast<float>(1.0 / 3.0));
}

TEST(MeshWriter, ObjRoundTripIsExact) {
  TempDir dir;
  const auto path = dir.path() / "t.obj";
  ASSERT_TRUE(write_mesh(tetra(), path).is_ok());
  expect_same(tetra(), parse_obj(read_bytes(path)), 0.0);
}

TEST(MeshWriter, OffRoundTripIsExact) {
  TempDir dir;
  const auto path = dir.path() / "t.OFF";  // extensions are case-insensitive
  ASSERT_TRUE(write_mesh(tetra(), path).is_ok());
  expect_same(tetra(), parse_off(read_bytes(path)), 0.0);
}

TEST(MeshWriter, EmptyMeshIsAValidFile) {
  TempDir dir;
  const auto path = dir.path() / "empty.ply";
  ASSERT_TRUE(write_mesh(TriangleMesh{}, path).is_ok());
  EXPECT_TRUE(parse_ply(read_bytes(path)).vertices.empty());
}

TEST(MeshWriter, UnknownExtensionNamesPathAndFormats) {
  TempDir dir;
  const auto path = dir.path() / "t.stl";
  const Status status = write_mesh(tetra(), path);
  ASSERT_FALSE(status.is_ok());
  EXPECT_NE(status.message().find(path.string()), std::string::npos) << status.message();
  EXPECT_NE(status.message().find(".ply, .obj or .off"), std::string::npos) << status.message();
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(MeshWriter, RefusesIndicesOutOfRange) {
  TempDir dir;
  TriangleMesh mesh = tetra();
  mesh.triangles.push_back({0, 1, 9});
  const Status status = write_mesh(mesh, dir.path() / "bad.obj");
  ASSERT_FALSE(status.is_ok());
  EXPECT_NE(status.message().find("triangle 4 uses vertex 9"), std::string::npos)
      << status.message();
}

TEST(MeshWriter, UnwritablePathNamesThePath) {
  TempDir dir;
  const auto path = dir.path() / "missing" / "t.ply";
  const Status status = write_mesh(tetra(), path);
  ASSERT_FALSE(status.is_ok());
  EXPECT_NE(status.message().find(path.string()), std::string::npos) << status.message();
}

MeshSet two_labels() {
  MeshSet set;
  set.meshes.push_back({1, "liver", tetra()});
  TriangleMesh moved = tetra();
  for (Vec3& p : moved.vertices) p += Vec3(5, 0, 0);
  set.meshes.push_back({3, "kidney", moved});
  return set;
}

TEST(MeshSetWriter, OneLabelToOneFile) {
  TempDir dir;
  MeshSet set;
  set.meshes.push_back({2, "x", tetra()});
  const auto path = dir.path() / "single.obj";
  const auto written = write_mesh_set(set, path);
  ASSERT_TRUE(written.is_ok()) << written.message();
  ASSERT_EQ(written->size(), 1u);
  EXPECT_EQ(written->front(), path);
  expect_same(tetra(), parse_obj(read_bytes(path)), 0.0);
}

TEST(MeshSetWriter, SeveralLabelsToADirectory) {
  TempDir dir;
  const auto out = dir.path() / "meshes" / "nested";
  const auto written = write_mesh_set(two_labels(), out);
  ASSERT_TRUE(written.is_ok()) << written.message();
  ASSERT_EQ(written->size(), 2u);
  EXPECT_EQ((*written)[0], out / "label_1.ply");
  EXPECT_EQ((*written)[1], out / "label_3.ply");
  const TriangleMesh second = parse_ply(read_bytes(out / "label_3.ply"));
  EXPECT_NEAR(second.vertices[1].x(), 6.0, 1e-6);
}

TEST(MeshSetWriter, OneLabelToADirectory) {
  TempDir dir;
  MeshSet set;
  set.meshes.push_back({4, "x", tetra()});
  const auto written = write_mesh_set(set, dir.path() / "out");
  ASSERT_TRUE(written.is_ok()) << written.message();
  EXPECT_EQ(written->front(), dir.path() / "out" / "label_4.ply");
  EXPECT_TRUE(std::filesystem::is_regular_file(written->front()));
}

TEST(MeshSetWriter, SeveralLabelsToOneFileIsAnError) {
  TempDir dir;
  const auto out = dir.path() / "both.ply";
  const auto written = write_mesh_set(two_labels(), out);
  ASSERT_FALSE(written.is_ok());
  EXPECT_NE(written.message().find("2 labels"), std::string::npos) << written.message();
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(MeshSetWriter, DirectoryBlockedByAFile) {
  TempDir dir;
  const auto out = dir.path() / "taken";
  std::ofstream(out) << "x";
  const auto written = write_mesh_set(two_labels(), out);
  ASSERT_FALSE(written.is_ok());
  EXPECT_NE(written.message().find(out.string()), std::string::npos) << written.message();
}

}  // namespace
}  // namespace sonoshape::mesh_writer_test
