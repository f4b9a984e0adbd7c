// Slice-set JSON: parsing, every error of docs/formats/slices.md, warnings, writing.
#include "sonoshape/core/slice_io.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::slice_io_test {
namespace {

using sonoshape::testing::contains;

using sonoshape::testing::TempDir;

// The example of slices.md.
const char* kSpecExample = R"({
  "format": "sonoshape-slices",
  "version": 1,
  "units": "mm",
  "labels": [ {"id": 1, "name": "liver"}, {"id": 2, "name": "kidney"},
              {"id": 3, "name": "rib", "casts_shadow": true} ],
  "bounds": { "min": [-90, -80, -70], "max": [90, 80, 70] },
  "slices": [
    {
      "origin": [0.0, 0.0, 12.5],
      "u": [1, 0, 0],
      "v": [0, 1, 0],
      "timestamp": 0.033,
      "fov": [[-40, 0], [40, 0], [40, 60], [-40, 60]],
      "regions": [
        { "label": 1, "polygon": [[-10, 5], [12, 5], [12, 30], [-10, 30]],
          "holes": [ [[0, 10], [4, 10], [4, 14], [0, 14]] ] },
        { "label": "unknown", "polygon": [[20, 40], [30, 40], [25, 50]] }
      ]
    }
  ]
})";

// A document with the given slices (JSON text of the array's contents) and extra top-level keys.
std::string doc(const std::string& slices, const std::string& extra = "") {
  return R"({"format": "sonoshape-slices", "version": 1, )" + extra + R"("slices": [)" + slices +
         "]}";
}

// One axis-aligned slice at height z with the given regions (JSON text).
std::string slice_at(double z, const std::string& regions) {
  return R"({"origin": [0, 0, )" + std::to_string(z) +
         R"(], "u": [1, 0, 0], "v": [0, 1, 0], "regions": [)" + regions + "]}";
}

std::string square_region(int label, double x0, double y0, double size) {
  auto n = [](double x) { return std::to_string(x); };
  return R"({"label": )" + std::to_string(label) + R"(, "polygon": [[)" + n(x0) + "," + n(y0) +
         "],[" + n(x0 + size) + "," + n(y0) + "],[" + n(x0 + size) + "," + n(y0 + size) + "],[" +
         n(x0) + "," + n(y0 + size) + "]]}";
}

Result<SliceSet> parse(const std::string& text) {
  return parse_slice_set_json(text, "t.slices.json");
}

// Parses text that must fail and returns the message (which must name the file).
std::string parse_error(const std::string& text) {
  const Result<SliceSet> result = parse(text);
  EXPECT_FALSE(result.is_ok());
  if (result.is_ok()) return {};
  EXPECT_TRUE(contains(result.message(), "t.slices.json"));
  return result.message();
}

TEST(SliceJson, ParsesTheSpecExample) {
  const Result<SliceSet> result = parse(kSpecExample);
  ASSERT_TRUE(result.is_ok()) << result.message();
  const SliceSet& set = *result;
  EXPECT_EQ(set.units, "mm");
  ASSERT_EQ(set.labels.size(), 3u);
  EXPECT_EQ(set.labels[1].id, 2);
  EXPECT_EQ(set.labels[1].name, "kidney");
  EXPECT_FALSE(set.labels[1].casts_shadow);
  EXPECT_TRUE(set.labels[2].casts_shadow);
  ASSERT_TRUE(set.bounds.has_value());
  EXPECT_EQ(set.bounds->min, Vec3(-90, -80, -70));
  EXPECT_EQ(set.bounds->max, Vec3(90, 80, 70));
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  EXPECT_EQ(s.origin_mm, Vec3(0, 0, 12.5));
  EXPECT_EQ(s.normal(), Vec3::UnitZ());
  ASSERT_TRUE(s.timestamp_s.has_value());
  EXPECT_DOUBLE_EQ(*s.timestamp_s, 0.033);
  ASSERT_TRUE(s.fov.has_value());
  EXPECT_EQ(s.fov->size(), 4u);
  ASSERT_EQ(s.regions.size(), 2u);
  EXPECT_EQ(s.regions[0].label, 1);
  EXPECT_EQ(s.regions[0].outer.size(), 4u);
  ASSERT_EQ(s.regions[0].holes.size(), 1u);
  EXPECT_EQ(s.regions[0].holes[0][2], Vec2(4, 14));
  EXPECT_EQ(s.regions[1].label, kUnknownLabel);
  EXPECT_TRUE(s.regions[1].holes.empty());
}

TEST(SliceJson, OptionalFieldsDefault) {
  const Result<SliceSet> result = parse(doc(slice_at(0, square_region(1, 0, 0, 1))));
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->units, "mm");
  EXPECT_TRUE(result->labels.empty());
  EXPECT_FALSE(result->bounds.has_value());
  EXPECT_FALSE(result->slices[0].timestamp_s.has_value());
  EXPECT_FALSE(result->slices[0].fov.has_value());
  EXPECT_EQ(result->slices[0].outline_sd_mm, 0.0);  // exact outlines
}

