// Rounding overlaps (issue 21): a slice set whose regions a polygon library cut apart, written
// with 7 decimals, overlaps by ~1e-8 mm² where a corner of one region sits on another region's
// edge (a T-junction: rounding moves the corner off the edge). The readers snap those slivers,
// record a "rounding_overlap" repair and reconstruct; --strict and real overlaps stay errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iterator>
#include <map>
#include <numbers>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/region_clipping.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/recon/reconstruct.hpp"

namespace sonoshape::rounding_overlap_test {
namespace {

constexpr double kRadius = 10.0;  // disc, mm
constexpr int kSlices = 11;       // z = 0, 2, ..., 20 mm: a prism 20 mm tall
constexpr double kSpacing = 2.0;
constexpr double kBoxGap = 1.0;  // from the end slices to the faces of the box (mm)

Ring2 disc() {
  Ring2 p;
  for (int k = 0; k < 96; ++k) {
    const double angle = 2.0 * std::numbers::pi * k / 96.0;
    p.emplace_back(kRadius * std::cos(angle), kRadius * std::sin(angle));
  }
  return p;
}

// The part of the plane above the wavy line y = 1.5 sin(0.7 x) + 0.2 x + 2 (material 1's side).
Ring2 above_wave() {
  Ring2 p;
  for (double x = -15.0; x <= 15.0; x += 0.5)
    p.emplace_back(x, 1.5 * std::sin(0.7 * x) + 0.2 * x + 2.0);
  p.emplace_back(15.0, 30.0);
  p.emplace_back(-15.0, 30.0);
  return p;
}

Ring2 left_of(double x) { return {{-30.0, -30.0}, {x, -30.0}, {x, 30.0}, {-30.0, 30.0}}; }

// The disc's part above the wave (material 1) or below it (2): exact Boolean operations
// (clip_region), rounded to doubles.
std::vector<Region> disc_part(int label) {
  return clip_region(Region{label, disc(), {}}, above_wave(), label == 1);
}

// Splits each piece at the vertical lines x = cuts.
std::vector<Region> split(std::vector<Region> pieces, const std::vector<double>& cuts) {
  for (double cut : cuts) {
    std::vector<Region> next;
    for (const Region& piece : pieces)
      for (bool left : {true, false})
        for (Region& part : clip_region(piece, left_of(cut), left)) next.push_back(std::move(part));
    pieces = std::move(next);
  }
  return pieces;
}

// `value` times `scale`, rounded to `decimals` as a file with that many decimals writes it.
double rounded(double value, double scale = 1.0, int decimals = 7) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, scale * value);
  return std::strtod(text, nullptr);
}

Ring2 rounded_ring(const Ring2& ring, double scale = 1.0, int decimals = 7) {
  Ring2 out;
  for (const Vec2& p : ring)
    out.emplace_back(rounded(p.x(), scale, decimals), rounded(p.y(), scale, decimals));
  return out;
}

// Intended areas of the two materials (before rounding to decimals), mm².
std::map<int, double> material_areas() {
  std::map<int, double> areas;
  for (int label : {1, 2})
    for (const Region& piece : disc_part(label)) areas[label] += std::abs(signed_area(piece.outer));
  return areas;
}

// A stack of z-slices through a disc of material 1 above a wavy line and 2 below it; a
// labelling tool emits each material as tiles cut at vertical lines (their position drifts from
// slice to slice), which puts tile corners on the other material's wavy edge. Coordinates are
// rounded to 7 decimals, as a file writes them. With `scale`, every length is multiplied by it
// and rounded to `decimals` (a set in metres: 1e-3 and 10; in micrometres: 1e3 and 4).
SliceSet wavy_disc_set(double scale = 1.0, int decimals = 7) {
  SliceSet set;
  set.labels = {{1, "upper"}, {2, "lower"}};
  set.bounds = Box3{scale * Vec3(-12.0, -12.0, -kBoxGap),
                    scale * Vec3(12.0, 12.0, (kSlices - 1) * kSpacing + kBoxGap)};
  for (int i = 0; i < kSlices; ++i) {
    LabeledSlice slice;
    slice.origin_mm = Vec3(0.0, 0.0, scale * i * kSpacing);
    for (const auto& [label, pieces] :
         {std::pair{1, split(disc_part(1), {3.9 + 0.0131 * i})},
          {2, split(disc_part(2), {-4.3 + 0.0173 * i, 0.37 + 0.0119 * i})}})
      for (const Region& piece : pieces) {
        Region region;
        region.label = label;
        region.outer = rounded_ring(piece.outer, scale, decimals);
        for (const Ring2& hole : piece.holes)
          region.holes.push_back(rounded_ring(hole, scale, decimals));
        slice.regions.push_back(std::move(region));
      }
    set.slices.push_back(std::move(slice));
  }
  return set;
}

