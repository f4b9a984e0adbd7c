#include "sonoshape/segmentation/contours.hpp"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Constrained_triangulation_plus_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polyline_simplification_2/simplify.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <string>
#include <unordered_set>
#include <utility>

#include "parallel.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/slice_io.hpp"

namespace sonoshape::segmentation {
namespace {

// The masks are traced at this many times their resolution (see trace_mask).
constexpr int kUpsample = 2;

namespace PS = CGAL::Polyline_simplification_2;
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Tds =
    CGAL::Triangulation_data_structure_2<PS::Vertex_base_2<Kernel>,
                                         CGAL::Constrained_triangulation_face_base_2<Kernel>>;
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<Kernel, Tds, CGAL::Exact_predicates_tag>;
using Ct = CGAL::Constrained_triangulation_plus_2<Cdt>;

// One region in pixel coordinates (column, row) before it is mapped into the plane.
struct PixelRegion {
  int label = 0;
  Ring2 outer;
  std::vector<Ring2> holes;
};

// Removes pinches: where a 2x2 block holds exactly one of its diagonals, the outline would pass
// through the block's centre twice. One pixel of the pair goes (the lower one), which leaves
// the block with a single pixel and cannot create a pinch in a block already visited, so one
// raster pass leaves none (the mask is "well-composed": its 4- and 8-components agree and its
// boundaries are simple curves that touch neither themselves nor each other).
void remove_pinches(cv::Mat& mask) {
  for (int j = 0; j + 1 < mask.rows; ++j) {
    std::uint8_t* top = mask.ptr<std::uint8_t>(j);
    std::uint8_t* bottom = mask.ptr<std::uint8_t>(j + 1);
    for (int i = 0; i + 1 < mask.cols; ++i) {
      const bool a = top[i], b = top[i + 1], c = bottom[i], d = bottom[i + 1];
      if (a && d && !b && !c)
        bottom[i + 1] = 0;
      else if (b && c && !a && !d)
        bottom[i] = 0;
    }
  }
}

// Drops repeated points and the corners of straight runs: what is left are the ring's turns.
void keep_turns(Ring2& ring) {
  Ring2 kept;
  kept.reserve(ring.size());
  for (const Vec2& p : ring)
    if (kept.empty() || p != kept.back()) kept.push_back(p);
  while (kept.size() > 1 && kept.front() == kept.back()) kept.pop_back();
  ring.clear();
  const std::size_t n = kept.size();
  for (std::size_t k = 0; k < n; ++k) {
    const Vec2& a = kept[(k + n - 1) % n];
    const Vec2& b = kept[k];
    const Vec2& c = kept[(k + 1) % n];
    const bool straight = (a.x() == b.x() && b.x() == c.x()) || (a.y() == b.y() && b.y() == c.y());
    if (!straight || n < 4) ring.push_back(b);
  }
}

// The outlines of a well-composed mask, in pixel coordinates, on the pixels' edges (pixel (i, j)
// covers [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5]). cv::findContours runs through the centres of
// boundary pixels, so a one-pixel neck or line would give a ring of zero width; on the mask
// upsampled by 2 (each pixel a 2x2 block) every boundary pixel is a quadrant of a pixel, and the
// quadrant's outer corner is a corner of the pixel's edges that lies on the outline (a concave
// corner's diagonal step joins two quadrants of that same corner): the rings are the exact
// outlines of the pixels. Neighbouring labels share their edges; rings of one label touch
// neither themselves nor each other (the mask is well-composed).
// `mask` may be a part of the image whose top-left pixel is `origin`, with nothing set outside
// it: the rings are those of the whole image (findContours meets them in the same order).
std::vector<PixelRegion> trace_mask(const cv::Mat& mask, int label, cv::Point origin) {
  cv::Mat up;
  cv::resize(mask, up, cv::Size(), kUpsample, kUpsample, cv::INTER_NEAREST);
  cv::copyMakeBorder(up, up, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  std::vector<std::vector<cv::Point>> contours;
  std::vector<cv::Vec4i> hierarchy;  // next, previous, first child, parent
  cv::findContours(up, contours, hierarchy, cv::RETR_CCOMP, cv::CHAIN_APPROX_SIMPLE,
                   origin * kUpsample);
  auto to_ring = [&](const std::vector<cv::Point>& contour) {
    Ring2 ring;
    ring.reserve(contour.size());
    // Upsampled column x (1 of border) is quadrant (x - 1) % 2 of pixel (x - 1) / 2: its outer
    // edge is the pixel's left one, at (x - 1) / 2 - 0.5, for the left quadrant (x odd) and the
    // right one, at (x - 1) / 2 + 0.5, for the right quadrant: x / 2 - 0.5 in both cases.
    auto edge = [](int x) { return x / kUpsample - 0.5; };
    for (const cv::Point& p : contour) ring.emplace_back(edge(p.x), edge(p.y));
    keep_turns(ring);
    return ring;
  };
  std::vector<PixelRegion> regions;
  for (std::size_t k = 0; k < contours.size(); ++k) {
    if (hierarchy[k][3] >= 0) continue;  // a hole: taken with its outer ring
    PixelRegion region{label, to_ring(contours[k]), {}};
    for (int child = hierarchy[k][2]; child >= 0;
         child = hierarchy[static_cast<std::size_t>(child)][0])
      region.holes.push_back(to_ring(contours[static_cast<std::size_t>(child)]));
    regions.push_back(std::move(region));
  }
  return regions;
}

// Pixel-edge corners as keys: coordinates are half pixels, exact in 2 x 32 bits.
using CornerSet = std::unordered_set<std::uint64_t>;
std::uint64_t corner_key(const Vec2& p) {
  const auto x = static_cast<std::uint32_t>(std::lround(2.0 * p.x()) + (1 << 30));
  const auto y = static_cast<std::uint32_t>(std::lround(2.0 * p.y()) + (1 << 30));
  return (std::uint64_t{x} << 32) | y;
}

// The pixel corners that smooth_outline must keep: where three values (labels, or outside the
// sector or the image) meet, and around every 2x2 block that holds one label on a diagonal
// alone, whose pixel remove_pinches takes from that label's mask only: there the traced rings
// of two neighbouring labels need not turn alike, so a cut could make them overlap.
CornerSet junction_corners(const cv::Mat& map, const cv::Mat& in_sector) {
  auto value = [&](int i, int j) -> int {
    if (i < 0 || j < 0 || i >= map.cols || j >= map.rows || !in_sector.at<std::uint8_t>(j, i))
      return -1;
    return map.at<std::uint8_t>(j, i);
  };
  CornerSet junctions;
  for (int cj = 0; cj <= map.rows; ++cj)
    for (int ci = 0; ci <= map.cols; ++ci) {
      // The block whose centre is corner (ci - 0.5, cj - 0.5): a b / c d.
      const int a = value(ci - 1, cj - 1), b = value(ci, cj - 1);
      const int c = value(ci - 1, cj), d = value(ci, cj);
      const int distinct = 1 + (b != a) + (c != a && c != b) + (d != a && d != b && d != c);
      const bool pinch = (a == d && b != a && c != a) || (b == c && a != b && d != b);
      if (pinch) {
        for (int dj = -1; dj <= 1; ++dj)
          for (int di = -1; di <= 1; ++di)
            junctions.insert(corner_key(Vec2(ci + di - 0.5, cj + dj - 0.5)));
      } else if (distinct >= 3) {
        junctions.insert(corner_key(Vec2(ci - 0.5, cj - 0.5)));
      }
    }
  return junctions;
}

// OutlineForm::kSmooth on one ring of turns (axis-parallel edges between pixel corners). The
// ring becomes the midpoints of its unit edges (the marching-squares outline of the mask; the
// junctions stay as corners), which is then smoothed by a few Taubin steps (a Laplacian step
// and a negative one, so that a convex outline does not shrink), each point kept within
// kSmoothReachPx of where it started. Rings that share a chain of edges see the same points
// on it, whose neighbours are the same or junctions, so they are smoothed alike and keep
// sharing it.
constexpr int kSmoothSteps = 4;          // pairs of Taubin steps: about 3 px along the outline
constexpr double kSmoothReachPx = 0.35;  // two sides of a one-pixel neck stay apart
void smooth_outline(Ring2& ring, const CornerSet& junctions) {
  const std::size_t n = ring.size();
  if (n < 4) return;
  Ring2 points;
  std::vector<char> fixed;
  for (std::size_t k = 0; k < n; ++k) {
    const Vec2& corner = ring[k];
    const Vec2& next = ring[(k + 1) % n];
    const Vec2 step = next - corner;
    const auto units = static_cast<int>(std::lround(step.norm()));
    const Vec2 unit = step / units;  // exact: an axis direction
    for (int m = 0; m < units; ++m) {
      // A junction on a straight run (a third label meets this ring's edge) stays too: the
      // neighbouring ring that turns there has it, and both must smooth from the same points.
      if (const Vec2 c = corner + m * unit; junctions.count(corner_key(c))) {
        points.push_back(c);
        fixed.push_back(1);
      }
      points.push_back(corner + (m + 0.5) * unit);
      fixed.push_back(0);
    }
  }
  const Ring2 start = points;
  const std::size_t count = points.size();
  Ring2 moved(count);
  for (int step = 0; step < 2 * kSmoothSteps; ++step) {
    const double factor = step % 2 == 0 ? 0.5 : -0.53;  // Taubin's lambda and mu
    for (std::size_t k = 0; k < count; ++k) {
      if (fixed[k]) {
        moved[k] = points[k];
        continue;
      }
      const Vec2 mean = 0.5 * (points[(k + count - 1) % count] + points[(k + 1) % count]);
      Vec2 p = points[k] + factor * (mean - points[k]);
      const Vec2 shift = p - start[k];
      if (shift.norm() > kSmoothReachPx) p = start[k] + shift * (kSmoothReachPx / shift.norm());
      moved[k] = p;
    }
    points.swap(moved);
  }
  // Points in line with both neighbours (the runs away from any step stay straight) add
  // nothing but work for the simplification; a ring that shares them drops them alike.
  ring.clear();
  for (std::size_t k = 0; k < count; ++k) {
    const Vec2& before = points[(k + count - 1) % count];
    const Vec2& after = points[(k + 1) % count];
    const Vec2 a = points[k] - before, b = after - points[k];
    if (fixed[k] || std::abs(a.x() * b.y() - a.y() * b.x()) > 1e-9 * a.norm() * b.norm() ||
        a.dot(b) <= 0.0)
      ring.push_back(points[k]);
  }
}

// The squared-distance cost made a total order. Equal costs are common on a pixel grid, and the
// simplification would take them in the order of the triangulation's constraint set, which
// follows memory addresses: the same frame (or a .mha and a .nrrd copy of it) could simplify
// differently from run to run. A tie-breaker from the vertex's own coordinates (a hash of their
// bits: distinct vertices get distinct keys but by a 2^-30 chance) makes the result
// reproducible; at most 1e-4 px² it does not change what the tolerance allows.
struct ReproducibleCost {
  template <class Pct>
  boost::optional<double> operator()(const Pct& pct,
                                     typename Pct::Vertices_in_constraint_iterator it) const {
    const boost::optional<double> cost = PS::Squared_distance_cost()(pct, it);
    if (!cost) return cost;
    const auto bits = [](double x) {
      std::uint64_t b = 0;
      std::memcpy(&b, &x, sizeof b);
      return b;
    };
    std::uint64_t h = bits((*it)->point().x()) * 0x9E3779B97F4A7C15ull ^ bits((*it)->point().y());
    h ^= h >> 31;  // splitmix64's finaliser
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 29;
    const auto key = static_cast<std::uint32_t>(h >> 34);  // 30 bits
    return *cost + 1e-4 * std::ldexp(static_cast<double>(key), -30);
  }
};

// Simplifies every ring in one constrained triangulation (CGAL Polyline_simplification_2): a
// vertex goes only when the shortcut stays within epsilon_px of the removed points and the
// triangulation shows it crosses no other ring, so simple rings stay simple and apart (unlike
// approxPolyDP ring by ring, which lets neighbours cross). An edge two rings share is one
// constraint of the triangulation, simplified once for both: neighbours keep sharing it.
void simplify_together(std::vector<PixelRegion>& regions, double epsilon_px) {
  if (epsilon_px <= 0.0) return;
  // The simplification takes rings that share edges and corners with other rings (it simplifies
  // a shared run once, for both), but it is undefined, and crashes, on a ring that passes a
  // point twice (a pinch). The tracing guarantees none; should it ever fail, keep the exact
  // outlines.
  auto pinched = [](const Ring2& ring) {
    std::set<std::pair<double, double>> seen;
    for (const Vec2& p : ring)
      if (!seen.insert({p.x(), p.y()}).second) return true;
    return false;
  };
  for (const PixelRegion& r : regions) {
    if (pinched(r.outer)) return;
    for (const Ring2& hole : r.holes)
      if (pinched(hole)) return;
  }
  Ct ct;
  std::vector<Ct::Constraint_id> ids;
  auto insert = [&](const Ring2& ring) {
    std::vector<Kernel::Point_2> points;
    points.reserve(ring.size());
    for (const Vec2& p : ring) points.emplace_back(p.x(), p.y());
    ids.push_back(ct.insert_constraint(points.begin(), points.end(), true));
  };
  for (const PixelRegion& r : regions) {
    insert(r.outer);
    for (const Ring2& hole : r.holes) insert(hole);
  }
  PS::simplify(ct, ReproducibleCost(), PS::Stop_above_cost_threshold(epsilon_px * epsilon_px));
  std::size_t next = 0;
  auto read = [&](Ring2& ring) {
    ring.clear();
    const Ct::Constraint_id id = ids[next++];
    for (auto it = ct.vertices_in_constraint_begin(id); it != ct.vertices_in_constraint_end(id);
         ++it)
      ring.emplace_back((*it)->point().x(), (*it)->point().y());
    if (ring.size() > 1 && ring.front() == ring.back()) ring.pop_back();  // closed: first again
  };
  for (PixelRegion& r : regions) {
    read(r.outer);
    for (Ring2& hole : r.holes) read(hole);
  }
}

// A ring with at least 3 corners and an area: what survives simplification normally is.
bool has_area(const Ring2& ring) { return ring.size() >= 3 && std::abs(signed_area(ring)) > 1e-6; }

std::string label_name(int label) {
  return label == kLabelPixelUnknown ? std::string("unknown") : "label " + std::to_string(label);
}

Ring2 to_plane(const Ring2& ring_px, const ImagePlane& plane) {
  Ring2 ring;
  ring.reserve(ring_px.size());
  for (const Vec2& p : ring_px) ring.push_back(plane.to_plane(p.x(), p.y()));
  return ring;
}

double region_area_mm2(const Region& r) {
  double area = std::abs(signed_area(r.outer));
  for (const Ring2& hole : r.holes) area -= std::abs(signed_area(hole));
  return area;
}

}  // namespace

double ImagePlane::spacing_mm() const {
  return std::sqrt(std::abs(pixel_to_plane.leftCols<2>().determinant()));
}

ImagePlane image_plane(const Eigen::Matrix4d& T_reference_image, const Vec3& probe_origin_mm) {
  const Vec3 a = T_reference_image.block<3, 1>(0, 0);  // one column step, mm
  const Vec3 b = T_reference_image.block<3, 1>(0, 1);  // one row step, mm
  const Vec3 t = T_reference_image.block<3, 1>(0, 3);  // pixel (0, 0)
  if (!a.allFinite() || !b.allFinite() || !t.allFinite() ||
      a.cross(b).norm() <= 1e-12 * std::max(1.0, a.squaredNorm() + b.squaredNorm()))
    throw GeometryError(
        "image_plane: the calibrated pixel axes are degenerate or not finite; "
        "check the ImageToProbe calibration");
  ImagePlane plane;
  plane.u = a.normalized();
  plane.v = (b - b.dot(plane.u) * plane.u).normalized();
  const Vec3 n = plane.u.cross(plane.v);
  plane.origin_mm = probe_origin_mm - n.dot(probe_origin_mm - t) * n;
  const Vec3 offset = t - plane.origin_mm;
  plane.pixel_to_plane << a.dot(plane.u), b.dot(plane.u), offset.dot(plane.u),  //
      a.dot(plane.v), b.dot(plane.v), offset.dot(plane.v);
  return plane;
}

std::vector<Region> label_map_regions(const LabelImage& labels, const ImageU8& sector,
                                      const ImagePlane& plane, double tolerance_mm,
                                      std::vector<Repair>* repairs, OutlineForm form) {
  if (labels.width != sector.width || labels.height != sector.height ||
      labels.pixels.size() != sector.pixels.size())
    throw std::invalid_argument("label_map_regions: label map and sector differ in size");
  const cv::Mat map(labels.height, labels.width, CV_8U,
                    const_cast<std::uint8_t*>(labels.pixels.data()));
  const cv::Mat in_sector = cv::Mat(sector.height, sector.width, CV_8U,
                                    const_cast<std::uint8_t*>(sector.pixels.data())) > 0;
  std::array<bool, 256> present{};
  for (std::size_t p = 0; p < labels.pixels.size(); ++p)
    if (sector.pixels[p]) present[labels.pixels[p]] = true;
  std::vector<int> values;
  for (int value = 1; value < 256; ++value)
    if (present[static_cast<std::size_t>(value)]) values.push_back(value);
  // The labels are traced apart (on OpenCV's threads), each in its own bounding box grown by a
  // pixel (the upsampled mask of the whole frame was most of the time), and collected in order.
  std::vector<std::vector<PixelRegion>> traced(values.size());
  detail::parallel_for(cv::Range(0, static_cast<int>(values.size())), [&](const cv::Range& range) {
    for (int k = range.start; k < range.end; ++k) {
      const int value = values[static_cast<std::size_t>(k)];
      // Outside the sector is unknown through the fov; only unknown inside it needs regions.
      const cv::Mat whole = (map == value) & in_sector;
      const cv::Rect box =
          (cv::boundingRect(whole) + cv::Point(-1, -1) + cv::Size(2, 2)) & cv::Rect({}, map.size());
      cv::Mat mask = whole(box).clone();
      remove_pinches(mask);
      traced[static_cast<std::size_t>(k)] = trace_mask(mask, value, box.tl());
    }
  });
  std::vector<PixelRegion> pixel_regions;
  for (std::vector<PixelRegion>& regions : traced)
    for (PixelRegion& r : regions) pixel_regions.push_back(std::move(r));
  if (form == OutlineForm::kSmooth) {
    const CornerSet junctions = junction_corners(map, in_sector);
    for (PixelRegion& r : pixel_regions) {
      smooth_outline(r.outer, junctions);
      for (Ring2& hole : r.holes) smooth_outline(hole, junctions);
    }
  }
  simplify_together(pixel_regions, tolerance_mm / plane.spacing_mm());

  std::vector<Region> regions;
  auto record = [&](const PixelRegion& r, const std::string& what, const Ring2& ring) {
    if (!repairs) return;
    repairs->push_back(Repair{"degenerate_region", label_name(r.label),
                              what + " of " + std::to_string(ring.size()) +
                                  " points and no area after simplification; dropped",
                              std::abs(signed_area(to_plane(ring, plane)))});
  };
  for (const PixelRegion& r : pixel_regions) {
    if (!has_area(r.outer)) {
      record(r, "an outer ring", r.outer);
      continue;
    }
    Region region;
    region.label = r.label == kLabelPixelUnknown ? kUnknownLabel : r.label;
    region.outer = to_plane(r.outer, plane);
    for (const Ring2& hole : r.holes) {
      if (has_area(hole))
        region.holes.push_back(to_plane(hole, plane));
      else
        record(r, "a hole", hole);
    }
    regions.push_back(std::move(region));
  }
  return regions;
}

namespace {

Status validate_one(const LabeledSlice& slice) {
  SliceSet one;
  one.slices.push_back(slice);
  return validate_slice_set(one, "segmented frame");
}

}  // namespace

void drop_invalid_regions(LabeledSlice& slice, std::vector<Repair>* repairs) {
  std::vector<Region> regions = std::move(slice.regions), kept;
  LabeledSlice alone = slice;  // the plane alone: each region is judged on its own
  alone.fov.reset();
  for (Region& r : regions) {
    alone.regions.assign(1, r);
    if (const Status ok = validate_one(alone); ok) {
      kept.push_back(std::move(r));
    } else if (repairs) {
      const int label = r.label == kUnknownLabel ? kLabelPixelUnknown : r.label;
      repairs->push_back(Repair{"invalid_region", label_name(label), "dropped: " + ok.message(),
                                region_area_mm2(r)});
    }
  }
  slice.regions = std::move(kept);
}

Result<LabeledSlice> make_slice(const LabelImage& labels, const ImageU8& sector,
                                const Ring2& sector_px, const ImagePlane& plane,
                                double tolerance_mm, std::vector<Repair>* repairs,
                                OutlineForm form) {
  LabeledSlice slice;
  slice.origin_mm = plane.origin_mm;
  slice.u = plane.u;
  slice.v = plane.v;
  slice.fov = to_plane(sector_px, plane);
  if (Status fov = validate_one(slice); !fov) return fov;  // no region can mend the fov
  std::vector<Repair> found;
  slice.regions = label_map_regions(labels, sector, plane, tolerance_mm, &found, form);
  Status valid = validate_one(slice);
  if (!valid && (tolerance_mm > 0.0 || form != OutlineForm::kPixelEdges)) {
    // The construction should make this unreachable; the exact outlines are the safer form.
    found.clear();
    slice.regions = label_map_regions(labels, sector, plane, 0.0, &found);
    valid = validate_one(slice);
  }
  if (!valid) {
    drop_invalid_regions(slice, &found);
    valid = validate_one(slice);
    if (!valid) return valid;
  }
  if (repairs) repairs->insert(repairs->end(), found.begin(), found.end());
  return slice;
}

}  // namespace sonoshape::segmentation