TEST(SliceJson, TheOutlinesErrorIsReadAndANegativeOneRefused) {
  const std::string with_error = R"({"origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], )"
                                 R"("outline_sd_mm": 0.6, "regions": [)" +
                                 square_region(1, 0, 0, 1) + "]}";
  const Result<SliceSet> result = parse(doc(with_error));
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->slices[0].outline_sd_mm, 0.6);
  std::string negative = with_error;
  negative.replace(negative.find("0.6"), 3, "-0.6");
  const std::string message = parse_error(doc(negative));
  EXPECT_TRUE(contains(message, "slice 0, outline_sd_mm: a negative standard deviation"))
      << message;
  std::string text = with_error;
  text.replace(text.find("0.6"), 3, "\"big\"");
  EXPECT_TRUE(contains(parse_error(doc(text)), "slice 0, outline_sd_mm: expected a number"));
}

TEST(SliceJsonErrors, NotJsonReportsThePosition) {
  const std::string message =
      parse_error("{\"format\": \"sonoshape-slices\",\n  \"version\": 1,\n  oops }");
  EXPECT_TRUE(contains(message, "not valid JSON"));
  EXPECT_TRUE(contains(message, "line 3"));
}

// Issue 27: a file in metres or furlongs read as millimetres gave a surface 1000 times off, and
// bounds of +-1e308 an empty mesh, both with exit 0. Now errors naming the field and the fix.
TEST(SliceJsonErrors, UnitsOtherThanMillimetresAreRefused) {
  for (const std::string units : {"m", "cm", "furlongs", "MM"}) {
    const Result<SliceSet> set =
        parse(R"({"format": "sonoshape-slices", "version": 1, "units": ")" + units +
              R"(", "slices": []})");
    ASSERT_FALSE(set.is_ok()) << units;
    EXPECT_TRUE(contains(set.message(), "units")) << set.message();
    EXPECT_TRUE(contains(set.message(), "\"units\": \"mm\"")) << set.message();
  }
  EXPECT_TRUE(parse(R"({"format": "sonoshape-slices", "version": 1, "units": "mm", "slices": []})")
                  .is_ok());
}

TEST(SliceJsonErrors, BoundsFarLargerThanTheRegionsAreRefused) {
  auto with_bounds = [](double half) {
    std::ostringstream text;
    text.precision(17);
    text << R"({"format": "sonoshape-slices", "version": 1, "bounds": {"min": [)" << -half << ","
         << -half << "," << -half << R"(], "max": [)" << half << "," << half << "," << half
         << R"(]}, "slices": [{"origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], "regions": [)"
         << R"({"label": 1, "polygon": [[-5, -5], [5, -5], [5, 5], [-5, 5]]}]}]})";
    return parse(text.str());
  };
  const Result<SliceSet> huge = with_bounds(1e308);
  ASSERT_FALSE(huge.is_ok());
  EXPECT_TRUE(contains(huge.message(), "t.slices.json: bounds:")) << huge.message();
  EXPECT_TRUE(contains(huge.message(), "leave bounds out")) << huge.message();
  // 1000 times the regions' extent (10) is the limit: 5000 either side fails, 4000 passes.
  EXPECT_FALSE(with_bounds(5001.0).is_ok());
  EXPECT_TRUE(with_bounds(4000.0).is_ok()) << with_bounds(4000.0).message();
}

TEST(SliceJsonErrors, WrongFormat) {
  const std::string message =
      parse_error(R"({"format": "something-else", "version": 1, "slices": []})");
  EXPECT_TRUE(contains(message, "\"format\""));
  EXPECT_TRUE(contains(message, "sonoshape-slices"));
  EXPECT_TRUE(contains(parse_error(R"([1, 2, 3])"), "not a slice set"));
}

TEST(SliceJsonErrors, UnknownVersion) {
  const std::string message =
      parse_error(R"({"format": "sonoshape-slices", "version": 2, "slices": []})");
  EXPECT_TRUE(contains(message, "unknown version 2"));
  EXPECT_TRUE(contains(parse_error(R"({"format": "sonoshape-slices", "slices": []})"),
                       "\"version\" is missing"));
}

TEST(SliceJsonErrors, BasisNotUnit) {
  const std::string slice = R"({"origin": [0,0,0], "u": [2,0,0], "v": [0,1,0], "regions": [)" +
                            square_region(1, 0, 0, 1) + "]}";
  const std::string message = parse_error(doc(slice_at(0, "") + "," + slice));
  EXPECT_TRUE(contains(message, "slice 1: u is not unit length"));
  EXPECT_TRUE(contains(message, "\"normalize\": true"));
}

TEST(SliceJsonErrors, BasisNotOrthogonal) {
  const std::string slice =
      R"({"origin": [0,0,0], "u": [1,0,0], "v": [0.01,0.99995,0], "regions": []})";
  EXPECT_TRUE(contains(parse_error(doc(slice)), "slice 0: u and v are not orthogonal"));
}

