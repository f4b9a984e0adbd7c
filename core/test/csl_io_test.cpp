// `.csl` contour files: reading real-world quirks, the errors, writing, and a JSON round trip.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::csl_io_test {
namespace {

using sonoshape::testing::contains;

using sonoshape::testing::TempDir;

Result<SliceSet> parse(const std::string& text) { return parse_csl(text, "t.csl"); }

std::string parse_error(const std::string& text) {
  const Result<SliceSet> result = parse(text);
  EXPECT_FALSE(result.is_ok());
  if (result.is_ok()) return {};
  EXPECT_TRUE(contains(result.message(), "t.csl"));
  return result.message();
}

// Every world point of a slice's ring.
std::vector<Vec3> world(const LabeledSlice& s, const Ring2& ring) {
  std::vector<Vec3> points;
  for (const Vec2& p : ring) points.push_back(s.to_world(p));
  return points;
}

// Same points in the same cyclic order, starting anywhere, in either direction.
bool same_cycle(const std::vector<Vec3>& a, const std::vector<Vec3>& b, double tol = 1e-9) {
  if (a.size() != b.size()) return false;
  const std::size_t n = a.size();
  for (int direction : {1, -1})
    for (std::size_t start = 0; start < n; ++start) {
      bool all = true;
      for (std::size_t k = 0; k < n && all; ++k) {
        long j =
            (static_cast<long>(start) + direction * static_cast<long>(k)) % static_cast<long>(n);
        if (j < 0) j += static_cast<long>(n);
        all = (a[k] - b[static_cast<std::size_t>(j)]).norm() <= tol;
      }
      if (all) return true;
    }
  return false;
}

// Two planes z = 0 and z = 10, three labels. Plane 1: a label-1 square (component 0) with a
// square hole written "4h0" (component 1), a label-2 triangle (component 2) beside it.
// Plane 2 is empty. Blank lines, tabs, exponents and a leading '+' on purpose.
const char* kTwoPlanes = R"(CSLC

2 3

1 11 3 0 0 1 0

0 0 0
1e1 0 0
10 10 0
0 1.0E+1 0
2 2 0
2 8 0
8 8 0

8 2 0
20 0 0
30 0 +0
25 5 0
4 1 0 1 2 3
4h0 1 4 5 6 7

3 2 8 9 10

2 0 0 0 0 -1 10
)";

TEST(Csl, ReadsPlanesHolesLabelsAndEmptyPlanes) {
  const Result<SliceSet> result = parse(kTwoPlanes);
  ASSERT_TRUE(result.is_ok()) << result.message();
  const SliceSet& set = *result;
  ASSERT_EQ(set.labels.size(), 2u);
  EXPECT_EQ(set.labels[0].id, 1);
  EXPECT_EQ(set.labels[1].name, "label_2");
  ASSERT_EQ(set.slices.size(), 2u);

  const LabeledSlice& s = set.slices[0];
  EXPECT_NEAR(std::abs(s.normal().dot(Vec3::UnitZ())), 1.0, 1e-15);
  EXPECT_NEAR(s.u.norm(), 1.0, 1e-15);
  EXPECT_NEAR(s.u.dot(s.v), 0.0, 1e-15);
  EXPECT_NEAR((s.normal() - Vec3::UnitZ()).norm(), 0.0, 1e-15);
  ASSERT_EQ(s.regions.size(), 2u);
  EXPECT_EQ(s.regions[0].label, 1);
  EXPECT_TRUE(same_cycle(world(s, s.regions[0].outer),
                         {Vec3(0, 0, 0), Vec3(10, 0, 0), Vec3(10, 10, 0), Vec3(0, 10, 0)}));
  ASSERT_EQ(s.regions[0].holes.size(), 1u);
  EXPECT_TRUE(same_cycle(world(s, s.regions[0].holes[0]),
                         {Vec3(2, 2, 0), Vec3(2, 8, 0), Vec3(8, 8, 0), Vec3(8, 2, 0)}));
  EXPECT_EQ(s.regions[1].label, 2);
  EXPECT_TRUE(s.regions[1].holes.empty());

  const LabeledSlice& empty = set.slices[1];
  EXPECT_TRUE(empty.regions.empty());
  EXPECT_NEAR(std::abs(empty.normal().dot(Vec3::UnitZ())), 1.0, 1e-15);
  EXPECT_NEAR(empty.origin_mm.z(), 10.0, 1e-12);
}