std::string fixed7(double value, int decimals = 7) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

// The set as a .slices.json file writes it with 7 decimals (or `decimals`).
std::string json_7_decimals(const SliceSet& set, int decimals = 7) {
  auto fixed7 = [decimals](double value) { return rounding_overlap_test::fixed7(value, decimals); };
  auto ring_text = [&](const Ring2& ring) {
    std::string out = "[";
    for (std::size_t k = 0; k < ring.size(); ++k)
      out += (k ? ", [" : "[") + fixed7(ring[k].x()) + ", " + fixed7(ring[k].y()) + "]";
    return out + "]";
  };
  auto vec_text = [&](const Vec3& v) {
    return "[" + fixed7(v.x()) + ", " + fixed7(v.y()) + ", " + fixed7(v.z()) + "]";
  };
  std::string out = R"({"format": "sonoshape-slices", "version": 1, "units": "mm",
    "labels": [{"id": 1, "name": "upper"}, {"id": 2, "name": "lower"}],
    "bounds": {"min": )" +
                    vec_text(set.bounds->min) + ", \"max\": " + vec_text(set.bounds->max) +
                    "}, \"slices\": [";
  for (std::size_t i = 0; i < set.slices.size(); ++i) {
    const LabeledSlice& s = set.slices[i];
    out += std::string(i ? ",\n" : "\n") + "{\"origin\": [0, 0, " + fixed7(s.origin_mm.z()) +
           "], \"u\": [1, 0, 0], \"v\": [0, 1, 0], \"regions\": [";
    for (std::size_t j = 0; j < s.regions.size(); ++j)
      out += std::string(j ? ", " : "") + "{\"label\": " + std::to_string(s.regions[j].label) +
             ", \"polygon\": " + ring_text(s.regions[j].outer) + "}";
    out += "]}";
  }
  return out + "]}";
}

// The set as a .csl contour file writes it: 3D vertices with 7 decimals, one component per region.
std::string csl_7_decimals(const SliceSet& set) {
  std::ostringstream out;  // a stream: GCC 12 warns (-Wrestrict) on "text" + std::string chains
  out << "CSLC\n" << set.slices.size() << " 3\n";
  for (std::size_t i = 0; i < set.slices.size(); ++i) {
    const LabeledSlice& s = set.slices[i];
    std::size_t vertices = 0;
    for (const Region& r : s.regions) vertices += r.outer.size();
    out << "\n"
        << i + 1 << " " << vertices << " " << s.regions.size() << " 0 0 1 "
        << fixed7(-s.origin_mm.z()) << "\n";
    std::ostringstream components;
    std::size_t next = 0;
    for (const Region& r : s.regions) {
      components << r.outer.size() << " " << r.label;
      for (const Vec2& p : r.outer) {
        const Vec3 w = s.to_world(p);
        out << fixed7(w.x()) << " " << fixed7(w.y()) << " " << fixed7(w.z()) << "\n";
        components << " " << next++;
      }
      components << "\n";
    }
    out << components.str();
  }
  return out.str();
}

// Pairs of regions that the validation refuses as overlapping, counted slice by slice (the
// validation message of a whole set stops at 20 problems).
int overlapping_pairs(const SliceSet& set, std::string* first_message = nullptr) {
  int count = 0;
  for (const LabeledSlice& slice : set.slices) {
    SliceSet one;
    one.slices = {slice};
    const Status status = validate_slice_set(one, "one");
    const std::string message = status.message();
    for (std::size_t at = message.find(" overlap by "); at != std::string::npos;
         at = message.find(" overlap by ", at + 1))
      ++count;
    if (!status && first_message && first_message->empty()) *first_message = message;
  }
  return count;
}