TEST(SliceJson, NormalizeFixesTheBasis) {
  const std::string slice = R"({"origin": [0,0,0], "u": [2,0,0], "v": [1,3,0], "regions": [)" +
                            square_region(1, 0, 0, 1) + "]}";
  const Result<SliceSet> result = parse(doc(slice, R"("normalize": true, )"));
  ASSERT_TRUE(result.is_ok()) << result.message();
  const LabeledSlice& s = result->slices[0];
  EXPECT_NEAR((s.u - Vec3::UnitX()).norm(), 0.0, 1e-15);
  EXPECT_NEAR((s.v - Vec3::UnitY()).norm(), 0.0, 1e-15);
}

TEST(SliceJsonErrors, NormalizeStillRejectsADegenerateBasis) {
  const std::string slice = R"({"origin": [0,0,0], "u": [1,0,0], "v": [3,0,0], "regions": []})";
  EXPECT_TRUE(contains(parse_error(doc(slice, R"("normalize": true, )")),
                       "slice 0: u and v do not span a plane"));
}

TEST(SliceJsonErrors, FewerThanThreeDistinctPoints) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[1,0],[0,0],[1,0]]})";
  const std::string message =
      parse_error(doc(slice_at(0, square_region(1, 5, 5, 1)) + "," +
                      slice_at(1, square_region(1, 5, 5, 1) + "," + region)));
  EXPECT_TRUE(contains(
      message,
      "slice 1, region 1 (label 1), outer ring: polygon has fewer than 3 distinct points"));
}

double region_area(const Region& r) {
  double area = std::abs(signed_area(r.outer));
  for (const Ring2& hole : r.holes) area -= std::abs(signed_area(hole));
  return area;
}

// Reads a document that must read, returning the set and what went to stderr.
std::pair<SliceSet, std::string> parse_with_warnings(const std::string& text) {
  ::testing::internal::CaptureStderr();
  const Result<SliceSet> result = parse(text);
  const std::string warnings = ::testing::internal::GetCapturedStderr();
  EXPECT_TRUE(result.is_ok()) << result.message();
  return {result.is_ok() ? *result : SliceSet{}, warnings};
}

TEST(SliceJsonRepairs, BowTieBecomesTheTwoTrianglesItEncloses) {
  // Edge 0 (0,0)-(2,2) crosses edge 2 (2,0)-(0,2); region 1 after it keeps its index.
  const std::string bow_tie = R"({"label": 2, "polygon": [[0,0],[2,2],[2,0],[0,2]]})";
  const auto [set, warnings] =
      parse_with_warnings(doc(slice_at(0, bow_tie + "," + square_region(1, 5, 5, 1))));
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 3u);
  EXPECT_EQ(s.regions[0].label, 2);
  EXPECT_EQ(s.regions[1].label, 1);
  EXPECT_EQ(s.regions[2].label, 2);
  EXPECT_NEAR(region_area(s.regions[0]) + region_area(s.regions[2]), 2.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_EQ(set.repairs[0].kind, "self_intersection");
  EXPECT_EQ(set.repairs[0].where, "slice 0, region 0 (label 2), outer ring");
  EXPECT_TRUE(contains(set.repairs[0].detail,
                       "contour crosses itself at [1, 1]; repaired into 2 simple polygons by "
                       "the non-zero rule"));
  EXPECT_TRUE(contains(warnings,
                       "t.slices.json: slice 0: region 0 (label 2), outer ring: "
                       "contour crosses itself"));
}

TEST(SliceJsonErrors, StrictRefusesASelfIntersectingPolygon) {
  const std::string region = R"({"label": 2, "polygon": [[0,0],[2,2],[2,0],[0,2]]})";
  const Result<SliceSet> result =
      parse_slice_set_json(doc(slice_at(0, region)), "t.slices.json", ReadOptions{true});
  ASSERT_FALSE(result.is_ok());
  EXPECT_TRUE(contains(result.message(),
                       "t.slices.json: slice 0, region 0 (label 2), outer ring: contour crosses "
                       "itself at [1, 1]"));
  EXPECT_TRUE(contains(result.message(), "--strict"));
}

TEST(SliceValidation, SelfIntersectingPolygonBuiltInCodeNamesTheEdges) {
  // validate_slice_set checks sets built in code; it repairs nothing.
  SliceSet set;
  set.slices.resize(1);
  set.slices[0].regions.push_back({2, {Vec2(0, 0), Vec2(2, 2), Vec2(2, 0), Vec2(0, 2)}, {}});
  const Status status = validate_slice_set(set, "mem");
  ASSERT_FALSE(status.is_ok());
  EXPECT_TRUE(contains(
      status.message(),
      "slice 0, region 0 (label 2), outer ring: polygon self-intersects (edges 0 and 2 cross)"));
  EXPECT_TRUE(contains(status.message(), "split it into separate regions"));
}