TEST(Csl, ObliquePlaneKeepsWorldPositions) {
  // The plane x + y + z = 3 through three vertices given exactly on it.
  const Result<SliceSet> result =
      parse("CSLC\n1 2\n1 3 1 1 1 1 -3\n3 0 0\n0 3 0\n0 0 3\n3 1 0 1 2\n");
  ASSERT_TRUE(result.is_ok()) << result.message();
  const LabeledSlice& s = result->slices[0];
  EXPECT_NEAR((s.normal() - Vec3(1, 1, 1).normalized()).norm(), 0.0, 1e-15);
  EXPECT_NEAR(s.u.norm(), 1.0, 1e-15);
  EXPECT_NEAR(s.v.norm(), 1.0, 1e-15);
  EXPECT_TRUE(same_cycle(world(s, s.regions[0].outer),
                         {Vec3(3, 0, 0), Vec3(0, 3, 0), Vec3(0, 0, 3)}, 1e-12));
}

TEST(Csl, PlaneGivenTwiceIsMergedWithAWarning) {
  // Plane 2 repeats plane 1 with its vertices listed in another order.
  const char* text =
      "CSLC\n3 2\n"
      "1 3 1 0 0 1 -1\n0 0 1\n4 0 1\n0 4 1\n3 1 0 1 2\n"
      "2 3 1 0 0 1 -5\n0 0 5\n4 0 5\n0 4 5\n3 1 0 1 2\n"
      "3 3 1 0 0 -2 2\n0 4 1\n0 0 1\n4 0 1\n3 1 1 2 0\n";
  ::testing::internal::CaptureStderr();
  const Result<SliceSet> result = parse(text);
  const std::string warnings = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->slices.size(), 2u);
  EXPECT_TRUE(contains(warnings, "plane 3 (line 13): lies in the same plane as plane 1 (line 3)"));
}

TEST(Csl, PlaneGivenTwiceWithOtherContentsIsAnError) {
  const char* text =
      "CSLC\n2 2\n"
      "1 3 1 0 0 1 -1\n0 0 1\n4 0 1\n0 4 1\n3 1 0 1 2\n"
      "2 3 1 0 0 1 -1\n0 0 1\n5 0 1\n0 4 1\n3 1 0 1 2\n";
  const std::string message = parse_error(text);
  EXPECT_TRUE(contains(message, "plane 1 (line 3) and plane 2 (line 8)"));
  EXPECT_TRUE(contains(message, "contents disagree"));
}

TEST(Csl, VerticesSlightlyOffThePlaneAreProjected) {
  const char* text =
      "CSLC\n1 2\n1 4 1 0 0 1 -2\n0 0 2.0000001\n10 0 2\n10 10 1.9999999\n0 10 2\n4 1 0 1 2 3\n";
  ::testing::internal::CaptureStderr();
  const Result<SliceSet> result = parse(text);
  const std::string warnings = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_TRUE(contains(warnings, "plane 1 (line 3): vertices lie up to"));
  EXPECT_TRUE(contains(warnings, "projected onto it"));
  const LabeledSlice& s = result->slices[0];
  for (const Vec3& p : world(s, s.regions[0].outer)) EXPECT_NEAR(p.z(), 2.0, 1e-12);
}

TEST(Csl, VerticesFarOffThePlaneAreAnError) {
  const char* text = "CSLC\n1 2\n1 4 1 0 0 1 -2\n0 0 2\n10 0 2\n10 10 3\n0 10 2\n4 1 0 1 2 3\n";
  const std::string message = parse_error(text);
  EXPECT_TRUE(contains(message, "plane 1 (line 3): vertex 2 lies 1 off the plane"));
  EXPECT_TRUE(contains(message, "and the vertices are not coplanar either (vertex "));
  EXPECT_TRUE(contains(message, "off the plane that fits them best)"));
}

TEST(Csl, RepeatedConsecutivePointsAreDropped) {
  const char* text = "CSLC\n1 2\n1 4 1 0 0 1 0\n0 0 0\n1 0 0\n1 1 0\n1 1 0\n6 1 0 1 1 2 3 0\n";
  ::testing::internal::CaptureStderr();
  const Result<SliceSet> result = parse(text);
  const std::string warnings = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(result.is_ok()) << result.message();
  EXPECT_EQ(result->slices[0].regions[0].outer.size(), 3u);
  EXPECT_TRUE(contains(warnings, "plane 1 (line 3): dropped 3 repeated consecutive points"));
}

