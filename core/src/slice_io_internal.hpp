#pragma once
// Internal helpers shared by the slice-set readers (slice_io.cpp, csl_io.cpp). No CGAL types here:
// the exact-predicate work lives in slice_io.cpp.
#include <cstddef>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "sonoshape/core/repairs.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::detail {

/// Two points of a ring closer than this fraction of the ring's size count as the same point.
constexpr double kRepeatedPointRelTol = 1e-9;
/// u and v must be unit and orthogonal to this tolerance.
constexpr double kBasisTol = 1e-6;
/// Coincident slices: normals parallel to 1e-9, offsets equal to 1e-9 of the set's size.
constexpr double kCoincidentTol = 1e-9;
/// Two regions of one slice whose overlap is at most this fraction of the slice's extent (the
/// bounding-box diagonal of its regions) thick (2·area/perimeter of each component) share an
/// edge that rounding moved apart: a set cut by a polygon library and written with 7 decimals
/// overlaps by about 1e-8 along such edges.
constexpr double kRoundingOverlapRelTol = 1e-6;

/// How messages name slices, regions and rings. The JSON reader uses the defaults ("slice 3,
/// region 1 (label 2), hole 0"); the .csl reader names planes and components instead, so a user
/// can find the line to fix.
class SliceNaming {
 public:
  virtual ~SliceNaming() = default;
  virtual std::string slice(std::size_t slice) const;
  virtual std::string region(std::size_t slice, std::size_t region, int label) const;
  virtual std::string outer(std::size_t slice, std::size_t region, int label) const;
  virtual std::string hole(std::size_t slice, std::size_t region, int label,
                           std::size_t hole) const;
};

/// Thrown by RepairLog::add under ReadOptions::strict; the readers turn it into their Status.
struct RepairRefused {
  std::string message;
};

/// Collects a reader's repairs: the records for SliceSet::repairs, one warning per slice on
/// stderr when finished, and under ReadOptions::strict an error at the first repair.
class RepairLog {
 public:
  RepairLog(std::string source_name, const ReadOptions& options)
      : source_name_(std::move(source_name)), strict_(options.strict) {}

  /// Records a repair of the slice named `slice_name` ("" when it concerns the whole file).
  /// Strict: throws RepairRefused naming the file, the element and the way out.
  void add(const std::string& slice_name, Repair repair);
  /// Prints the warnings (one line per slice, slices in the order first repaired) and hands the
  /// records over.
  std::vector<Repair> finish();

 private:
  std::string source_name_;
  bool strict_ = false;
  std::vector<std::pair<std::string, Repair>> repairs_;  // (slice name, repair) in order
};

/// "unknown" or the id as text.
std::string label_text(int label);

/// Bounding-box diagonal of a ring (0 for fewer than 2 points).
double ring_size(const Ring2& ring);

/// Drops consecutive repeated points (closer than kRepeatedPointRelTol * ring size), including a
/// last point that repeats the first. Returns how many points were dropped.
std::size_t drop_repeated_points(Ring2& ring);

/// Empty when `ring` (free of repeated consecutive points) is a usable polygon: finite, at least 3
/// distinct points, simple (exact predicates), non-zero area. Otherwise what is wrong and the fix.
std::string ring_problem(const Ring2& ring);

/// What check_ring found: the readers repair a ring whose only fault is that it crosses itself.
struct RingCheck {
  std::string problem;           ///< empty when the ring is usable; else ring_problem's text
  bool self_intersects = false;  ///< the fault is that the ring crosses or touches itself
  Vec2 crossing = Vec2::Zero();  ///< then a point where it does
};

/// ring_problem, telling a self-intersection apart from the other faults.
RingCheck check_ring(const Ring2& ring);

/// One ring of a repaired contour. Depth 0 is an outer boundary of what the contour encloses,
/// depth 1 a hole in the ring `parent`, depth 2 an island in that hole, and so on.
struct NestedRing {
  Ring2 ring;
  std::size_t depth = 0;
  std::size_t parent = 0;  ///< index in ContourRepair::rings of the enclosing ring (depth > 0)
};

