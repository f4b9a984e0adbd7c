#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <string>

#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/testing/cube.hpp"

namespace sonoshape::mesh_reader_test {
namespace {

namespace fs = std::filesystem;

// The same mesh with every triangle reversed (inward-facing).
TriangleMesh flipped(TriangleMesh mesh) {
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  return mesh;
}

fs::path write_temp(const std::string& name, const std::string& content) {
  const fs::path dir =
      fs::temp_directory_path() / ("sonoshape_mesh_reader_test_" + std::to_string(::getpid()));
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
  const TriangleMesh cube = testing::cube();
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
  EXPECT_EQ(mesh->vertices, testing::cube().vertices);
}

TEST(MeshReader, TruncatedBinaryPlyNamesTheElement) {
  const auto mesh = read_mesh(write_temp("short.ply", binary_cube_ply(true)));
  ASSERT_FALSE(mesh);
  EXPECT_NE(mesh.message().find("short.ply"), std::string::npos) << mesh.message();
  EXPECT_NE(mesh.message().find("face 10"), std::string::npos) << mesh.message();
  EXPECT_NE(mesh.message().find("ends early"), std::string::npos) << mesh.message();
}

// Found by fuzzing (tests/data/fuzz/mesh/): a header whose last line had no newline read past
// the end of the text and ended the program with std::out_of_range.
TEST(MeshReader, PlyHeaderEndingWithoutNewlineReadsOrFailsClearly) {
  const auto empty =
      read_mesh(write_temp("end.ply",
                           "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                           "property float y\nproperty float z\nend_header"),
                true);
  ASSERT_TRUE(empty) << empty.message();
  EXPECT_EQ(empty->vertices.size(), 0u);
  const auto cut = read_mesh(
      write_temp("cut.ply",
                 "ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty float x\n"
                 "property float y\nproperty float z\nend_header"));
  ASSERT_FALSE(cut);
  EXPECT_NE(cut.message().find("cut.ply"), std::string::npos) << cut.message();
  EXPECT_NE(cut.message().find("ends early"), std::string::npos) << cut.message();
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

  const auto format = read_mesh(write_temp("mesh.3ds", "MM"));
  ASSERT_FALSE(format);
  EXPECT_NE(format.message().find(".3ds"), std::string::npos);
  EXPECT_NE(format.message().find(".stl"), std::string::npos) << format.message();

  const auto empty = read_mesh(write_temp("points.obj", "v 0 0 0\n"));
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.message().find("no faces"), std::string::npos);
}

// ---- STL ----------------------------------------------------------------------------------

// Each triangle with its own three corners, as STL stores them.
std::string ascii_stl(const TriangleMesh& mesh) {
  std::string out = "solid cube\n";
  for (const auto& t : mesh.triangles) {
    out += "  facet normal 0 0 0\n    outer loop\n";
    for (std::uint32_t i : t) {
      const Vec3& p = mesh.vertices[i];
      out += "      vertex " + std::to_string(p.x()) + " " + std::to_string(p.y()) + " " +
             std::to_string(p.z()) + "\n";
    }
    out += "    endloop\n  endfacet\n";
  }
  return out + "endsolid cube\n";
}

std::string binary_stl(const TriangleMesh& mesh, const std::string& header) {
  std::string out = header;
  out.resize(80, ' ');
  put<std::uint32_t>(out, static_cast<std::uint32_t>(mesh.triangles.size()));
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) put<float>(out, 0.0f);
    for (std::uint32_t i : t)
      for (int k = 0; k < 3; ++k) put<float>(out, static_cast<float>(mesh.vertices[i][k]));
    put<std::uint16_t>(out, 0);
  }
  return out;
}

std::string obj_text(const TriangleMesh& mesh) {
  std::string out;
  for (const Vec3& p : mesh.vertices)
    out += "v " + std::to_string(p.x()) + " " + std::to_string(p.y()) + " " +
           std::to_string(p.z()) + "\n";
  for (const auto& t : mesh.triangles)
    out += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " +
           std::to_string(t[2] + 1) + "\n";
  return out;
}

// V - E + F over the mesh's vertex indices.
long long euler_characteristic(const TriangleMesh& mesh) {
  std::set<std::pair<std::uint32_t, std::uint32_t>> edges;
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) edges.insert(std::minmax(t[k], t[(k + 1) % 3]));
  return static_cast<long long>(mesh.vertices.size()) - static_cast<long long>(edges.size()) +
         static_cast<long long>(mesh.triangles.size());
}

void expect_same_closed_mesh(const TriangleMesh& stl, const TriangleMesh& obj) {
  EXPECT_EQ(stl.vertices.size(), obj.vertices.size());
  EXPECT_EQ(stl.triangles.size(), obj.triangles.size());
  EXPECT_NEAR(signed_volume(stl), signed_volume(obj), 1e-9);
  EXPECT_EQ(euler_characteristic(stl), 2);
  EXPECT_TRUE(check_mesh_health(stl).closed_manifold_oriented());
}