TEST(Csl, NestingWithoutHoleMarkers) {
  // Component 0 (label 1) contains component 1 (label 2, an island of another material) and
  // component 2 (label 1, a hole without its "h" marker); component 3 (label 2) sits in that hole.
  const char* text =
      "CSLC\n1 3\n1 16 4 0 0 1 0\n"
      "0 0 0\n20 0 0\n20 20 0\n0 20 0\n"
      "2 2 0\n6 2 0\n6 6 0\n2 6 0\n"
      "10 10 0\n18 10 0\n18 18 0\n10 18 0\n"
      "12 12 0\n14 12 0\n14 14 0\n12 14 0\n"
      "4 1 0 1 2 3\n4 2 4 5 6 7\n4 1 8 9 10 11\n4 2 12 13 14 15\n";
  const Result<SliceSet> result = parse(text);
  ASSERT_TRUE(result.is_ok()) << result.message();
  const LabeledSlice& s = result->slices[0];
  ASSERT_EQ(s.regions.size(), 3u);
  EXPECT_EQ(s.regions[0].label, 1);
  EXPECT_EQ(s.regions[0].holes.size(), 2u);  // the unmarked hole and the island's outline
  EXPECT_EQ(s.regions[1].label, 2);
  EXPECT_EQ(s.regions[2].label, 2);
  EXPECT_TRUE(validate_slice_set(*result, "mem").is_ok());
}

TEST(CslErrors, LabelZeroSaysLabelsStartAtOne) {
  const std::string message =
      parse_error("CSLC\n1 2\n1 3 1 0 0 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 0 1 2\n");
  EXPECT_TRUE(contains(message, "line 7: plane 1, component 0: label 0 is the outside"));
  EXPECT_TRUE(contains(message, "add 1 to every component label"));
}

TEST(CslErrors, LabelBeyondTheHeader) {
  const std::string message =
      parse_error("CSLC\n1 2\n1 3 1 0 0 1 0\n0 0 0\n1 0 0\n0 1 0\n3 2 0 1 2\n");
  EXPECT_TRUE(contains(message, "label 2 is outside 1..1"));
}

TEST(CslErrors, StructuralProblems) {
  EXPECT_TRUE(contains(parse_error("CSL\n1 2\n"), "expected the header \"CSLC\""));
  EXPECT_TRUE(contains(parse_error("CSLC\n1 1\n"), "nLabels = 1"));
  EXPECT_TRUE(
      contains(parse_error("CSLC\n1 2\n1 3 1 0 0 1 0\n0 0 0\n1 0 0\n"), "the file ends early"));
  EXPECT_TRUE(contains(parse_error("CSLC\n1 2\n1 3 1 0 0 1 0\n0 0 0\n1 x 0\n0 1 0\n3 1 0 1 2\n"),
                       "line 5: expected a vertex y (a finite number), got \"x\""));
  EXPECT_TRUE(contains(parse_error("CSLC\n1 2\n1 3 1 0 0 1 0\n0 0 0\n1 0 0\n0 1 0\n3 1 0 1 3\n"),
                       "vertex index 3 is outside 0..2"));
  EXPECT_TRUE(contains(parse_error("CSLC\n1 2\n1 3 1 0 0 0 0\n0 0 0\n1 0 0\n0 1 0\n3 1 0 1 2\n"),
                       "the normal (A, B, C) is zero"));
  EXPECT_TRUE(contains(parse_error("CSLC\n1 2\n1 3 1 0 0 1 0\n0 0 0\n1 0 0\n0 1 0\n3h0 1 0 1 2\n"),
                       "cannot be its own parent"));
  // The boundary: a parent index equal to the component count (2 of components 0..1) reads
  // past the plane's components unless refused (issue 27's surviving mutation).
  EXPECT_TRUE(contains(parse_error("CSLC\n1 2\n1 8 2 0 0 1 0\n0 0 0\n10 0 0\n10 10 0\n0 10 0\n"
                                   "2 2 0\n8 2 0\n8 8 0\n2 8 0\n4 1 0 1 2 3\n4h2 1 7 6 5 4\n"),
                       "names component 2 as the parent of this hole, but the plane's "
                       "components are 0..1"));
  // One below the boundary is a hole of the last component: accepted.
  EXPECT_TRUE(parse("CSLC\n1 2\n1 8 2 0 0 1 0\n0 0 0\n10 0 0\n10 10 0\n0 10 0\n2 2 0\n8 2 0\n"
                    "8 8 0\n2 8 0\n4 1 0 1 2 3\n4h0 1 7 6 5 4\n")
                  .is_ok());
  EXPECT_TRUE(contains(parse_error("CSLC\n1 2\n1 0 0 0 0 1 0\n2 0 0 0 0 1 0\n"),
                       "unexpected text after the last of the 1 planes"));
}