TEST(RoundingOverlap, GeneratedSetOverlapsAlongSharedEdges) {
  const SliceSet set = wavy_disc_set();
  std::string message;
  const int pairs = overlapping_pairs(set, &message);
  // 3 T-junctions per slice; rounding moves each to one side of the edge or the other.
  EXPECT_GE(pairs, 5);
  EXPECT_LE(pairs, 3 * kSlices);
  EXPECT_NE(message.find("thinner than the rounding tolerance"), std::string::npos) << message;
}

TEST(RoundingOverlap, ReaderSnapsThemAndRecordsRepairs) {
  const SliceSet rounded = wavy_disc_set();
  const int pairs = overlapping_pairs(rounded);
  const auto read = parse_slice_set_json(json_7_decimals(rounded), "wavy.slices.json");
  ASSERT_TRUE(read) << read.message();
  // A corner on a shared edge overlaps the regions on both sides of it; one snap clears both.
  EXPECT_GE(2 * static_cast<int>(read->repairs.size()), pairs);
  EXPECT_LE(static_cast<int>(read->repairs.size()), pairs);
  const std::regex where(R"(slice \d+, region \d+ \(label [12]\) and region \d+ \(label [12]\))");
  for (const Repair& repair : read->repairs) {
    EXPECT_EQ(repair.kind, "rounding_overlap");
    EXPECT_TRUE(std::regex_match(repair.where, where)) << repair.where;
    EXPECT_GT(repair.area_changed_mm2, 0.0);
    EXPECT_LT(repair.area_changed_mm2, 1e-6) << repair.detail;  // ~1e-8: 7 decimals
    EXPECT_NE(repair.detail.find("around ("), std::string::npos) << repair.detail;
  }
  // Snapped: no overlap left, also once written as doubles and read back (no second repair).
  EXPECT_TRUE(validate_slice_set(*read, "snapped"))
      << validate_slice_set(*read, "snapped").message();
  EXPECT_EQ(overlapping_pairs(*read), 0);
  const std::string path = ::testing::TempDir() + "snapped.slices.json";
  ASSERT_TRUE(write_slice_set_json(*read, path));
  const auto again = read_slice_set(path);
  ASSERT_TRUE(again) << again.message();
  EXPECT_TRUE(again->repairs.empty());
}

TEST(RoundingOverlap, CslReaderSnapsThemToo) {
  const auto read = parse_csl(csl_7_decimals(wavy_disc_set()), "wavy.csl");
  ASSERT_TRUE(read) << read.message();
  int snapped = 0;
  for (const Repair& repair : read->repairs)
    if (repair.kind == "rounding_overlap") {
      ++snapped;
      EXPECT_NE(repair.where.find("plane "), std::string::npos) << repair.where;
      EXPECT_LT(repair.area_changed_mm2, 1e-6) << repair.detail;
    }
  EXPECT_GE(snapped, 5);
  EXPECT_TRUE(validate_slice_set(*read, "snapped"));
}

TEST(RoundingOverlap, StrictRefusesNamingSliceAndRegions) {
  const auto read =
      parse_slice_set_json(json_7_decimals(wavy_disc_set()), "wavy.slices.json", ReadOptions{true});
  ASSERT_FALSE(read);
  const std::regex names(
      R"(wavy\.slices\.json: slice \d+, region \d+ \(label [12]\) and region \d+ )"
      R"(\(label [12]\): overlap of .*--strict)");
  EXPECT_TRUE(std::regex_search(read.message(), names)) << read.message();
}

