// The arrangement must stay a consistent cell complex on generic and degenerate planes.
#include "arrangement.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>

#include "sonoshape/core/errors.hpp"

namespace sonoshape::recon::arrangement_test {
namespace {

// Volume of a cell from its faces (divergence theorem), oriented outwards from the cell.
double cell_volume(const Arrangement& arr, int cell) {
  double six_volume = 0.0;
  for (const int f : arr.cell(cell).faces) {
    const ArrangementFace& face = arr.face(f);
    const double orientation = face.cell_negative == cell ? 1.0 : -1.0;  // normal points out
    const Vec3& p0 = arr.vertex(face.vertices[0]);
    for (std::size_t i = 1; i + 1 < face.vertices.size(); ++i)
      six_volume += orientation *
                    p0.dot(arr.vertex(face.vertices[i]).cross(arr.vertex(face.vertices[i + 1])));
  }
  return six_volume / 6.0;
}

// Every cell is a closed polyhedron whose faces use each edge once in each direction when
// oriented outwards, and every face knows this cell.
void expect_consistent(const Arrangement& arr, const Box3& box) {
  double total = 0.0;
  for (int c = 0; c < static_cast<int>(arr.cell_count()); ++c) {
    std::map<std::pair<int, int>, int> edges;
    for (const int f : arr.cell(c).faces) {
      const ArrangementFace& face = arr.face(f);
      ASSERT_TRUE(face.cell_positive == c || face.cell_negative == c) << "face " << f;
      const bool outward_is_stored = face.cell_negative == c;
      const std::size_t n = face.vertices.size();
      ASSERT_GE(n, 3u);
      for (std::size_t i = 0; i < n; ++i) {
        int a = face.vertices[i], b = face.vertices[(i + 1) % n];
        if (!outward_is_stored) std::swap(a, b);
        ++edges[{a, b}];
        // Every vertex lies exactly on its face's plane and edges on their edge planes.
        EXPECT_EQ(arr.side(face.plane, a), 0);
        EXPECT_EQ(arr.side(face.edge_planes[i], face.vertices[i]), 0);
        EXPECT_EQ(arr.side(face.edge_planes[i], face.vertices[(i + 1) % n]), 0);
      }
    }
    for (const auto& [edge, count] : edges) {
      EXPECT_EQ(count, 1) << "cell " << c;
      const auto reverse = edges.find({edge.second, edge.first});
      EXPECT_TRUE(reverse != edges.end()) << "cell " << c << " is not closed";
    }
    const double volume = cell_volume(arr, c);
    EXPECT_GT(volume, 0.0) << "cell " << c;
    total += volume;
  }
  const Vec3 s = box.size();
  EXPECT_NEAR(total, s.x() * s.y() * s.z(), 1e-9 * s.x() * s.y() * s.z());
}

const Box3 kBox{Vec3(-1.0, -2.0, -1.5), Vec3(2.0, 1.0, 1.5)};

TEST(Arrangement, BoxAloneIsOneCell) {
  Arrangement arr(kBox);
  EXPECT_EQ(arr.cell_count(), 1u);
  EXPECT_EQ(arr.face_count(), 6u);
  expect_consistent(arr, kBox);
}

// Planes with random normals through random points well inside kBox.
struct RandomPlanes {
  explicit RandomPlanes(unsigned seed) : rng(seed) {}
  void insert_next(Arrangement& arr, int slice) {
    const Vec3 n(gauss(rng), gauss(rng), gauss(rng));
    const Vec3 p(uniform(rng), uniform(rng), uniform(rng));
    arr.insert_plane(n, -n.dot(p), slice);
  }
  std::mt19937_64 rng;
  std::normal_distribution<double> gauss;
  std::uniform_real_distribution<double> uniform{-0.8, 0.8};
};

TEST(Arrangement, RandomPlanesGiveClosedCellsFillingTheBox) {
  RandomPlanes planes(7);
  std::mt19937_64& rng = planes.rng;
  Arrangement arr(kBox);
  for (int i = 0; i < 12; ++i) planes.insert_next(arr, i);
  EXPECT_GT(arr.cell_count(), 100u);
  expect_consistent(arr, kBox);
  // Point location agrees with the exact cell sides.
  std::uniform_real_distribution<double> inside(0.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    const Vec3 p =
        kBox.min + (kBox.max - kBox.min).cwiseProduct(Vec3(inside(rng), inside(rng), inside(rng)));
    const int c = arr.locate(p);
    for (const int f : arr.cell(c).faces) {
      const ArrangementFace& face = arr.face(f);
      const double s = arr.plane(face.plane).signed_distance(p);
      EXPECT_GE(face.cell_positive == c ? s : -s, -1e-12);
    }
  }
}

TEST(Arrangement, LocateFromAGuessAgreesWithTheTree) {
  // Random planes, then axis-aligned ones through a grid of points (points on planes, on their
  // lines and at their crossings), then a sweep of nearly parallel ones (a deep tree).
  RandomPlanes planes(11);
  std::mt19937_64& rng = planes.rng;
  Arrangement arr(kBox);
  int slice = 0;
  for (int i = 0; i < 6; ++i) planes.insert_next(arr, slice++);
  for (const double x : {-0.5, 0.0, 0.5}) arr.insert_plane(Vec3(1, 0, 0), -x, slice++);
  for (const double y : {-1.0, 0.0}) arr.insert_plane(Vec3(0, 1, 0), -y, slice++);
  for (int i = 0; i < 8; ++i) arr.insert_plane(Vec3(0.01 * i, 0.02, 1), -(-1.2 + 0.3 * i), slice++);
  std::vector<Vec3> points;
  std::uniform_real_distribution<double> inside(0.0, 1.0);
  for (int k = 0; k < 300; ++k)
    points.push_back(
        kBox.min + (kBox.max - kBox.min).cwiseProduct(Vec3(inside(rng), inside(rng), inside(rng))));
  for (const double x : {-0.5, 0.0, 0.5, 0.25})
    for (const double y : {-1.0, 0.0, -0.5})
      for (const double z : {-1.2, -0.9, 0.0, 0.3, 0.7}) points.emplace_back(x, y, z);
  std::uniform_int_distribution<int> any_cell(-1, static_cast<int>(arr.cell_count()));
  int guessed = 0;
  for (const Vec3& p : points) {
    const int expected = arr.locate(p);
    EXPECT_EQ(arr.locate(p, expected), expected);
    for (int k = 0; k < 20; ++k) EXPECT_EQ(arr.locate(p, any_cell(rng)), expected);
    // Points on a plane: the guess across the plane must not be taken.
    for (const int f : arr.cell(expected).faces) {
      const ArrangementFace& face = arr.face(f);
      const int across = face.cell_positive == expected ? face.cell_negative : face.cell_positive;
      if (across < 0) continue;
      EXPECT_EQ(arr.locate(p, across), expected);
      ++guessed;
    }
  }
  EXPECT_GT(guessed, 1000);
}

TEST(Arrangement, ReportsTheFacesANewPlaneSplits) {
  // The online engine rebuilds the images of these faces only: every other older face must keep
  // its polygon (vertex ids and plane).
  RandomPlanes planes(11);
  Arrangement arr(kBox);
  for (int i = 0; i < 10; ++i) {
    std::vector<std::vector<int>> before;
    for (std::size_t f = 0; f < arr.face_count(); ++f)
      before.push_back(arr.face(static_cast<int>(f)).vertices);
    planes.insert_next(arr, i);
    const std::vector<int> split = arr.faces_split_by_last_plane();
    EXPECT_FALSE(split.empty());  // the plane passes through the box's interior
    for (std::size_t f = 0; f < before.size(); ++f) {
      const bool listed = std::find(split.begin(), split.end(), static_cast<int>(f)) != split.end();
      EXPECT_EQ(listed, arr.face(static_cast<int>(f)).vertices != before[f])
          << "plane " << i << ", face " << f;
    }
  }
}

TEST(Arrangement, ThreePlanesThroughOneLineAndFourThroughOnePoint) {
  Arrangement arr(kBox);
  // Three planes containing the z axis, then a fourth and fifth through the origin.
  arr.insert_plane(Vec3(1, 0, 0), 0.0, 0);
  arr.insert_plane(Vec3(0, 1, 0), 0.0, 1);
  arr.insert_plane(Vec3(1, 1, 0), 0.0, 2);
  arr.insert_plane(Vec3(0, 0, 1), 0.0, 3);
  arr.insert_plane(Vec3(1, -1, 1), 0.0, 4);
  expect_consistent(arr, kBox);
  EXPECT_EQ(arr.cell_count(),
            20u);  // 6 wedges, halved by z = 0, 8 of the 12 crossed by the last plane
}

TEST(Arrangement, NearlyParallelPlanesStayConsistent) {
  Arrangement arr(kBox);
  arr.insert_plane(Vec3(0, 0, 1), -0.1, 0);
  arr.insert_plane(Vec3(1e-13, 0, 1), -0.1, 1);  // meets the first inside the box? far away
  arr.insert_plane(Vec3(1e-9, 1e-9, 1), -0.1 + 1e-12, 2);
  arr.insert_plane(Vec3(0, 1e-15, 1), -0.1 - 1e-15, 3);
  expect_consistent(arr, kBox);
}

TEST(Arrangement, PlaneThroughExistingVerticesAndEdges) {
  Arrangement arr(kBox);
  arr.insert_plane(Vec3(1, 0, 0), 0.0, 0);
  arr.insert_plane(Vec3(0, 1, 0), 0.0, 1);
  // Through the box's corner diagonal and the line x = y = 0.
  arr.insert_plane(Vec3(1, -1, 0), 0.0, 2);
  // Through the box edge x = 2, y = 1 and the origin's line.
  arr.insert_plane(Vec3(1, -2, 0), 0.0, 3);
  expect_consistent(arr, kBox);
}

TEST(Arrangement, DuplicatePlaneIsRejected) {
  Arrangement arr(kBox);
  arr.insert_plane(Vec3(0, 0, 1), -0.5, 0);
  EXPECT_THROW(arr.insert_plane(Vec3(0, 0, -2), 1.0, 1), GeometryError);
  EXPECT_THROW(arr.insert_plane(Vec3(1, 0, 0), -2.0, 2), GeometryError);  // a box face
}

TEST(Arrangement, PlaneMissingTheBoxChangesNothing) {
  Arrangement arr(kBox);
  EXPECT_TRUE(arr.insert_plane(Vec3(0, 0, 1), -10.0, 0).empty());
  EXPECT_EQ(arr.cell_count(), 1u);
}

}  // namespace
}  // namespace sonoshape::recon::arrangement_test