// A header declaring 1e9 materials with one used (issue 27): read at once, one label, and the
// warning names the unused ids as a range, not one by one.
TEST(CslErrors, HugeNLabelsWithOneMaterialUsedIsReadAtOnce) {
  const Result<SliceSet> set =
      parse("CSLC\n1 1000000000\n1 3 1 0 0 1 0\n0 0 0\n1 0 0\n0 1 0\n3 1 0 1 2\n");
  ASSERT_TRUE(set.is_ok()) << set.message();
  ASSERT_EQ(set->labels.size(), 1u);
  EXPECT_EQ(set->labels[0].id, 1);
}

TEST(CslErrors, StrictRefusesASelfIntersectingComponentNamingPlaneComponentAndLine) {
  const Result<SliceSet> result =
      parse_csl("CSLC\n1 2\n1 4 1 0 0 1 0\n0 0 0\n2 2 0\n2 0 0\n0 2 0\n\n4 1 0 1 2 3\n", "t.csl",
                ReadOptions{true});
  ASSERT_FALSE(result.is_ok());
  EXPECT_TRUE(contains(result.message(),
                       "t.csl: plane 1 (line 3), component 0 (line 9, label 1): contour crosses "
                       "itself at (1, 1, 0)"));
  EXPECT_TRUE(contains(result.message(), "--strict"));
}

// Reads `text`, returning the set and what went to stderr.
std::pair<SliceSet, std::string> parse_with_warnings(const std::string& text) {
  ::testing::internal::CaptureStderr();
  const Result<SliceSet> result = parse(text);
  const std::string warnings = ::testing::internal::GetCapturedStderr();
  EXPECT_TRUE(result.is_ok()) << result.message();
  return {result.is_ok() ? *result : SliceSet{}, warnings};
}

double region_area(const Region& r) {
  double area = std::abs(signed_area(r.outer));
  for (const Ring2& hole : r.holes) area -= std::abs(signed_area(hole));
  return area;
}

double label_area(const LabeledSlice& s, int label) {
  double area = 0.0;
  for (const Region& r : s.regions)
    if (r.label == label) area += region_area(r);
  return area;
}

std::size_t count_lines(const std::string& text, const std::string& part) {
  std::size_t n = 0;
  for (std::size_t at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
  return n;
}

// One plane z = 0 with a 10 x 10 square of label 1 (vertices 0-3), then `more` vertices and
// components (the vertex count and component count given).
std::string square_plane(int n_labels, int n_vertices, int n_components, const std::string& more) {
  return "CSLC\n1 " + std::to_string(n_labels) + "\n1 " + std::to_string(4 + n_vertices) + " " +
         std::to_string(1 + n_components) + " 0 0 1 0\n0 0 0\n10 0 0\n10 10 0\n0 10 0\n" + more;
}

TEST(CslHoleLabels, ParentsLabelZeroAndNLabelsAllMeanOutside) {
  // Three square holes in the label-1 square, labelled 1 (the parent's), 0 and 3 (= nLabels).
  const std::string text = square_plane(3, 12, 3,
                                        "1 1 0\n2 1 0\n2 2 0\n1 2 0\n"
                                        "4 1 0\n5 1 0\n5 2 0\n4 2 0\n"
                                        "7 1 0\n8 1 0\n8 2 0\n7 2 0\n"
                                        "4 1 0 1 2 3\n4h0 1 4 5 6 7\n4h0 0 8 9 10 11\n"
                                        "4h0 3 12 13 14 15\n");
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 1u);
  EXPECT_EQ(s.regions[0].holes.size(), 3u);
  EXPECT_NEAR(label_area(s, 1), 97.0, 1e-12);
  EXPECT_TRUE(set.repairs.empty());
  EXPECT_TRUE(contains(warnings, "material 2 never occurs"));
}

TEST(CslHoleLabels, AnotherMaterialFillsTheHole) {
  // A hole labelled 2 in the label-1 square: label 1 loses it and label 2 fills it.
  const std::string text = square_plane(3, 4, 1,
                                        "2 2 0\n6 2 0\n6 6 0\n2 6 0\n"
                                        "4 1 0 1 2 3\n4h0 2 4 5 6 7\n");
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 2u);
  EXPECT_NEAR(label_area(s, 1), 84.0, 1e-12);
  EXPECT_NEAR(label_area(s, 2), 16.0, 1e-12);
  ASSERT_EQ(set.labels.size(), 2u);
  EXPECT_TRUE(warnings.empty()) << warnings;
}