/// The simple polygons a self-intersecting contour encloses.
struct ContourRepair {
  std::vector<NestedRing> rings;  ///< parents before their children; empty: encloses no area
  /// Area (the ring's units squared) where the non-zero and even-odd rules disagree: covered
  /// twice or more by the contour, so the choice of rule decided it.
  double area_changed = 0.0;
  /// How many rings are outer boundaries (even depth).
  std::size_t polygons() const;
};

/// The region that `ring` (at least 3 points) encloses by the non-zero winding rule, as simple,
/// strictly non-touching rings (Clipper's union). Corners of `ring` keep their exact coordinates;
/// new corners (where the ring crosses itself) are computed to 1e-12 of the ring's size. Meant
/// for rings check_ring reports as self-intersecting.
ContourRepair repair_contour(const Ring2& ring);

/// The record of a repair_contour: kind "self_intersection", `where` the ring as messages name
/// it, `crossing` the point where it crossed itself as text, `hole` whether the ring is a hole.
Repair self_intersection_repair(const std::string& where, const std::string& crossing,
                                const ContourRepair& result, bool hole);

/// True when `inner` lies inside the closed region bounded by `outer` (exact predicates). Meant
/// for rings that do not cross each other: it decides by the first vertex of `inner` that is not
/// on the boundary of `outer`; when every vertex is on it, by their exact difference.
bool ring_inside_ring(const Ring2& inner, const Ring2& outer);

/// Pairs (earlier, later) of coincident slices whose contents are identical.
using SlicePairs = std::vector<std::pair<std::size_t, std::size_t>>;

/// Regions `a` < `b` of slice `slice`.
struct RegionPair {
  std::size_t slice = 0, a = 0, b = 0;
};
using RegionPairs = std::vector<RegionPair>;

/// validate_slice_set with the naming of the caller's format. Identical coincident slices are not
/// an error: they are returned in `identical` (when non-null) for the reader to merge. With
/// `thin_overlaps`, overlaps no thicker than kRoundingOverlapRelTol of the slice's extent are not
/// errors either: they are returned there for the reader to snap.
Status validate_slice_set_named(const SliceSet& set, const std::string& source_name,
                                const SliceNaming& naming, SlicePairs* identical,
                                RegionPairs* thin_overlaps = nullptr);

/// Snaps the given pairs of regions (valid regions whose overlap validate_slice_set_named found
/// thin): vertices of the later region within kRoundingOverlapRelTol of the slice's extent of the
/// earlier one's vertices move onto them, and each region's vertices that near the other's edges
/// are inserted into those edges, so the two share the edge exactly. A pair is changed only when
/// the result no longer overlaps under the exact test. Records a "rounding_overlap" repair per
/// snapped pair (RepairRefused under strict).
void snap_rounding_overlaps(SliceSet& set, const RegionPairs& pairs, const SliceNaming& naming,
                            RepairLog& repairs);

/// Drops the later slice of each identical pair, recording a repair naming both.
void merge_identical_slices(SliceSet& set, const SlicePairs& identical, const SliceNaming& naming,
                            RepairLog& repairs);

/// The common end of both readers: validates a parsed set, merges slices given twice and hands
/// the repairs over to SliceSet::repairs (printing their warnings).
Result<SliceSet> finish_parsed_set(SliceSet set, const std::string& source_name,
                                   const SliceNaming& naming, RepairLog& repairs);

/// Whole-file helpers: read text (errors name the path) and write text.
Result<std::string> read_text_file(const std::filesystem::path& path);
Status write_text_file(const std::filesystem::path& path, const std::string& text);

/// Shortest decimal text that reads back as the same double.
std::string format_double(double value);

/// `value` to 7 significant digits, for places and areas in messages ("56028.62").
std::string format_short(double value);

}  // namespace sonoshape::detail