TEST(SliceJsonRepairs, SelfIntersectingHoleBecomesTwoHoles) {
  const std::string region = R"({"label": 2, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[1,1],[2,1],[2,2],[1,2]], [[3,3],[7,7],[7,3],[3,7]]]})";
  const auto [set, warnings] = parse_with_warnings(doc(slice_at(0, region)));
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 1u);
  EXPECT_EQ(set.slices[0].regions[0].holes.size(), 3u);
  EXPECT_NEAR(region_area(set.slices[0].regions[0]), 100.0 - 1.0 - 8.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_EQ(set.repairs[0].where, "slice 0, region 0 (label 2), hole 1");
}

TEST(SliceJsonRepairs, HolesFollowThePartOfARepairedOuterRingThatHoldsThem) {
  // A bow tie of two 4 x 4 triangles-ish lobes, each with a small hole.
  const std::string region = R"({"label": 1, "polygon": [[0,0],[8,8],[8,0],[0,8]],
      "holes": [[[0.5,3.5],[1.5,3.5],[1.5,4.5],[0.5,4.5]], [[6.5,3.5],[7.5,3.5],[7.5,4.5],[6.5,4.5]]]})";
  const auto [set, warnings] = parse_with_warnings(doc(slice_at(0, region)));
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 2u);
  EXPECT_EQ(s.regions[0].holes.size(), 1u);
  EXPECT_EQ(s.regions[1].holes.size(), 1u);
  EXPECT_NEAR(region_area(s.regions[0]) + region_area(s.regions[1]), 32.0 - 2.0, 1e-9);
}

TEST(SliceJsonRepairs, PolygonFoldingBackOnItselfLosesItsSpike) {
  // Adjacent edges 1 and 2 run back along the same line: the spike (4,2)-(4,4) encloses nothing.
  const std::string region = R"({"label": 1, "polygon": [[0,0],[4,0],[4,4],[4,2],[0,4]]})";
  const auto [set, warnings] = parse_with_warnings(doc(slice_at(0, region)));
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 1u);
  EXPECT_EQ(set.slices[0].regions[0].outer.size(), 4u);
  EXPECT_NEAR(region_area(set.slices[0].regions[0]), 12.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_NEAR(set.repairs[0].area_changed_mm2, 0.0, 1e-9);
}

TEST(SliceJsonRepairs, RegionWhoseOuterRingEnclosesNothingIsDropped) {
  // Out to (4, 0), up to (2, 2) and back the same way: no area.
  const std::string nothing = R"({"label": 1, "polygon": [[0,0],[4,0],[2,2],[4,0]]})";
  const auto [set, warnings] =
      parse_with_warnings(doc(slice_at(0, nothing + "," + square_region(2, 5, 5, 1))));
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 1u);
  EXPECT_EQ(set.slices[0].regions[0].label, 2);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_TRUE(contains(set.repairs[0].detail, "it encloses no area; dropped it"));
}

TEST(SliceJsonRepairs, FovWithASpikeIsRepaired) {
  const std::string slice =
      R"({"origin": [0,0,0], "u": [1,0,0], "v": [0,1,0], "fov": [[0,0],[4,0],[4,4],[4,2],[0,4]], "regions": []})";
  const auto [set, warnings] = parse_with_warnings(doc(slice));
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_TRUE(set.slices[0].fov.has_value());
  EXPECT_NEAR(std::abs(signed_area(*set.slices[0].fov)), 12.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_EQ(set.repairs[0].where, "slice 0, fov");
}

TEST(SliceJsonErrors, ZeroArea) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[1,1],[3,3]]})";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, region))),
                       "slice 0, region 0 (label 1), outer ring: polygon has zero area"));
}

TEST(SliceJsonErrors, OverlappingRegions) {
  const std::string message =
      parse_error(doc(slice_at(0, square_region(1, 0, 0, 1)) + "," +
                      slice_at(1, square_region(1, 0, 0, 2) + "," + square_region(2, 1, 1, 2))));
  EXPECT_TRUE(contains(message, "slice 1: region 0 (label 1) and region 1 (label 2) overlap"));
}

TEST(SliceJson, SharedEdgesTouchingAndNestingInHolesAreFine) {
  const std::string in_hole = R"({"label": 1, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[2,2],[8,2],[8,8],[2,8]]]})";
  const std::string regions = in_hole + "," + square_region(1, 10, 0, 5) + "," +  // shares an edge
                              square_region(2, 15, 5, 5) + "," +  // touches a corner
                              square_region(2, 2, 2, 6);          // fills the hole exactly
  const Result<SliceSet> result = parse(
      doc(slice_at(0, regions) + "," + slice_at(1, in_hole + "," + square_region(2, 3, 3, 2))));
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->slices[0].regions.size(), 4u);
  EXPECT_EQ(result->slices[1].regions.size(), 2u);
}

TEST(SliceJsonErrors, RegionOverlapsAnotherThroughItsHole) {
  const std::string in_hole = R"({"label": 1, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[2,2],[8,2],[8,8],[2,8]]]})";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, in_hole + "," + square_region(2, 1, 1, 3)))),
                       "region 0 (label 1) and region 1 (label 2) overlap"));
}