TEST(CslHoleLabels, AFilledHoleAlsoWrittenAsAComponentIsOneRegion) {
  const std::string text = square_plane(3, 4, 2,
                                        "2 2 0\n6 2 0\n6 6 0\n2 6 0\n"
                                        "4 1 0 1 2 3\n4h0 2 4 5 6 7\n4 2 7 6 5 4\n");
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 2u);
  EXPECT_NEAR(label_area(set.slices[0], 2), 16.0, 1e-12);
}

TEST(CslHoleLabels, AnOrganWrittenAsAHoleAndAsItsOwnContourIsCutOutOnce) {
  // As Abdomen does: the label-2 organ is a component of its own and a hole (label 1) of the body.
  const std::string text = square_plane(20, 4, 2,
                                        "2 2 0\n6 2 0\n6 6 0\n2 6 0\n"
                                        "4 2 4 5 6 7\n4 1 0 1 2 3\n4h1 1 7 6 5 4\n");
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 2u);
  EXPECT_NEAR(label_area(s, 1), 84.0, 1e-12);
  EXPECT_NEAR(label_area(s, 2), 16.0, 1e-12);
}

TEST(Csl, AContourInAPocketTouchingItWithEveryCornerIsNotInsideIt) {
  // Component 1 (label 2, a triangle) sits in a notch of component 0 whose boundary passes
  // through all three of its corners: it is beside component 0, not in it.
  const std::string text =
      "CSLC\n1 3\n1 8 2 0 0 1 0\n"
      "0 0 0\n10 0 0\n10 10 0\n6 10 0\n5 6 0\n4 10 0\n0 10 0\n5 9 0\n"
      "7 1 0 1 2 3 4 5 6\n3 2 3 4 5\n";
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 2u);
  EXPECT_TRUE(s.regions[0].holes.empty());
  EXPECT_NEAR(label_area(s, 2), 4.0, 1e-12);
}

TEST(CslRepairs, PinchedOffLoopFilledByAnotherMaterialAsAbdomenWritesIt) {
  // The label-2 organ's contour pinches off a clockwise loop at (10, 15): a hole in the organ by
  // the non-zero rule, which component 0 (label 3) fills. The body (label 1) has the organ's
  // outline, without the loop, as a hole, listed before the organ: the organ lies in that hole.
  const char* text =
      "CSLC\n1 4\n1 11 4 0 0 1 0\n"
      "0 0 0\n20 0 0\n20 20 0\n0 20 0\n5 5 0\n15 5 0\n15 15 0\n10 15 0\n11 13 0\n"
      "9 13 0\n5 15 0\n"
      "3 3 7 8 9\n4 1 0 1 2 3\n5h1 1 4 5 6 7 10\n8 2 4 5 6 7 8 9 7 10\n";
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  EXPECT_NEAR(label_area(s, 1), 300.0, 1e-9);
  EXPECT_NEAR(label_area(s, 2), 98.0, 1e-9);
  EXPECT_NEAR(label_area(s, 3), 2.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_TRUE(contains(set.repairs[0].detail,
                       "at (10, 15, 0); repaired into 1 simple polygon "
                       "with 1 hole"));
}

TEST(CslErrors, HoleLabelBeyondNLabels) {
  const std::string message = parse_error(
      square_plane(3, 4, 1, "2 2 0\n6 2 0\n6 6 0\n2 6 0\n4 1 0 1 2 3\n4h0 4 4 5 6 7\n"));
  EXPECT_TRUE(contains(message, "plane 1, component 1: label 4 is outside 0..3"));
}

TEST(CslLabels, DeclaredButUnusedMaterialsAreNotLabelsAndAreNamedOnce) {
  const std::string text = square_plane(20, 0, 0, "4 1 0 1 2 3\n");
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.labels.size(), 1u);
  EXPECT_EQ(set.labels[0].id, 1);
  EXPECT_EQ(set.material_ids(), std::vector<int>{1});
  EXPECT_EQ(count_lines(warnings, "\n"), 1u) << warnings;
  EXPECT_TRUE(contains(warnings, "materials 2..19 never occur"));
  EXPECT_TRUE(set.repairs.empty());
  // A note, not a repair: --strict reads the file.
  EXPECT_TRUE(parse_csl(text, "t.csl", ReadOptions{true}).is_ok());
}

// Three planes z = 1, 2, 3 written with +D where their vertices satisfy -D (as rose.csl does).
const char* kFlippedD =
    "CSLC\n3 2\n"
    "1 3 1 0 0 1 1\n0 0 1\n4 0 1\n0 4 1\n3 1 0 1 2\n"
    "2 3 1 0 0 1 2\n0 0 2\n4 0 2\n0 4 2\n3 1 0 1 2\n"
    "3 3 1 0 0 1 3\n0 0 3\n4 0 3\n0 4 3\n3 1 0 1 2\n";