// Two squares of one slice overlapping in [x0, 5] x [0, 1]; a location must fall inside it.
void expect_real_overlap(double x0, const std::string& area_text) {
  const std::string text = R"({"format": "sonoshape-slices", "version": 1, "slices": [
    {"origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], "regions": [
      {"label": 1, "polygon": [[0, 0], [5, 0], [5, 1], [0, 1]]},
      {"label": 2, "polygon": [[)" +
                           std::to_string(x0) + R"(, 0], [9, 0], [9, 1], [)" + std::to_string(x0) +
                           R"(, 1]]}]}]})";
  const auto read = parse_slice_set_json(text, "squares.slices.json");
  ASSERT_FALSE(read);
  const std::string& message = read.message();
  EXPECT_NE(message.find("squares.slices.json: slice 0: region 0 (label 1) and region 1 "
                         "(label 2) overlap by " +
                         area_text),
            std::string::npos)
      << message;
  std::smatch at;
  ASSERT_TRUE(std::regex_search(message, at, std::regex(R"(around \(([-0-9.e]+), ([-0-9.e]+)\))")))
      << message;
  const double x = std::stod(at[1].str()), y = std::stod(at[2].str());
  EXPECT_GT(x, x0);
  EXPECT_LT(x, 5.0);
  EXPECT_GT(y, 0.0);
  EXPECT_LT(y, 1.0);
  EXPECT_EQ(message.find("rounding tolerance"), std::string::npos) << message;
}

TEST(RoundingOverlap, RealOverlapsStayErrorsWithAreaAndLocation) {
  expect_real_overlap(4.0, "1 ");      // 1 mm²
  expect_real_overlap(4.99, "0.01 ");  // a thin band, but 0.01 mm is no rounding of a 9 mm slice
}

TEST(RoundingOverlap, SnappedSetReconstructsToTheIntendedPrisms) {
  const auto read = parse_slice_set_json(json_7_decimals(wavy_disc_set()), "wavy.slices.json");
  ASSERT_TRUE(read) << read.message();
  recon::ReconstructionOptions options;
  options.threads = 2;
  MeshSet meshes;
  ASSERT_NO_THROW(meshes = recon::reconstruct(*read, options));
  const std::map<int, double> areas = material_areas();
  ASSERT_EQ(meshes.meshes.size(), 2u);
  for (const MeshSet::Entry& entry : meshes.meshes) {
    SCOPED_TRACE("label " + std::to_string(entry.label));
    EXPECT_TRUE(check_mesh_health(entry.mesh).closed_manifold_oriented());
    // The end slices say inside, the box faces outside: the prism ends halfway between them.
    const double intended = areas.at(entry.label) * ((kSlices - 1) * kSpacing + kBoxGap);
    const double volume = signed_volume(entry.mesh);
    std::printf("label %d: volume %.2f mm^3, intended prism %.2f mm^3 (ratio %.4f)\n", entry.label,
                volume, intended, volume / intended);
    EXPECT_NEAR(volume / intended, 1.0, 0.03);
  }
}

// The rounding tolerance is relative to the slice's extent, not 1e-6 in the file's units
// (scripts/mutate: rounding-tolerance-absolute): the same set in micrometres, written with the
// same relative precision (4 decimals), is snapped as the set in mm is; in metres (10 decimals)
// too, and an overlap of 8e-6 of the slice's extent stays an error there as it does in mm.
TEST(RoundingOverlap, TheToleranceScalesWithTheSetInMetresOrMicrometres) {
  for (const auto& [scale, decimals] : {std::pair{1e3, 4}, std::pair{1e-3, 10}}) {
    SCOPED_TRACE("scale " + std::to_string(scale));
    const SliceSet set = wavy_disc_set(scale, decimals);
    EXPECT_GE(overlapping_pairs(set), 5);
    const auto read = parse_slice_set_json(json_7_decimals(set, decimals), "wavy.slices.json");
    ASSERT_TRUE(read) << read.message();
    EXPECT_GE(read->repairs.size(), 3u);
    EXPECT_EQ(overlapping_pairs(*read), 0);
  }
  // Two squares of 0.01 a side (metres) overlapping by 2e-7: no rounding of 7 or more digits.
  const std::string text = R"({"format": "sonoshape-slices", "version": 1, "slices": [
    {"origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], "regions": [
      {"label": 1, "polygon": [[0, 0], [0.01, 0], [0.01, 0.01], [0, 0.01]]},
      {"label": 2, "polygon": [[0.0099998, 0], [0.02, 0], [0.02, 0.01], [0.0099998, 0.01]]}]}]})";
  const auto metres = parse_slice_set_json(text, "metres.slices.json");
  ASSERT_FALSE(metres);
  EXPECT_NE(metres.message().find("overlap by"), std::string::npos) << metres.message();
}

}  // namespace
}  // namespace sonoshape::rounding_overlap_test
