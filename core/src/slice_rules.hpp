#pragma once
// The rules of docs/formats/slices.md ("What a reader rejects"), one named check each
// (slice_rules.cpp), shared by every slice-set reader (JSON, .csl) and by validate_slice_set;
// and the common end of the readers: validate, snap rounding overlaps, merge slices given twice.
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "repair_log.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::detail {

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

/// Drops the later slice of each identical pair, recording a repair naming both.
void merge_identical_slices(SliceSet& set, const SlicePairs& identical, const SliceNaming& naming,
                            RepairLog& repairs);

/// The common end of both readers: validates a parsed set, merges slices given twice and hands
/// the repairs over to SliceSet::repairs (printing their warnings).
Result<SliceSet> finish_parsed_set(SliceSet set, const std::string& source_name,
                                   const SliceNaming& naming, RepairLog& repairs);

}  // namespace sonoshape::detail
