// The dispatcher of mesh_io.hpp: every format it writes reads back through read_mesh, the
// extension picks the format in any case, and InputError (errors.hpp) carries the messages of
// every reader.
#include "sonoshape/core/mesh_io.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::mesh_io_test {
namespace {

using testing::contains;
using testing::TempDir;

// A tetrahedron whose coordinates are exact in float (PLY stores floats).
TriangleMesh tetra() {
  TriangleMesh mesh;
  mesh.vertices = {Vec3(0.5, 0, 0), Vec3(1, 0, 0), Vec3(0, 0.25, 0), Vec3(0, 0, -2.5e3)};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

TEST(MeshIo, EveryWrittenFormatReadsBackThroughTheDispatcher) {
  const TempDir dir;
  for (const char* name : {"a.ply", "a.obj", "a.off", "A.PLY", "A.Obj", "A.OFF"}) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(write_mesh(tetra(), dir.path() / name));
    const Result<TriangleMesh> back = read_mesh(dir.path() / name);
    ASSERT_TRUE(back) << back.message();
    EXPECT_EQ(back->vertices, tetra().vertices);
    EXPECT_EQ(back->triangles, tetra().triangles);
  }
}

TEST(MeshIo, StlIsReadOnlyAndOtherExtensionsAreNamed) {
  const TempDir dir;
  const Status stl = write_mesh(tetra(), dir.path() / "a.stl");
  ASSERT_FALSE(stl);
  EXPECT_TRUE(contains(stl.message(), "unknown mesh format \".stl\"")) << stl.message();
  EXPECT_TRUE(contains(stl.message(), ".ply, .obj or .off")) << stl.message();
  std::ofstream(dir.path() / "a.xyz") << "v 0 0 0\n";
  const Result<TriangleMesh> xyz = read_mesh(dir.path() / "a.xyz");
  ASSERT_FALSE(xyz);
  EXPECT_TRUE(
      contains(xyz.message(), "unsupported extension '.xyz' (use .obj, .ply, .off or .stl)"))
      << xyz.message();
}

TEST(InputError, JoinsTheKnownPartsAndAddsTheFileOnce) {
  const InputError at_line("line 3", "a vertex needs x y z");
  EXPECT_STREQ(at_line.what(), "line 3: a vertex needs x y z");
  EXPECT_EQ(at_line.element(), "line 3");
  EXPECT_EQ(at_line.problem(), "a vertex needs x y z");
  EXPECT_EQ(at_line.message_in("mesh file a.obj"), "mesh file a.obj: line 3: a vertex needs x y z");
  const InputError whole_file("", "the file is empty");
  EXPECT_STREQ(whole_file.what(), "the file is empty");
  EXPECT_EQ(whole_file.message_in("a.stl"), "a.stl: the file is empty");
  // An error that names its own file keeps it (a repair refused under --strict).
  const InputError named("b.csl", "plane 2", "needs a repair");
  EXPECT_EQ(named.file(), "b.csl");
  EXPECT_EQ(named.message_in("other"), "b.csl: plane 2: needs a repair");
  const Error& base = named;  // caught as every sonoshape error
  EXPECT_STREQ(base.what(), "b.csl: plane 2: needs a repair");
}

}  // namespace
}  // namespace sonoshape::mesh_io_test