TEST(CslPlanes, FlippedDIsFittedToTheVerticesWithOneWarningForTheFile) {
  const auto [set, warnings] = parse_with_warnings(kFlippedD);
  ASSERT_EQ(set.slices.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const LabeledSlice& s = set.slices[i];
    EXPECT_NEAR((s.normal() - Vec3::UnitZ()).norm(), 0.0, 1e-12);  // the written orientation
    for (const Vec3& p : world(s, s.regions[0].outer))
      EXPECT_NEAR(p.z(), static_cast<double>(i + 1), 1e-12);
  }
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_EQ(set.repairs[0].kind, "plane_refit");
  EXPECT_EQ(set.repairs[0].where, "");
  EXPECT_EQ(count_lines(warnings, "\n"), 1u) << warnings;
  EXPECT_TRUE(contains(warnings,
                       "t.csl: planes 1..3 (3 of 3): the plane equation disagrees with its "
                       "vertices (they satisfy Ax+By+Cz-D=0); fitted the plane to the vertices"));
  const Result<SliceSet> strict = parse_csl(kFlippedD, "t.csl", ReadOptions{true});
  ASSERT_FALSE(strict.is_ok());
  EXPECT_TRUE(contains(strict.message(), "t.csl: planes 1..3 (3 of 3): the plane equation"));
}

TEST(CslPlanes, NoisyVerticesOfAWronglyWrittenPlaneAreFittedAndProjected) {
  // The vertices lie near z = 5 + x/10 (noise 1e-5, not coplanar); the plane says z = 0.
  const char* text =
      "CSLC\n1 2\n1 4 1 0 0 1 0\n"
      "0 0 5.00001\n10 0 6\n10 10 6.00001\n0 10 5\n4 1 0 1 2 3\n";
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  const Vec3 n = set.slices[0].normal();
  EXPECT_NEAR((n - Vec3(-0.1, 0, 1).normalized()).norm(), 0.0, 1e-5);
  ASSERT_EQ(set.repairs.size(), 2u);
  EXPECT_EQ(set.repairs[0].kind, "off_plane_vertices");
  EXPECT_EQ(set.repairs[1].kind, "plane_refit");
  EXPECT_TRUE(contains(warnings, "t.csl: plane 1 (1 of 1): the plane equation disagrees"));
  EXPECT_FALSE(contains(warnings, "Ax+By+Cz-D=0"));
}

TEST(CslRepairs, FigureEightBecomesTwoPolygons) {
  const auto [set, warnings] =
      parse_with_warnings("CSLC\n1 2\n1 4 1 0 0 1 0\n0 0 0\n2 2 0\n2 0 0\n0 2 0\n4 1 0 1 2 3\n");
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 2u);
  EXPECT_NEAR(label_area(s, 1), 2.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  const Repair& r = set.repairs[0];
  EXPECT_EQ(r.kind, "self_intersection");
  EXPECT_EQ(r.where, "plane 1 (line 3), component 0 (line 8, label 1)");
  EXPECT_TRUE(contains(r.detail,
                       "contour crosses itself at (1, 1, 0); repaired into 2 simple "
                       "polygons by the non-zero rule"));
  EXPECT_NEAR(r.area_changed_mm2, 0.0, 1e-9);  // each lobe is covered once
  EXPECT_TRUE(contains(warnings,
                       "t.csl: plane 1 (line 3): component 0 (line 8, label 1): "
                       "contour crosses itself"));
}