TEST(MeshReader, AsciiAndBinaryStlWeldToTheObjMesh) {
  // A tetrahedron and a cube off-origin (non-integer coordinates survive the float round trip).
  TriangleMesh tetra;
  tetra.vertices = {{0.5, 0.25, 0.0}, {2.0, 0.25, 0.0}, {0.5, 1.75, 0.0}, {0.5, 0.25, 1.5}};
  tetra.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  for (const auto& [name, shape] :
       {std::pair<std::string, TriangleMesh>{"tetra", tetra},
        {"cube", testing::cube(Vec3(0.5, -1.25, 2.0), Vec3(3.0, 0.75, 4.5))}}) {
    SCOPED_TRACE(name);
    const auto obj = read_mesh(write_temp(name + ".obj", obj_text(shape)));
    ASSERT_TRUE(obj) << obj.message();
    EXPECT_TRUE(check_mesh_health(*obj).closed_manifold_oriented());
    const auto ascii = read_mesh(write_temp(name + "_ascii.stl", ascii_stl(shape)));
    ASSERT_TRUE(ascii) << ascii.message();
    expect_same_closed_mesh(*ascii, *obj);
    const auto binary = read_mesh(write_temp(name + "_binary.STL", binary_stl(shape, "made")));
    ASSERT_TRUE(binary) << binary.message();
    expect_same_closed_mesh(*binary, *obj);
  }
  EXPECT_NEAR(signed_volume(*read_mesh(write_temp("tetra_ascii.stl", ascii_stl(tetra)))),
              1.5 * 1.5 * 1.5 / 6.0, 1e-12);
}

TEST(MeshReader, BinaryStlWhoseHeaderStartsWithSolidIsBinary) {
  const std::string data = binary_stl(testing::cube(), "solid cube exported by a CAD tool");
  ASSERT_EQ(data.substr(0, 5), "solid");
  const auto mesh = read_mesh(write_temp("solid_binary.stl", data));
  ASSERT_TRUE(mesh) << mesh.message();
  EXPECT_EQ(mesh->vertices.size(), 8u);
  EXPECT_NEAR(signed_volume(*mesh), 8.0, 1e-12);
  EXPECT_TRUE(check_mesh_health(*mesh).closed_manifold_oriented());
}

TEST(MeshReader, StlErrorsNameFileFacetAndFix) {
  // Truncated binary, with and without a "solid" header: the declared count and the cut facet.
  for (const std::string& header : {std::string("binary"), std::string("solid x")}) {
    std::string data = binary_stl(testing::cube(), header);
    data.resize(data.size() - 70);
    const auto cut = read_mesh(write_temp("cut.stl", data));
    ASSERT_FALSE(cut);
    EXPECT_NE(cut.message().find("cut.stl"), std::string::npos) << cut.message();
    EXPECT_NE(cut.message().find("declares 12 facets"), std::string::npos) << cut.message();
    EXPECT_NE(cut.message().find("facet 10"), std::string::npos) << cut.message();
    EXPECT_NE(cut.message().find("re-export"), std::string::npos) << cut.message();
  }
  const auto tiny = read_mesh(write_temp("tiny.stl", std::string("\x01\x02", 2)));
  ASSERT_FALSE(tiny);
  EXPECT_NE(tiny.message().find("84-byte header"), std::string::npos) << tiny.message();

  std::string ascii = ascii_stl(testing::cube());
  ascii.replace(ascii.find("endloop", ascii.find("endloop") + 1), 7, "endlop");
  const auto keyword = read_mesh(write_temp("keyword.stl", ascii));
  ASSERT_FALSE(keyword);
  EXPECT_NE(keyword.message().find("facet 1"), std::string::npos) << keyword.message();
  EXPECT_NE(keyword.message().find("'endlop'"), std::string::npos) << keyword.message();
  EXPECT_NE(keyword.message().find("line 14"), std::string::npos) << keyword.message();

  std::string nan_text = ascii_stl(testing::cube());
  const std::size_t x_at = nan_text.find("vertex ") + 7;
  nan_text.replace(x_at, nan_text.find(' ', x_at) - x_at, "nan");
  const auto nan_ascii = read_mesh(write_temp("nan.stl", nan_text));
  ASSERT_FALSE(nan_ascii);
  EXPECT_NE(nan_ascii.message().find("facet 0"), std::string::npos) << nan_ascii.message();
  EXPECT_NE(nan_ascii.message().find("'nan'"), std::string::npos) << nan_ascii.message();

  TriangleMesh with_nan = testing::cube();
  with_nan.vertices.push_back(Vec3(0.0, std::numeric_limits<double>::quiet_NaN(), 0.0));
  with_nan.triangles[5][1] = static_cast<std::uint32_t>(with_nan.vertices.size() - 1);
  const auto nan_binary = read_mesh(write_temp("nan_binary.stl", binary_stl(with_nan, "b")));
  ASSERT_FALSE(nan_binary);
  EXPECT_NE(nan_binary.message().find("facet 5, corner 1"), std::string::npos)
      << nan_binary.message();

  const auto no_facets = read_mesh(write_temp("empty.stl", "solid x\nendsolid x\n"));
  ASSERT_FALSE(no_facets);
  EXPECT_NE(no_facets.message().find("no faces"), std::string::npos) << no_facets.message();
  const auto unterminated = read_mesh(write_temp("open.stl", "solid x\n facet normal 0 0 1\n"));
  ASSERT_FALSE(unterminated);
  EXPECT_NE(unterminated.message().find("truncated"), std::string::npos) << unterminated.message();
}

TEST(MeshReader, OrientOutwardFlipsInwardMeshesOnly) {
  TriangleMesh inward = flipped(testing::cube());
  EXPECT_LT(signed_volume(inward), 0.0);
  orient_outward(inward);
  EXPECT_NEAR(signed_volume(inward), 8.0, 1e-12);
  TriangleMesh outward = testing::cube();
  orient_outward(outward);
  EXPECT_EQ(outward.triangles, testing::cube().triangles);
}

}  // namespace
}  // namespace sonoshape::mesh_reader_test