TEST(SliceJsonErrors, RegionInsideAnotherWithoutTouching) {
  // Boundaries do not meet: decided by point tests rather than Boolean operations.
  const std::string message =
      parse_error(doc(slice_at(0, square_region(1, 0, 0, 10) + "," + square_region(2, 3, 3, 2))));
  EXPECT_TRUE(contains(message, "slice 0: region 0 (label 1) and region 1 (label 2) overlap"));
  const std::string message2 =
      parse_error(doc(slice_at(0, square_region(2, 3, 3, 2) + "," + square_region(1, 0, 0, 10))));
  EXPECT_TRUE(contains(message2, "slice 0: region 0 (label 2) and region 1 (label 1) overlap"));
}

TEST(SliceJsonErrors, HoleFarOutsideItsPolygon) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[20,20],[22,20],[22,22],[20,22]]]})";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, region))), "hole 0: hole is not inside"));
}

TEST(SliceJsonErrors, HoleInsideAnotherHole) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[1,1],[9,1],[9,9],[1,9]], [[4,4],[5,4],[5,5],[4,5]]]})";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, region))), "hole 0: overlaps hole 1"));
}

TEST(SliceJsonErrors, HoleOutsideItsPolygon) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[8,8],[12,8],[12,12],[8,12]]]})";
  EXPECT_TRUE(
      contains(parse_error(doc(slice_at(0, region))),
               "slice 0, region 0 (label 1), hole 0: hole is not inside the region's outer ring"));
}

TEST(SliceJsonErrors, HoleThatIsTheWholeOuterRing) {
  const std::string square = "[[0,0],[1,0],[1,1],[0,1]]";
  const std::string region =
      R"({"label": 1, "polygon": )" + square + R"(, "holes": [)" + square + "]}";
  const std::string message =
      parse_error(doc(slice_at(0, region + "," + square_region(2, 0, 0, 1))));
  EXPECT_TRUE(contains(message,
                       "slice 0, region 0 (label 1), hole 0: hole is the region's whole "
                       "outer ring"));
}

TEST(SliceJsonErrors, OverlappingHoles) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[1,1],[5,1],[5,5],[1,5]], [[4,4],[8,4],[8,8],[4,8]]]})";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, region))),
                       "slice 0, region 0 (label 1), hole 0: overlaps hole 1"));
}

// Found by fuzzing (tests/data/fuzz/slices_json/, tests/data/fuzz/csl/): holes that CGAL's Boolean
// operations cannot take crashed the overlap test between regions.
TEST(SliceJsonErrors, HoleSharingAnEdgeWithTheOuterRing) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[10,0],[10,10],[0,10]],
      "holes": [[[2,0],[8,0],[5,4]]]})";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, region))),
                       "slice 0, region 0 (label 1): its holes meet the outer ring or each other "
                       "along an edge"));
}

TEST(SliceJson, HolesMeetingInCornersAcrossTheRegionAreRead) {
  // The holes touch each other and the outer ring in corners: the shape of the fuzzed input
  // whose overlap test crashed with CGAL's default (polyline) traits.
  const std::string region = R"({"label": 1,
      "polygon": [[0,0],[10,0],[10,5],[10,10],[0,10],[0,5]],
      "holes": [[[0,5],[4,4],[5,5],[4,6]], [[5,5],[6,4],[10,5],[6,6]]]})";
  const std::string filling = R"({"label": 2, "polygon": [[0,5],[4,4],[5,5],[4,6]]})";
  const auto set = parse(doc(slice_at(0, region + "," + filling)));
  EXPECT_TRUE(set.is_ok()) << set.message();
  const std::string overlapping = R"({"label": 2, "polygon": [[1,1],[3,1],[3,3],[1,3]]})";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, region + "," + overlapping))),
                       "region 0 (label 1) and region 1 (label 2) overlap"));
}

TEST(SliceJson, HoleTouchingTheOuterRingAtOneCornerIsFine) {
  const std::string region = R"({"label": 1,
      "polygon": [[0,0],[10,0],[10,10],[0,10],[0,5]], "holes": [[[0,5],[4,4],[4,6]]]})";
  // A second material fills the hole, so the overlap test between the regions runs.
  const std::string filling = R"({"label": 2, "polygon": [[0,5],[4,4],[4,6]]})";
  const auto set = parse(doc(slice_at(0, region + "," + filling)));
  EXPECT_TRUE(set.is_ok()) << set.message();
}

TEST(SliceJsonErrors, UndeclaredLabel) {
  const std::string labels = R"("labels": [{"id": 1, "name": "a"}, {"id": 2, "name": "b"}], )";
  const std::string message = parse_error(doc(slice_at(0, square_region(7, 0, 0, 1)), labels));
  EXPECT_TRUE(contains(message, "slice 0, region 0 (label 7): label 7 is not declared"));
  EXPECT_TRUE(contains(message, "declared: 1, 2"));
}

TEST(SliceJson, AnyPositiveLabelWithoutDeclaredLabels) {
  EXPECT_TRUE(parse(doc(slice_at(0, square_region(7, 0, 0, 1)))).is_ok());
  EXPECT_TRUE(parse(doc(slice_at(0, square_region(7, 0, 0, 1)), R"("labels": [], )")).is_ok());
}

