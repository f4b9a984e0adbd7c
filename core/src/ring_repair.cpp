// Repair of contours that cross themselves: the simple polygons a contour encloses, by Clipper's
// union with the non-zero fill rule.
#include "ring_repair.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <polyclipping/clipper.hpp>
#include <utility>

#include "ring_checks.hpp"
#include "text_io.hpp"

namespace sonoshape::detail {
namespace {

// Clipper works on 64-bit integers. Coordinates are taken relative to the ring's box centre and
// scaled so that the ring's size maps to 1e12 units: 1e-12 relative precision, far inside
// Clipper's range (about 4.6e18) and exact in a double on the way back (below 2^53).
constexpr double kUnitsPerSize = 1e12;

struct Frame {
  Vec2 centre = Vec2::Zero();
  double scale = 1.0;  // Clipper units per unit of the ring's coordinates
  // The ring's own points by their Clipper coordinates: output corners that are input corners
  // get their exact coordinates back, so that they still coincide with other contours sharing
  // them (Abdomen traces its organs' outlines again as holes of the body).
  std::map<std::pair<ClipperLib::cInt, ClipperLib::cInt>, Vec2> exact;

  ClipperLib::IntPoint to_clipper(const Vec2& p) const {
    const Vec2 q = (p - centre) * scale;
    return {static_cast<ClipperLib::cInt>(std::llround(q.x())),
            static_cast<ClipperLib::cInt>(std::llround(q.y()))};
  }
  Vec2 from_clipper(const ClipperLib::IntPoint& q) const {
    if (const auto it = exact.find({q.X, q.Y}); it != exact.end()) return it->second;
    return centre + Vec2(static_cast<double>(q.X), static_cast<double>(q.Y)) / scale;
  }
};

Frame frame_of(const Ring2& ring) {
  Vec2 lo = ring.front();
  Vec2 hi = ring.front();
  for (const Vec2& p : ring) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  Frame frame;
  frame.centre = 0.5 * (lo + hi);
  frame.scale = kUnitsPerSize / std::max((hi - lo).norm(), std::numeric_limits<double>::min());
  return frame;
}

// Walks Clipper's tree of outer boundaries and holes, parents before children. Rings whose area
// is below `min_area` (Clipper units²) are left out with everything inside them: they are what
// rounding to the integer grid leaves of a zero-width fold.
void flatten(const ClipperLib::PolyNode& node, std::size_t depth, std::optional<std::size_t> parent,
             const Frame& frame, double min_area, ContourRepair& out, double& nonzero_area) {
  const double area = std::abs(ClipperLib::Area(node.Contour));
  if (area <= min_area) return;
  NestedRing nested;
  nested.depth = depth;
  nested.parent = parent.value_or(0);
  nested.ring.reserve(node.Contour.size());
  for (const ClipperLib::IntPoint& q : node.Contour) nested.ring.push_back(frame.from_clipper(q));
  drop_repeated_points(nested.ring);
  out.rings.push_back(std::move(nested));
  nonzero_area += (depth % 2 == 0 ? area : -area);
  const std::size_t self = out.rings.size() - 1;
  for (const ClipperLib::PolyNode* child : node.Childs)
    flatten(*child, depth + 1, self, frame, min_area, out, nonzero_area);
}

}  // namespace

std::size_t ContourRepair::polygons() const {
  return static_cast<std::size_t>(std::count_if(
      rings.begin(), rings.end(), [](const NestedRing& r) { return r.depth % 2 == 0; }));
}

ContourRepair repair_contour(const Ring2& ring) {
  ContourRepair out;
  if (ring.size() < 3) return out;
  Frame frame = frame_of(ring);
  ClipperLib::Path path;
  path.reserve(ring.size());
  for (const Vec2& p : ring) {
    path.push_back(frame.to_clipper(p));
    frame.exact.try_emplace({path.back().X, path.back().Y}, p);
  }

  // Non-zero, not even-odd: the region a contour encloses is where its winding number is not
  // zero. A segmentation's outline that loops over itself (a small loop, a pinch traced twice)
  // covers that area twice, winding number 2, and even-odd would punch a hole there that nobody
  // drew. Strictly simple output splits rings that touch themselves at a point (a pinch) into
  // separate rings, as the slice-set rules want.
  ClipperLib::PolyTree tree;
  {
    ClipperLib::Clipper clipper;
    clipper.StrictlySimple(true);
    clipper.AddPath(path, ClipperLib::ptSubject, true);
    clipper.Execute(ClipperLib::ctUnion, tree, ClipperLib::pftNonZero, ClipperLib::pftNonZero);
  }
  // Same threshold as ring_problem's zero-area test: 1e-12 of the ring's size squared.
  const double min_area = 1e-12 * kUnitsPerSize * kUnitsPerSize;
  double nonzero_area = 0.0;
  for (const ClipperLib::PolyNode* child : tree.Childs)
    flatten(*child, 0, std::nullopt, frame, min_area, out, nonzero_area);

  // The two rules disagree exactly where the winding number is even and not zero (covered twice,
  // four times, ...); even-odd's area is contained in non-zero's, so the difference is that area.
  ClipperLib::Paths even_odd;
  {
    ClipperLib::Clipper clipper;
    clipper.AddPath(path, ClipperLib::ptSubject, true);
    clipper.Execute(ClipperLib::ctUnion, even_odd, ClipperLib::pftEvenOdd, ClipperLib::pftEvenOdd);
  }
  double even_odd_area = 0.0;
  for (const ClipperLib::Path& p : even_odd) even_odd_area += ClipperLib::Area(p);
  out.area_changed =
      std::max(0.0, nonzero_area - std::abs(even_odd_area)) / (frame.scale * frame.scale);
  return out;
}

Repair self_intersection_repair(const std::string& where, const std::string& crossing,
                                const ContourRepair& result, bool hole) {
  const std::size_t n = result.polygons();
  std::string done;
  if (result.rings.empty()) {
    done = "it encloses no area; dropped it";
  } else {
    std::size_t holes = result.rings.size() - n;
    done = "repaired into " + std::to_string(n) + " simple polygon" + (n == 1 ? "" : "s");
    if (holes) done += " with " + std::to_string(holes) + " hole" + (holes == 1 ? "" : "s");
    done += " by the non-zero rule";
    if (hole) done += " (the area the hole cuts out)";
    // What the choice of rule decided: even-odd would have left this out.
    if (result.area_changed > 0.0)
      done += "; an area of " + format_short(result.area_changed) +
              " that it covers more than once stays inside (even-odd would cut it out)";
    else
      done += "; area changed: 0 (no part is covered twice)";
  }
  return {"self_intersection", where, "contour crosses itself at " + crossing + "; " + done,
          result.area_changed};
}

}  // namespace sonoshape::detail