TEST(CslRepairs, SmallLoopIsFilledAndItsAreaReported) {
  // Along the bottom edge the contour curls once around [4,6]x[0,2], which it then covers twice.
  const auto [set, warnings] = parse_with_warnings(
      "CSLC\n1 2\n1 8 1 0 0 1 0\n"
      "0 0 0\n6 0 0\n6 2 0\n4 2 0\n4 -1 0\n10 -1 0\n10 10 0\n0 10 0\n8 1 0 1 2 3 4 5 6 7\n");
  ASSERT_EQ(set.slices.size(), 1u);
  const LabeledSlice& s = set.slices[0];
  ASSERT_EQ(s.regions.size(), 1u);
  EXPECT_TRUE(s.regions[0].holes.empty());  // even-odd would have punched [4,6]x[0,2] out
  EXPECT_NEAR(label_area(s, 1), 106.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_NEAR(set.repairs[0].area_changed_mm2, 4.0, 1e-9);
  EXPECT_TRUE(contains(warnings, "an area of 4 that it covers more than once stays inside"));
}

TEST(CslRepairs, PinchedRingBecomesTwoPolygonsTouchingAtAPoint) {
  const auto [set, warnings] = parse_with_warnings(
      "CSLC\n1 2\n1 7 1 0 0 1 0\n"
      "0 0 0\n2 0 0\n2 2 0\n4 2 0\n4 4 0\n2 4 0\n0 2 0\n8 1 0 1 2 3 4 5 2 6\n");
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 2u);
  EXPECT_NEAR(label_area(set.slices[0], 1), 8.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_TRUE(contains(set.repairs[0].detail, "at (2, 2, 0)"));
}

TEST(CslRepairs, SpikeOutAndBackIsCutOff) {
  const auto [set, warnings] = parse_with_warnings(
      square_plane(2, 1, 0, "15 5 0\n6 1 0 1 4 1 2 3\n"));  // 0 -> 10,0 -> 15,5 -> 10,0 -> ...
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 1u);
  EXPECT_EQ(set.slices[0].regions[0].outer.size(), 4u);
  EXPECT_NEAR(label_area(set.slices[0], 1), 100.0, 1e-9);
  EXPECT_EQ(set.repairs.size(), 1u);
}

TEST(CslRepairs, SelfIntersectingHoleBecomesTwoHoles) {
  const std::string text = square_plane(2, 4, 1,
                                        "2 2 0\n6 6 0\n6 2 0\n2 6 0\n"
                                        "4 1 0 1 2 3\n4h0 1 4 5 6 7\n");
  const auto [set, warnings] = parse_with_warnings(text);
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 1u);
  EXPECT_EQ(set.slices[0].regions[0].holes.size(), 2u);
  EXPECT_NEAR(label_area(set.slices[0], 1), 92.0, 1e-9);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_TRUE(contains(set.repairs[0].where, "component 1 (line 13, hole of component 0)"));
}

TEST(CslRepairs, RingEnclosingNothingIsDropped) {
  const auto [set, warnings] = parse_with_warnings(
      square_plane(2, 3, 1, "20 0 0\n24 0 0\n22 2 0\n4 1 0 1 2 3\n4 1 4 5 6 5\n"));
  ASSERT_EQ(set.slices.size(), 1u);
  ASSERT_EQ(set.slices[0].regions.size(), 1u);
  ASSERT_EQ(set.repairs.size(), 1u);
  EXPECT_TRUE(contains(set.repairs[0].detail, "encloses no area; dropped it"));
}

TEST(CslRepairs, OneWarningLinePerPlane) {
  // Two bow ties and a repeated point on one plane, a bow tie on the next.
  const char* text =
      "CSLC\n2 2\n"
      "1 8 2 0 0 1 0\n0 0 0\n2 2 0\n2 0 0\n0 2 0\n5 0 0\n7 2 0\n7 0 0\n5 2 0\n"
      "5 1 0 1 1 2 3\n4 1 4 5 6 7\n"
      "2 4 1 0 0 1 -1\n0 0 1\n2 2 1\n2 0 1\n0 2 1\n4 1 0 1 2 3\n";
  const auto [set, warnings] = parse_with_warnings(text);
  EXPECT_EQ(set.repairs.size(), 4u);
  EXPECT_EQ(count_lines(warnings, "\n"), 2u) << warnings;
  EXPECT_EQ(count_lines(warnings, "plane 1 (line 3): "), 1u) << warnings;
  EXPECT_EQ(count_lines(warnings, "plane 2 (line "), 1u) << warnings;
}

TEST(CslErrors, OverlappingComponentsAreNamed) {
  const char* text =
      "CSLC\n1 3\n1 8 2 0 0 1 0\n"
      "0 0 0\n4 0 0\n4 4 0\n0 4 0\n2 2 0\n6 2 0\n6 6 0\n2 6 0\n"
      "4 1 0 1 2 3\n4 2 4 5 6 7\n";
  const std::string message = parse_error(text);
  EXPECT_TRUE(contains(message,
                       "plane 1 (line 3): component 0 (line 12, label 1) and component 1 "
                       "(line 13, label 2) overlap"));
}