TEST(SliceJsonErrors, LabelsThatAreNotIds) {
  for (const char* label : {"0", "-1", "1.5", "\"liver\"", "null"}) {
    const std::string region =
        std::string(R"({"label": )") + label + R"(, "polygon": [[0,0],[1,0],[0,1]]})";
    const std::string message =
        parse_error(doc(slice_at(0, square_region(1, 5, 5, 1)) + "," + slice_at(1, region)));
    EXPECT_TRUE(contains(message, "slice 1, region 0: label " + std::string(label))) << label;
    EXPECT_TRUE(contains(message, "neither \"unknown\" nor a positive integer")) << label;
  }
}

// A material that casts an acoustic shadow (bone) says so in its label entry; leaving the key
// out means it does not, as in files written before the key existed.
TEST(SliceJson, ALabelCastsAShadowOnlyWhereItSaysSo) {
  const std::string labels =
      R"("labels": [{"id": 1, "name": "rib", "casts_shadow": true}, {"id": 2, "name": "liver"},)"
      R"( {"id": 3, "name": "kidney", "casts_shadow": false}], )";
  const Result<SliceSet> set = parse(doc(slice_at(0, square_region(1, 0, 0, 1)), labels));
  ASSERT_TRUE(set.is_ok()) << set.message();
  ASSERT_EQ(set->labels.size(), 3u);
  EXPECT_TRUE(set->labels[0].casts_shadow);
  EXPECT_FALSE(set->labels[1].casts_shadow);
  EXPECT_FALSE(set->labels[2].casts_shadow);
  EXPECT_TRUE(set->label_info(1).casts_shadow);
  EXPECT_FALSE(set->label_info(2).casts_shadow);
  EXPECT_FALSE(set->label_info(7).casts_shadow);  // not declared
  EXPECT_EQ(set->label_info(7).name, "label_7");
}

TEST(SliceJsonErrors, CastsShadowThatIsNotABoolean) {
  for (const char* value : {"1", "\"yes\"", "null", "[true]"}) {
    std::string labels = R"("labels": [{"id": 1, "name": "a"}, {"id": 2, "name": "rib", )";
    labels += R"("casts_shadow": )";
    labels += value;
    labels += "}], ";
    const std::string message = parse_error(doc(slice_at(0, square_region(1, 0, 0, 1)), labels));
    EXPECT_TRUE(contains(message, "labels, entry 1")) << message;
    EXPECT_TRUE(contains(message, std::string("\"casts_shadow\" is ") + value)) << message;
    EXPECT_TRUE(contains(message, "not true or false")) << message;
  }
}

TEST(SliceJsonErrors, NonNumbersAndNonFiniteNumbers) {
  const std::string nan_region = R"({"label": 1, "polygon": [[0,0],[1,"NaN"],[0,1]]})";
  const std::string message = parse_error(doc(slice_at(0, nan_region)));
  EXPECT_TRUE(
      contains(message, "slice 0, region 0 (label 1), outer ring, point 1: expected a number"));
  EXPECT_TRUE(contains(message, "NaN and infinity are not allowed"));

  const std::string inf_origin =
      R"({"origin": [0, "Infinity", 0], "u": [1,0,0], "v": [0,1,0], "regions": []})";
  EXPECT_TRUE(contains(parse_error(doc(inf_origin)), "slice 0, origin: expected a number"));
  // Too large for a double: either nlohmann refuses it or we see infinity; both must fail.
  const std::string huge = R"({"label": 1, "polygon": [[0,0],[1e999,0],[0,1]]})";
  parse_error(doc(slice_at(0, huge)));
}

TEST(SliceJsonErrors, NonFiniteInCodeSetIsRejectedByValidation) {
  SliceSet set;
  set.slices.resize(1);
  set.slices[0].regions.push_back({1, {Vec2(0, 0), Vec2(std::nan(""), 0), Vec2(0, 1)}, {}});
  const Status status = validate_slice_set(set, "mem");
  ASSERT_FALSE(status.is_ok());
  EXPECT_TRUE(
      contains(status.message(),
               "mem: slice 0, region 0 (label 1), outer ring: point 1 is not a finite number"));
}

TEST(SliceJsonErrors, SliceOutsideBounds) {
  const std::string bounds = R"("bounds": {"min": [-10,-10,-10], "max": [10,10,10]}, )";
  // Slice 1's plane crosses the box but its region lies beside it; slice 2 has no region and
  // its plane misses the box.
  const std::string message =
      parse_error(doc(slice_at(0, square_region(1, 0, 0, 1)) + "," +
                          slice_at(1, square_region(1, 50, 50, 5)) + "," + slice_at(30, ""),
                      bounds));
  EXPECT_TRUE(contains(message, "slice 1: the slice lies entirely outside bounds"));
  EXPECT_TRUE(contains(message, "slice 2: the slice lies entirely outside bounds"));
  EXPECT_FALSE(contains(message, "slice 0:"));
}

