#include "sonoshape/simulator/mesh_reader.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "test_shapes.hpp"

namespace sonoshape::sim {
namespace {

namespace fs = std::filesystem;

fs::path write_temp(const std::string& name, const std::string& content) {
  const fs::path dir = fs::temp_directory_path() / "sonoshape_mesh_reader_test";
  fs::create_directories(dir);
  const fs::path path = dir / name;
  std::ofstream(path, std::ios::binary) << content;
  return path;
}

template <typename T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

TEST(MeshReader, ObjWithSlashesNegativeIndicesAndQuads) {
  const fs::path path = write_temp("quad.obj",
                                   "# a comment\n"
                                   "o square\n"
                                   "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                   "vt 0 0\nvn 0 0 1\n"
                                   "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
                                   "v 0 0 1\r\n"
                                   "f -1//1 -5//1 -4//1\n");
  const auto mesh = read_mesh(path);
  ASSERT_TRUE(mesh) << mesh.message();
  EXPECT_EQ(mesh->vertices.size(), 5u);
  ASSERT_EQ(mesh->triangles.size(), 3u);  // the quad becomes a fan of two
  EXPECT_EQ(mesh->triangles[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(mesh->triangles[1], (std::array<std::uint32_t, 3>{0, 2, 3}));
  EXPECT_EQ(mesh->triangles[2], (std::array<std::uint32_t, 3>{4, 0, 1}));
}

TEST(MeshReader, ObjErrorsNameFileAndLine) {
  const fs::path path = write_temp("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 7\n");
  const auto mesh = read_mesh(path);
  ASSERT_FALSE(mesh);
  EXPECT_NE(mesh.message().find("bad.obj"), std::string::npos) << mesh.message();
  EXPECT_NE(mesh.message().find("line 5"), std::string::npos) << mesh.message();
  EXPECT_NE(mesh.message().find("out of range"), std::string::npos) << mesh.message();

  const auto coordinate = read_mesh(write_temp("coord.obj", "v 0 zero 0\n"));
  ASSERT_FALSE(coordinate);
  EXPECT_NE(coordinate.message().find("line 1"), std::string::npos);
}

TEST(MeshReader, AsciiPlyWithExtraProperties) {
  const fs::path path = write_temp("tet.ply",
                                   "ply\nformat ascii 1.0\ncomment made by hand\n"
                                   "element vertex 4\nproperty float x\nproperty float y\n"
                                   "property float z\nproperty uchar red\n"
                                   "element face 4\nproperty list uchar int vertex_indices\n"
                                   "property float quality\n"
                                   "end_header\n"
                                   "0 0 0 255\n1 0 0 0\n0 1 0 0\n0 0 1 9\n"
                                   "3 0 2 1 0.5\n3 0 1 3 0.5\n3 0 3 2 0.5\n3 1 2 3 0.5\n");
  const auto mesh = read_mesh(path);
  ASSERT_TRUE(mesh) << mesh.message();
  EXPECT_EQ(mesh->vertices.size(), 4u);
  EXPECT_EQ(mesh->triangles.size(), 4u);
  EXPECT_DOUBLE_EQ(mesh->vertices[3].z(), 1.0);
  EXPECT_GT(signed_volume(*mesh), 0.0);
  EXPECT_TRUE(check_mesh_health(*mesh).closed_manifold_oriented());
}

std::string binary_cube_ply(bool truncate) {
  const TriangleMesh cube = test::cube();
  std::string out =
      "ply\nformat binary_little_endian 1.0\n"
      "element vertex 8\nproperty double x\nproperty double y\nproperty double z\n"
      "property float nx\n"
      "element face 12\nproperty list uchar uint vertex_indices\n"
      "element edge 1\nproperty int vertex1\nproperty list uchar short extra\n"
      "end_header\n";
  for (const Vec3& p : cube.vertices) {
    for (int k = 0; k < 3; ++k) put<double>(out, p[k]);
    put<float>(out, 0.5f);
  }
  for (const auto& t : cube.triangles) {
    put<std::uint8_t>(out, 3);
    for (std::uint32_t i : t) put<std::uint32_t>(out, i);
  }
  put<std::int32_t>(out, 0);
  put<std::uint8_t>(out, 2);
  put<std::int16_t>(out, 1);
  put<std::int16_t>(out, 2);
  if (truncate) out.resize(out.size() - 30);
  return out;
}

TEST(MeshReader, BinaryPlyWithDoublesAndOtherElements) {
  const auto mesh = read_mesh(write_temp("cube.ply", binary_cube_ply(false)));
  ASSERT_TRUE(mesh) << mesh.message();
  EXPECT_EQ(mesh->vertices.size(), 8u);
  EXPECT_EQ(mesh->triangles.size(), 12u);
  EXPECT_NEAR(signed_volume(*mesh), 8.0, 1e-12);
  EXPECT_EQ(mesh->vertices, test::cube().vertices);
}

TEST(MeshReader, TruncatedBinaryPlyNamesTheElement) {
  const auto mesh = read_mesh(write_temp("short.ply", binary_cube_ply(true)));
  ASSERT_FALSE(mesh);
  EXPECT_NE(mesh.message().find("short.ply"), std::string::npos) << mesh.message();
  EXPECT_NE(mesh.message().find("face 10"), std::string::npos) << mesh.message();
  EXPECT_NE(mesh.message().find("ends early"), std::string::npos) << mesh.message();
}

TEST(MeshReader, BigEndianPlyIsRejectedClearly) {
  const auto mesh = read_mesh(
      write_temp("big.ply", "ply\nformat binary_big_endian 1.0\nelement vertex 0\nend_header\n"));
  ASSERT_FALSE(mesh);
  EXPECT_NE(mesh.message().find("binary_big_endian"), std::string::npos) << mesh.message();
}

TEST(MeshReader, OffWithCommentsAndPolygons) {
  const fs::path path = write_temp("pyramid.off",
                                   "OFF\n# square pyramid\n5 5 0\n"
                                   "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 0.5 1\n"
                                   "4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4 255 0 0\n");
  const auto mesh = read_mesh(path);
  ASSERT_TRUE(mesh) << mesh.message();
  EXPECT_EQ(mesh->triangles.size(), 6u);
  EXPECT_NEAR(signed_volume(*mesh), 1.0 / 3.0, 1e-12);
  EXPECT_TRUE(check_mesh_health(*mesh).closed_manifold_oriented());

  const auto bad = read_mesh(write_temp("bad.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"));
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("face 0"), std::string::npos) << bad.message();
}

TEST(MeshReader, FileErrors) {
  const auto missing = read_mesh("/nonexistent/dir/mesh.obj");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("/nonexistent/dir/mesh.obj"), std::string::npos);

  const auto format = read_mesh(write_temp("mesh.stl", "solid x\nendsolid x\n"));
  ASSERT_FALSE(format);
  EXPECT_NE(format.message().find(".stl"), std::string::npos);

  const auto empty = read_mesh(write_temp("points.obj", "v 0 0 0\n"));
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.message().find("no faces"), std::string::npos);
}

TEST(MeshReader, OrientOutwardFlipsInwardMeshesOnly) {
  TriangleMesh inward = test::flipped(test::cube());
  EXPECT_LT(signed_volume(inward), 0.0);
  orient_outward(inward);
  EXPECT_NEAR(signed_volume(inward), 8.0, 1e-12);
  TriangleMesh outward = test::cube();
  orient_outward(outward);
  EXPECT_EQ(outward.triangles, test::cube().triangles);
}

}  // namespace
}  // namespace sonoshape::sim