SliceSet oblique_set() {
  SliceSet set;
  set.labels = {{1, "a"}, {2, "b"}};
  LabeledSlice s;
  s.origin_mm = Vec3(1.5, -2.25, 3.0);
  s.u = Vec3(1, 2, 2).normalized();
  s.v = Vec3(2, 1, -2).normalized();                                      // orthogonal to u
  Region a{1, {Vec2(0, 0), Vec2(0, 10), Vec2(10, 10), Vec2(10, 0)}, {}};  // clockwise on purpose
  a.holes.push_back({Vec2(2, 2), Vec2(8, 2), Vec2(8, 8), Vec2(2, 8)});    // counter-clockwise
  Region b{2, {Vec2(3, 3), Vec2(7, 3), Vec2(5, 7)}, {}};                  // in a's hole
  Region c{2, {Vec2(10, 0), Vec2(15, 0), Vec2(15, 5)}, {}};
  s.regions = {a, b, c};
  set.slices.push_back(s);
  LabeledSlice empty;
  empty.origin_mm = Vec3(0, 0, -4);
  set.slices.push_back(empty);
  LabeledSlice axial;
  axial.origin_mm = Vec3(0, 0, 7);
  axial.regions.push_back({1, {Vec2(-1, -1), Vec2(1, -1), Vec2(0, 1.0 / 3.0)}, {}});
  set.slices.push_back(axial);
  return set;
}

TEST(CslFiles, JsonToCslToJsonKeepsTheGeometry) {
  TempDir dir;
  const SliceSet original = oblique_set();
  ASSERT_TRUE(validate_slice_set(original, "mem").is_ok());
  ASSERT_TRUE(write_slice_set(original, dir.path() / "a.slices.json").is_ok());
  const Result<SliceSet> from_json = read_slice_set(dir.path() / "a.slices.json");
  ASSERT_TRUE(from_json.is_ok()) << from_json.message();
  ASSERT_TRUE(write_slice_set(*from_json, dir.path() / "b.csl").is_ok());
  const Result<SliceSet> from_csl = read_slice_set(dir.path() / "b.csl");
  ASSERT_TRUE(from_csl.is_ok()) << from_csl.message();
  ASSERT_TRUE(write_slice_set(*from_csl, dir.path() / "c.slices.json").is_ok());
  const Result<SliceSet> back = read_slice_set(dir.path() / "c.slices.json");
  ASSERT_TRUE(back.is_ok()) << back.message();

  ASSERT_EQ(back->slices.size(), original.slices.size());
  for (std::size_t i = 0; i < original.slices.size(); ++i) {
    const LabeledSlice& a = original.slices[i];
    const LabeledSlice& b = back->slices[i];
    EXPECT_NEAR(std::abs(a.normal().dot(b.normal())), 1.0, 1e-12) << i;
    EXPECT_NEAR(a.normal().dot(b.origin_mm - a.origin_mm), 0.0, 1e-12) << i;
    ASSERT_EQ(a.regions.size(), b.regions.size()) << i;
    for (std::size_t j = 0; j < a.regions.size(); ++j) {
      EXPECT_EQ(a.regions[j].label, b.regions[j].label);
      EXPECT_TRUE(same_cycle(world(a, a.regions[j].outer), world(b, b.regions[j].outer), 1e-12));
      ASSERT_EQ(a.regions[j].holes.size(), b.regions[j].holes.size());
      for (std::size_t k = 0; k < a.regions[j].holes.size(); ++k)
        EXPECT_TRUE(
            same_cycle(world(a, a.regions[j].holes[k]), world(b, b.regions[j].holes[k]), 1e-12));
    }
  }
}

TEST(CslFiles, WriterOrientsOuterCounterClockwiseAndHolesClockwise) {
  TempDir dir;
  ASSERT_TRUE(write_csl(oblique_set(), dir.path() / "o.csl").is_ok());
  const Result<SliceSet> back = read_slice_set(dir.path() / "o.csl");
  ASSERT_TRUE(back.is_ok()) << back.message();
  const LabeledSlice& s = back->slices[0];
  // The reader keeps the file's order; its basis has u x v along the written normal (A, B, C).
  EXPECT_GT(signed_area(s.regions[0].outer), 0.0);
  EXPECT_LT(signed_area(s.regions[0].holes[0]), 0.0);
}

TEST(CslFiles, WriterRefusesUnknownRegionsAndFov) {
  TempDir dir;
  SliceSet set = oblique_set();
  set.slices[0].regions[2].label = kUnknownLabel;
  Status status = write_csl(set, dir.path() / "u.csl");
  ASSERT_FALSE(status.is_ok());
  EXPECT_TRUE(contains(status.message(), "slice 0, region 2 is unknown"));
  set = oblique_set();
  set.slices[2].fov = Ring2{Vec2(-5, -5), Vec2(5, -5), Vec2(0, 5)};
  status = write_csl(set, dir.path() / "f.csl");
  ASSERT_FALSE(status.is_ok());
  EXPECT_TRUE(contains(status.message(), "slice 2 has a field of view"));
}

}  // namespace
}  // namespace sonoshape::csl_io_test