// A frame's sector that crosses the box says "outside" there even when the frame's regions
// (an organ deep in the image) lie beyond it, as a scan's last keyframe past its volume does;
// a sector wholly beyond the box is still refused.
TEST(SliceJson, ASliceWhoseFovCrossesTheBoundsIsReadWhereverItsRegionsLie) {
  const std::string bounds = R"("bounds": {"min": [-10,-10,-10], "max": [10,10,10]}, )";
  const auto with_fov = [](double z, const std::string& fov, const std::string& regions) {
    return R"({"origin": [0, 0, )" + std::to_string(z) +
           R"(], "u": [1, 0, 0], "v": [0, 1, 0], "fov": )" + fov + R"(, "regions": [)" + regions +
           "]}";
  };
  const std::string crossing = "[[-5,-5],[60,-5],[60,60],[-5,60]]";
  const std::string beyond = "[[40,40],[60,40],[60,60],[40,60]]";
  EXPECT_TRUE(parse(doc(slice_at(0, square_region(1, 0, 0, 1)) + "," +
                            with_fov(1, crossing, square_region(1, 50, 50, 5)),
                        bounds))
                  .is_ok());
  const std::string message = parse_error(doc(slice_at(0, square_region(1, 0, 0, 1)) + "," +
                                                  with_fov(1, beyond, square_region(1, 50, 50, 5)),
                                              bounds));
  EXPECT_TRUE(contains(message, "slice 1: the slice lies entirely outside bounds"));
}

TEST(SliceJson, EmptySliceInsideBoundsIsFine) {
  const std::string bounds = R"("bounds": {"min": [-10,-10,-10], "max": [10,10,10]}, )";
  EXPECT_TRUE(
      parse(doc(slice_at(5, "") + "," + slice_at(0, square_region(1, 8, 8, 5)), bounds)).is_ok());
}

TEST(SliceJsonErrors, BoundsMinNotBelowMax) {
  const std::string bounds = R"("bounds": {"min": [-10,5,-10], "max": [10,5,10]}, )";
  EXPECT_TRUE(contains(parse_error(doc(slice_at(0, square_region(1, 0, 0, 1)), bounds)),
                       "bounds: min[1] = 5 is not below max[1] = 5"));
}

TEST(SliceJsonErrors, ReportsSeveralProblemsAtOnce) {
  const std::string bad = R"({"label": 1, "polygon": [[0,0],[2,0],[4,0]]})";
  const std::string message = parse_error(doc(
      slice_at(0, bad) + "," + slice_at(1, square_region(1, 0, 0, 1)) + "," + slice_at(2, bad)));
  EXPECT_TRUE(contains(message, "slice 0, region 0"));
  EXPECT_TRUE(contains(message, "slice 2, region 0"));
}

TEST(SliceJson, RepeatedConsecutivePointsAreDroppedWithAWarning) {
  const std::string region = R"({"label": 1, "polygon": [[0,0],[1,0],[1,0],[1,1],[0,1],[0,0]]})";
  ::testing::internal::CaptureStderr();
  const Result<SliceSet> result = parse(doc(slice_at(0, region)));
  const std::string warnings = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->slices[0].regions[0].outer.size(), 4u);
  EXPECT_TRUE(contains(warnings, "slice 0: region 0 (label 1), outer ring: dropped 2 repeated"));
}

TEST(SliceJson, IdenticalCoincidentSlicesAreMerged) {
  // Slice 2 repeats slice 0 in the same plane with another basis (u, v swapped and the normal
  // flipped): the same world points.
  const std::string flipped =
      R"({"origin": [0,0,0], "u": [0,1,0], "v": [1,0,0], "regions": [{"label": 1,
          "polygon": [[0,0],[0,1],[1,1],[1,0]]}]})";
  ::testing::internal::CaptureStderr();
  const Result<SliceSet> result =
      parse(doc(slice_at(0, square_region(1, 0, 0, 1)) + "," +
                slice_at(3, square_region(1, 0, 0, 1)) + "," + flipped));
  const std::string warnings = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->slices.size(), 2u);
  EXPECT_TRUE(contains(warnings, "slice 2: lies in the same plane as slice 0"));
}

TEST(SliceJsonErrors, CoincidentSlicesThatDisagree) {
  const std::string message = parse_error(doc(slice_at(0, square_region(1, 0, 0, 1)) + "," +
                                              slice_at(3, square_region(1, 0, 0, 1)) + "," +
                                              slice_at(0, square_region(1, 0, 0, 2))));
  EXPECT_TRUE(contains(
      message, "slice 0 and slice 2: they lie in the same plane but their contents disagree"));
}

TEST(SliceJsonErrors, FovSelfIntersectingIntoTwoPolygons) {
  const std::string slice =
      R"({"origin": [0,0,0], "u": [1,0,0], "v": [0,1,0], "fov": [[0,0],[2,2],[2,0],[0,2]], "regions": []})";
  const std::string message = parse_error(doc(slice));
  EXPECT_TRUE(contains(message, "slice 0, fov: polygon self-intersects"));
  EXPECT_TRUE(contains(message, "it encloses 2 polygons and 0 holes, but a fov must be one"));
}

