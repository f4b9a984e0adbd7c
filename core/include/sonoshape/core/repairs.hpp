#pragma once
// What a reader changed in its input to make it usable. Real data (public .csl datasets, PLUS and
// Slicer recordings) come with pinched contours, flipped plane equations and rounding overlaps;
// readers repair what has one meaning, keep a record of it with the data (so commands can report
// it in --stats and scan.json) and, with ReadOptions::strict, refuse instead.
#include <string>
#include <vector>

namespace sonoshape {

/// One repair of input data.
struct Repair {
  /// Stable identifier a program can branch on, e.g. "self_intersection", "plane_refit",
  /// "rounding_overlap", "repeated_points", "off_plane_vertices", "duplicate_slice"
  /// (docs/formats/slices.md lists them all).
  std::string kind;
  /// The element as messages name it ("plane 12 (line 3456), component 2"); empty for the file.
  std::string where;
  /// What was found and what was done, in words.
  std::string detail;
  /// Area of the plane whose material changed by the repair (0 when none did), in mm² (or the
  /// file's units squared).
  double area_changed_mm2 = 0.0;
};

/// How readers treat input they can repair.
struct ReadOptions {
  /// Refuse instead of repairing: the first repair becomes an error naming the element.
  bool strict = false;
};

}  // namespace sonoshape
