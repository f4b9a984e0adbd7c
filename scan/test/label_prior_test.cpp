// The reconstruction as the segmentation's prior: meshes cut by a frame's plane, drawn into its
// pixels; and a prior built from slices of a sphere predicting the next frame.
#include "sonoshape/scan/label_prior.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "sonoshape/simulator/phantom.hpp"

namespace sonoshape::scan::label_prior_test {
namespace {

// A 100 x 80 image of 0.5 mm pixels whose plane is z = z_mm, pixel (i, j) at (i/2, j/2) mm.
segmentation::ImagePlane plane_at(double z_mm) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T(0, 0) = T(1, 1) = T(2, 2) = 0.5;
  T(2, 3) = z_mm;
  return segmentation::image_plane(T, Vec3(0, 0, z_mm));
}

MeshSet nested_spheres() {
  MeshSet set;
  TriangleMesh outer = simulator::make_sphere(15.0), inner = simulator::make_sphere(5.0);
  for (Vec3& p : outer.vertices) p += Vec3(25, 20, 0);
  for (Vec3& p : inner.vertices) p += Vec3(25, 20, 0);
  set.meshes.push_back({1, "organ", outer});
  set.meshes.push_back({2, "lesion", inner});
  return set;
}

TEST(PredictLabelMap, DrawsNestedSectionsWherePixelsAre) {
  const segmentation::ImageGeometry geometry = segmentation::full_image_geometry(100, 80, 0.5);
  const LabelImage map = predict_label_map(nested_spheres(), plane_at(0.0), geometry);
  EXPECT_EQ(map.at(50, 40), 2);       // (25, 20) mm: the lesion, drawn over the organ's hole
  EXPECT_EQ(map.at(50 + 20, 40), 1);  // 10 mm off the centre: the organ
  EXPECT_EQ(map.at(50 + 34, 40), 0);  // 17 mm off: outside both
  EXPECT_EQ(map.at(2, 2), 0);
  std::size_t organ = 0, lesion = 0;
  for (const std::uint8_t v : map.pixels) {
    organ += v == 1;
    lesion += v == 2;
  }
  // Areas in pixels of 0.25 mm^2: fillPoly also sets the pixels the outline touches, about half
  // a pixel all round (+12 % on the 5 mm lesion), a little more than the mesh loses inside.
  EXPECT_NEAR(lesion * 0.25, std::numbers::pi * 25.0, 0.15 * std::numbers::pi * 25.0);
  EXPECT_NEAR((organ + lesion) * 0.25, std::numbers::pi * 225.0, 0.06 * std::numbers::pi * 225.0);
  // Outside the sector nothing is predicted.
  segmentation::ImageGeometry half = geometry;
  for (int j = 0; j < 80; ++j)
    for (int i = 0; i < 50; ++i) half.sector.at(i, j) = 0;
  EXPECT_EQ(predict_label_map(nested_spheres(), plane_at(0.0), half).at(10, 10),
            kLabelPixelUnknown);
}

TEST(ReconstructionPrior, PredictsNothingFirstThenTheOrganBetweenItsSlices) {
  recon::ReconstructorOptions options;
  options.engine.max_depth = 5;
  options.bounds = Box3{Vec3(-10, -10, -30), Vec3(60, 50, 30)};
  ReconstructionPrior prior(options);
  const segmentation::ImageGeometry geometry = segmentation::full_image_geometry(100, 80, 0.5);
  EXPECT_FALSE(prior.predict(plane_at(0.0), geometry));
  // Two slices of a 15 mm disc-section organ at z = -4 and z = 4 mm.
  for (const double z : {-4.0, 4.0}) {
    LabeledSlice slice;
    slice.origin_mm = Vec3(0, 0, z);
    Region disc;
    for (int k = 0; k < 48; ++k) {
      const double a = 2.0 * std::numbers::pi * k / 48;
      disc.outer.emplace_back(25 + 14 * std::cos(a), 20 + 14 * std::sin(a));
    }
    slice.regions.push_back(disc);
    prior.add(slice);
  }
  const auto predicted = prior.predict(plane_at(0.0), geometry);
  ASSERT_TRUE(predicted);
  EXPECT_EQ(predicted->at(50, 40), 1);       // the organ's centre between its slices
  EXPECT_EQ(predicted->at(50 + 36, 40), 0);  // well outside it
}

}  // namespace
}  // namespace sonoshape::scan::label_prior_test