TEST(SliceJsonErrors, StructuralProblemsNameTheirPlace) {
  EXPECT_TRUE(contains(parse_error(R"({"format": "sonoshape-slices", "version": 1})"),
                       "\"slices\" must be an array"));
  EXPECT_TRUE(contains(parse_error(doc(R"({"u": [1,0,0], "v": [0,1,0]})")),
                       "slice 0: \"origin\" is missing"));
  EXPECT_TRUE(
      contains(parse_error(doc(slice_at(0, R"({"label": 1, "polygon": [[0,0],[1,0,3],[0,1]]})"))),
               "slice 0, region 0 (label 1), outer ring, point 1: expected [x, y]"));
}

TEST(SliceFiles, MissingFileNamesThePath) {
  TempDir dir;
  const auto path = dir.path() / "absent.slices.json";
  const Result<SliceSet> result = read_slice_set(path);
  ASSERT_FALSE(result.is_ok());
  EXPECT_TRUE(contains(result.message(), path.string()));
  EXPECT_TRUE(contains(result.message(), "no such file"));
}

TEST(SliceFiles, UnwritablePathNamesThePath) {
  TempDir dir;
  const auto path = dir.path() / "no_such_dir" / "out.slices.json";
  const Status status = write_slice_set(SliceSet{}, path);
  ASSERT_FALSE(status.is_ok());
  EXPECT_TRUE(contains(status.message(), path.string()));
}

TEST(SliceFiles, JsonRoundTripIsExact) {
  TempDir dir;
  Result<SliceSet> original = parse(kSpecExample);
  ASSERT_TRUE(original.is_ok());
  SliceSet set = *original;
  // Values that need all 17 digits to survive.
  set.slices[0].origin_mm = Vec3(1.0 / 3.0, 0.1 + 0.2, -2.0 / 7.0);
  set.slices[0].regions[0].outer[0] = Vec2(-10.000000000000002, 5.123456789012345);
  set.labels[0].name = "li\"ver";
  set.labels[1].casts_shadow = true;
  // Directions turned by 0.3 rad in their plane: both need all 17 digits too.
  set.slices[0].u = Vec3(std::cos(0.3), std::sin(0.3), 0.0);
  set.slices[0].v = Vec3(-std::sin(0.3), std::cos(0.3), 0.0);
  set.slices[0].outline_sd_mm = 0.1 + 0.2;
  const auto path = dir.path() / "set.slices.json";
  ASSERT_TRUE(write_slice_set(set, path).is_ok());
  const Result<SliceSet> back = read_slice_set(path);
  ASSERT_TRUE(back.is_ok()) << back.message();
  EXPECT_EQ(back->labels[0].name, "li\"ver");
  EXPECT_EQ(back->bounds->min, set.bounds->min);
  EXPECT_EQ(back->bounds->max, set.bounds->max);
  EXPECT_EQ(back->units, set.units);
  ASSERT_EQ(back->labels.size(), set.labels.size());
  for (std::size_t k = 0; k < set.labels.size(); ++k) {
    EXPECT_EQ(back->labels[k].id, set.labels[k].id);
    EXPECT_EQ(back->labels[k].casts_shadow, set.labels[k].casts_shadow) << k;
  }
  ASSERT_EQ(back->slices.size(), set.slices.size());
  const LabeledSlice& a = set.slices[0];
  const LabeledSlice& b = back->slices[0];
  EXPECT_EQ(a.origin_mm, b.origin_mm);
  EXPECT_EQ(a.u, b.u);
  EXPECT_EQ(a.v, b.v);
  EXPECT_EQ(a.timestamp_s, b.timestamp_s);
  EXPECT_EQ(a.outline_sd_mm, b.outline_sd_mm);
  EXPECT_EQ(*a.fov, *b.fov);
  ASSERT_EQ(a.regions.size(), b.regions.size());
  for (std::size_t j = 0; j < a.regions.size(); ++j) {
    EXPECT_EQ(a.regions[j].label, b.regions[j].label);
    EXPECT_EQ(a.regions[j].outer, b.regions[j].outer);
    EXPECT_EQ(a.regions[j].holes, b.regions[j].holes);
  }
}

TEST(SliceFiles, ReadDispatchesOnExtension) {
  TempDir dir;
  const auto csl = dir.path() / "tri.CSL";
  std::ofstream(csl) << "CSLC\n1 2\n1 3 1 0 0 1 0\n0 0 0\n1 0 0\n0 1 0\n3 1 0 1 2\n";
  const Result<SliceSet> result = read_slice_set(csl);
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->slices.size(), 1u);

  const auto json = dir.path() / "tri.json";
  std::ofstream(json) << "CSLC\n";
  const Result<SliceSet> not_json = read_slice_set(json);
  ASSERT_FALSE(not_json.is_ok());
  EXPECT_TRUE(contains(not_json.message(), "not valid JSON"));
}

}  // namespace
}  // namespace sonoshape::slice_io_test
