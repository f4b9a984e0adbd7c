// Face images: the slice's labelled regions clipped to its faces partition the regions exactly.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "cell_field.hpp"

namespace sonoshape::recon::face_images_test {
namespace {

double ring_area(const std::vector<Vec2>& points, std::uint32_t begin, std::uint32_t count) {
  return signed_area(Ring2(points.begin() + begin, points.begin() + begin + count));
}

// The bands give winding_number's answer from fewer edges: at random points, at the vertices,
// on the edges and just off them, for a long star-shaped ring, one with horizontal edges and a
// triangle (one band).
TEST(FaceImages, RingBandsGiveTheWindingNumberOfTheWholeRing) {
  std::vector<Ring2> rings(3);
  for (int k = 0; k < 400; ++k) {
    const double t = 2.0 * std::numbers::pi * k / 400;
    const double r = 30.0 + 12.0 * std::sin(7.0 * t) + 3.0 * std::cos(31.0 * t);
    rings[0].emplace_back(r * std::cos(t), r * std::sin(t));
  }
  for (int k = 0; k < 10; ++k) rings[1].emplace_back(2.0 * k, k % 2 ? 5.0 : 0.0);  // zigzag
  rings[1].emplace_back(18.0, -10.0);
  rings[1].emplace_back(0.0, -10.0);
  std::reverse(rings[1].begin(), rings[1].end());  // clockwise: a hole
  rings[2] = {Vec2(0, 0), Vec2(10, 0), Vec2(0, 10)};
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> uniform(-50.0, 50.0), unit(0.0, 1.0);
  int inside = 0;
  for (const Ring2& ring : rings) {
    const RingBands bands = make_ring_bands(ring);
    std::vector<Vec2> points;
    for (int k = 0; k < 4000; ++k) points.emplace_back(uniform(rng), uniform(rng));
    for (std::size_t i = 0; i < ring.size(); ++i) {
      const Vec2& a = ring[i];
      const Vec2& b = ring[(i + 1) % ring.size()];
      points.push_back(a);
      points.push_back(a + unit(rng) * (b - a));
      points.push_back(a + 0.5 * (b - a) + 1e-12 * Vec2(b.y() - a.y(), a.x() - b.x()));
    }
    for (const Vec2& p : points) {
      const int whole = winding_number(ring.data(), ring.size(), p);
      ASSERT_EQ(winding_number_in_bands(ring, bands, p), whole) << "at " << p.transpose();
      inside += whole != 0;
    }
    EXPECT_LT(bands.edges.size(), 4 * ring.size());
  }
  EXPECT_GT(inside, 1000);
}

TEST(FaceImages, ClippedPartsPartitionTheRegionsAndTheUnknownSet) {
  // A wavy region with a hole and an unknown patch on z = 0.1, cut by random planes.
  LabeledSlice slice;
  slice.origin_mm = Vec3(0, 0, 0.1);
  Ring2 outer, hole;
  for (int i = 0; i < 90; ++i) {
    const double t = 2.0 * std::numbers::pi * i / 90;
    outer.push_back((1.2 + 0.3 * std::sin(5 * t)) * Vec2(std::cos(t), std::sin(t)));
    hole.push_back(Vec2(0.2, 0.1) + 0.35 * Vec2(std::cos(-t), std::sin(-t)));
  }
  slice.regions.push_back({1, outer, {hole}});
  const Ring2 patch{Vec2(1.0, -0.2), Vec2(1.6, -0.2), Vec2(1.6, 0.3), Vec2(1.0, 0.3)};
  slice.regions.push_back({kUnknownLabel, patch, {}});
  SliceSet set;
  set.slices.push_back(slice);
  // Nine more slices without regions, at random orientations, cut the first into faces.
  std::mt19937_64 rng(4);
  std::normal_distribution<double> gauss;
  for (int i = 0; i < 9; ++i) {
    LabeledSlice empty;
    const Vec3 n = Vec3(gauss(rng), gauss(rng), gauss(rng)).normalized();
    empty.origin_mm = 0.4 * Vec3(gauss(rng), gauss(rng), gauss(rng));
    empty.u = n.unitOrthogonal();
    empty.v = n.cross(empty.u);
    set.slices.push_back(empty);
  }
  const Box3 box{Vec3::Constant(-2.0), Vec3::Constant(2.0)};
  set.bounds = box;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1}, box);
  Arrangement arrangement(box);
  for (std::size_t s = 0; s < prepared.size(); ++s) {
    const Vec3 n = prepared[s].u.cross(prepared[s].v);
    arrangement.insert_plane(n, -n.dot(prepared[s].origin), static_cast<int>(s));
  }
  const CellField field(arrangement, prepared, 1);
  // The material and unknown areas the partition must reproduce.
  double material_area = 0.0, unknown_area = 0.0;
  for (const Ring2& ring : prepared[0].rings_by_material[1]) material_area += signed_area(ring);
  for (const UnknownComponent& c : prepared[0].unknown)
    for (const Ring2& ring : c.rings) unknown_area += signed_area(ring);
  EXPECT_GT(material_area, 0.5 * signed_area(outer));
  double clipped_material = 0.0, clipped_unknown = 0.0, faces_area = 0.0, triangles_area = 0.0;
  int faces_on_slice = 0;
  for (std::size_t f = 0; f < arrangement.face_count(); ++f) {
    if (arrangement.plane(arrangement.face(static_cast<int>(f)).plane).slice != 0) continue;
    ++faces_on_slice;
    const FaceImage& image = field.face_image(static_cast<int>(f));
    faces_area += ring_area(field.points(), image.polygon_begin, image.polygon_count);
    for (const FaceImage::Part& part : image.parts)
      clipped_material += ring_area(field.points(), part.begin, part.count);
    for (const FaceImage::Part& part : image.unknown_parts)
      clipped_unknown += ring_area(field.points(), part.begin, part.count);
    for (std::uint32_t t = image.triangle_begin; t < image.triangle_begin + image.triangle_count;
         ++t) {
      const UnknownTriangle& tri = field.unknown_triangles()[t];
      triangles_area += signed_area(Ring2{tri.corners[0], tri.corners[1], tri.corners[2]});
    }
  }
  EXPECT_GT(faces_on_slice, 5);
  EXPECT_NEAR(faces_area, 16.0, 1e-9);  // the faces tile the plane inside the 4 x 4 box
  EXPECT_NEAR(clipped_material, material_area, 1e-9);
  EXPECT_NEAR(clipped_unknown, unknown_area, 1e-9);
  EXPECT_NEAR(triangles_area, unknown_area, 1e-9);  // the triangulation covers the unknown set
}

}  // namespace
}  // namespace sonoshape::recon::face_images_test
