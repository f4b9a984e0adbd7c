#include "sonoshape/acquisition/probe.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "sonoshape/core/errors.hpp"

namespace sonoshape::acquisition::probe_test {
namespace {

TEST(Probe, LinearPixelsMapToMillimetresLikeImageToProbe) {
  const Probe probe(linear_probe_geometry(200, 300));
  // The width decides the spacing here: 40 mm over 199 pixel steps (50 mm over 299 is less).
  EXPECT_DOUBLE_EQ(probe.spacing_mm(), 40.0 / 199.0);
  const Vec2 top_centre = probe.pixel_to_mm(99.5, 0.0);
  EXPECT_NEAR(top_centre.x(), 0.0, 1e-12);
  EXPECT_NEAR(top_centre.y(), 0.0, 1e-12);
  EXPECT_NEAR(probe.pixel_to_mm(0.0, 0.0).x(), -20.0, 1e-12);
  EXPECT_NEAR(probe.mm_to_pixel(Vec2(0.0, 50.0)).y(), 50.0 / probe.spacing_mm(), 1e-9);
  for (const Vec2& px : {Vec2(0, 0), Vec2(17.25, 3.5), Vec2(199, 299)}) {
    const Vec3 mm = probe.T_probe_image() * Vec3(px.x(), px.y(), 0.0);
    EXPECT_NEAR((mm.head<2>() - probe.pixel_to_mm(px.x(), px.y())).norm(), 0.0, 1e-12);
    EXPECT_NEAR(mm.z(), 0.0, 1e-12);
    EXPECT_NEAR((probe.mm_to_pixel(mm.head<2>()) - px).norm(), 0.0, 1e-9);
  }
  EXPECT_TRUE(probe.in_sector(Vec2(-19.9, 0.1)));
  EXPECT_FALSE(probe.in_sector(Vec2(-20.1, 10.0)));
  EXPECT_FALSE(probe.in_sector(Vec2(0.0, 50.1)));
  EXPECT_NEAR(signed_area(probe.sector_ring_mm()), 40.0 * 50.0, 1e-9);
}

TEST(Probe, ConvexSectorBeamsAndMask) {
  const Probe probe(convex_probe_geometry(256, 256));
  const double half = 30.0 * std::acos(-1.0) / 180.0;
  // The face's ends touch the top row; the deepest point of the central beam the bottom row.
  EXPECT_NEAR(probe.mm_to_pixel(Vec2(40.0 * std::sin(half), 40.0 * std::cos(half) - 40.0)).y(), 0.0,
              1e-9);
  EXPECT_LE(probe.mm_to_pixel(Vec2(0.0, 120.0)).y(), 255.0 + 1e-9);
  for (const Vec2& beam : {Vec2(0.0, 0.0), Vec2(100.5, 77.0), Vec2(255.0, 255.0)}) {
    const Vec2 mm = probe.beam_to_mm(beam.x(), beam.y());
    EXPECT_TRUE(probe.in_sector(mm));
    EXPECT_NEAR((probe.mm_to_beam(mm) - beam).norm(), 0.0, 1e-9);
  }
  EXPECT_FALSE(probe.in_sector(Vec2(0.0, -1.0)));   // above the face
  EXPECT_FALSE(probe.in_sector(Vec2(0.0, 120.5)));  // too deep
  EXPECT_FALSE(probe.in_sector(Vec2(70.0, 40.0)));  // outside the fan
  // Fan area: (fan / 2) (R_far^2 - R_near^2); the ring's arcs are polygons inside it.
  const double area = half * (160.0 * 160.0 - 40.0 * 40.0);
  EXPECT_NEAR(signed_area(probe.sector_ring_mm(512)), area, 1e-3 * area);
  const ImageU8 mask = probe.sector_mask();
  std::size_t inside = 0;
  for (const auto v : mask.pixels) inside += v ? 1 : 0;
  EXPECT_NEAR(inside * probe.spacing_mm() * probe.spacing_mm(), area, 0.01 * area);
  EXPECT_THROW(Probe(ProbeGeometry{ProbeType::kConvex, 100, 40, 200, 40, 64, 64, 3.5}),
               GeometryError);
}

TEST(Probe, GeometryRoundTripsThroughHeaderFields) {
  for (const ProbeGeometry& g :
       {linear_probe_geometry(320, 240), convex_probe_geometry(300, 400)}) {
    const Probe probe(g);
    const auto back = probe_from_fields(probe_fields(probe));
    ASSERT_TRUE(back) << back.message();
    EXPECT_TRUE(back->T_probe_image().isApprox(probe.T_probe_image(), 1e-15));
    EXPECT_EQ(back->sector_mask(), probe.sector_mask());
  }
  EXPECT_FALSE(probe_from_fields({{"SonoshapeProbeType", "convex"}}));
}

}  // namespace
}  // namespace sonoshape::acquisition::probe_test
