#include "thin_plate.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/reconstruction_box.hpp"

namespace sonoshape::recon {
namespace {

// ---------------------------------------------------------------------------------------------
// Slice data: the in-plane signed distance of each material.

// A slice's labels and true boundaries, ready for point queries.
class SliceDistances {
 public:
  /// Where an inside value lies between the lower bound (0) and the upper bound (1) that a
  /// material's edges along unknown regions and its true boundaries give (inside_distance).
  static constexpr double kUnseenShare = 0.5;

  /// `truncation[m - 1]`: material m's clamp (mm); `shadow_casters` as ThinPlateOptions has them;
  /// sections thinner than `thinnest_mm` are dilated to it (find_thin_rings).
  SliceDistances(const PreparedSlice& slice, int materials, const std::vector<double>& truncation,
                 const std::vector<bool>& shadow_casters, double thinnest_mm)
      : slice_(&slice), materials_(materials), truncation_(truncation) {
    for (const Ring2& ring : slice.known) known_bands_.push_back(make_ring_bands(ring));
    material_boxes_.assign(static_cast<std::size_t>(materials),
                           {Vec2::Constant(std::numeric_limits<double>::infinity()),
                            Vec2::Constant(-std::numeric_limits<double>::infinity())});
    for (std::size_t m = 1; m <= material_boxes_.size() && m < slice.ring_bounds.size(); ++m)
      for (const auto& [lo, hi] : slice.ring_bounds[m]) {
        auto& box = material_boxes_[m - 1];
        box.first = box.first.cwiseMin(lo);
        box.second = box.second.cwiseMax(hi);
      }
    classify_edges(shadow_casters);
    find_thin_rings(thinnest_mm);
    // Buckets of the truncation's size: a query reads the 3 x 3 around its own.
    Vec2 lo = Vec2::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (const auto& list : edges_)
      for (const auto& [a, b] : list) {
        lo = lo.cwiseMin(a.cwiseMin(b));
        hi = hi.cwiseMax(a.cwiseMax(b));
      }
    if (!(lo.x() <= hi.x())) return;
    make_buckets(lo, hi);
  }

  // An edge of a material's ring is a true boundary when the point just across it is known
  // and of another material: edges along an unknown region or the field of view's edge are
  // where the slice stops seeing, not a surface (they were cut there by the partition). But a
  // material that casts a shadow (bone) ends where its labeller drew its end, also along an
  // unknown region (its shadow); only the field of view's edge and the box's cut it short.
  void classify_edges(const std::vector<bool>& shadow_casters) {
    const PreparedSlice& slice = *slice_;
    double extent = 1.0;
    for (std::size_t m = 1; m < slice.ring_bounds.size(); ++m)
      for (const auto& [lo, hi] : slice.ring_bounds[m]) extent = std::max(extent, (hi - lo).norm());
    const double probe = 1e-7 * extent;
    if (std::find(shadow_casters.begin(), shadow_casters.end(), true) != shadow_casters.end())
      for (const Ring2& ring : slice.view) view_bands_.push_back(make_ring_bands(ring));
    edges_.resize(static_cast<std::size_t>(materials_) + 1);
    unseen_edges_.resize(static_cast<std::size_t>(materials_) + 1);
    whole_rings_.resize(static_cast<std::size_t>(materials_) + 1);
    for (int m = 1; m <= materials_ && static_cast<std::size_t>(m) < slice.rings_by_material.size();
         ++m) {
      const bool caster = static_cast<std::size_t>(m - 1) < shadow_casters.size() &&
                          shadow_casters[static_cast<std::size_t>(m - 1)];
      auto& whole = whole_rings_[static_cast<std::size_t>(m)];
      for (const Ring2& ring : slice.rings_by_material[static_cast<std::size_t>(m)]) {
        whole.push_back(1);
        for (std::size_t i = 0; i < ring.size(); ++i) {
          const Vec2& a = ring[i];
          const Vec2& b = ring[(i + 1) % ring.size()];
          const Vec2 d = b - a;
          const double length = d.norm();
          if (!(length > 0.0)) continue;
          // Outer rings run counter-clockwise and holes clockwise: the material is on the left.
          const Vec2 across = 0.5 * (a + b) + probe / length * Vec2(d.y(), -d.x());
          if (!known(across)) {
            whole.back() = 0;
            if (caster && in_view(across))
              edges_[static_cast<std::size_t>(m)].push_back({a, b});
            else
              unseen_edges_[static_cast<std::size_t>(m)].push_back({a, b});
            continue;
          }
          if (label(across) == m) {
            whole.back() = 0;
            continue;
          }
          edges_[static_cast<std::size_t>(m)].push_back({a, b});
        }
      }
    }
  }

  // A section thinner than the solve grid resolves can fall between the lines of nodes that a
  // slice's samples lie on (one per grid spacing squared of plane): a wire's echo of 0.3 mm^2
  // left no sample inside it on many frames of fCal's recording, and its tube broke where it
  // moved across those lines. The outer rings seen whole (every edge a true boundary) whose
  // thickness 2 A / P (a disc's radius, half a strip's width) is below `thinnest_mm` are the
  // candidates; dilate_unsampled_rings() dilates those that the samples miss. A ring thinner
  // than kSliverShare of it (a grazing cut's sliver, a label map's speck of a few pixels) is
  // left as drawn: dilated, it became a section of about a grid cell where the slice saw next
  // to nothing (`scan-exact`'s rib, a sliver of 0.13 mm, lost 0.0002 IoU).
  static constexpr double kSliverShare = 1.0 / 3.0;
  void find_thin_rings(double thinnest_mm) {
    const PreparedSlice& slice = *slice_;
    thin_candidates_.resize(static_cast<std::size_t>(materials_) + 1);
    thin_rings_.resize(static_cast<std::size_t>(materials_) + 1);
    if (!(thinnest_mm > 0.0)) return;
    for (int m = 1; m <= materials_ && static_cast<std::size_t>(m) < slice.rings_by_material.size();
         ++m) {
      const auto& rings = slice.rings_by_material[static_cast<std::size_t>(m)];
      for (std::size_t r = 0; r < rings.size(); ++r) {
        if (!whole_rings_[static_cast<std::size_t>(m)][r]) continue;
        const Ring2& ring = rings[r];
        double twice_area = 0.0, perimeter = 0.0;
        for (std::size_t i = 0; i < ring.size(); ++i) {
          const Vec2& a = ring[i];
          const Vec2& b = ring[(i + 1) % ring.size()];
          twice_area += a.x() * b.y() - b.x() * a.y();
          perimeter += (b - a).norm();
        }
        if (!(twice_area > 0.0) || twice_area >= thinnest_mm * perimeter) continue;
        const double thickness = twice_area / perimeter;
        if (thickness < kSliverShare * thinnest_mm) continue;
        thin_candidates_[static_cast<std::size_t>(m)].push_back(
            {r, thickness, thinnest_mm - thickness});
      }
    }
  }

  /// Dilates each thin ring (find_thin_rings) in which no point of `samples` (in-plane) lies
  /// deeper than half the ring's thickness by the difference to the thinnest section: its values
  /// become its own signed distance plus that offset (exact for the ring dilated by a disc), so
  /// that it reaches the samples wherever it lies. Sections that hold a sample keep their data as
  /// drawn. Returns whether any ring was dilated (the slice's data must then be taken again).
  bool dilate_unsampled_rings(const std::vector<Vec2>& samples) {
    bool dilated = false;
    for (int m = 1; m <= materials_; ++m)
      for (const ThinRing& thin : thin_candidates_[static_cast<std::size_t>(m)]) {
        const auto& [lo, hi] = slice_->ring_bounds[static_cast<std::size_t>(m)][thin.ring];
        const bool sampled = std::any_of(samples.begin(), samples.end(), [&](const Vec2& q) {
          return (q.array() >= lo.array()).all() && (q.array() <= hi.array()).all() &&
                 ring_signed_distance(m, thin.ring, q) >= 0.5 * thin.thickness;
        });
        if (sampled) continue;
        thin_rings_[static_cast<std::size_t>(m)].push_back(thin);
        auto& box = material_boxes_[static_cast<std::size_t>(m - 1)];
        box.first = box.first.cwiseMin(lo - Vec2::Constant(thin.offset));
        box.second = box.second.cwiseMax(hi + Vec2::Constant(thin.offset));
        dilated = true;
      }
    return dilated;
  }

  /// Whether material m has rings dilated to the thinnest section in this slice.
  bool has_thin_rings(int m) const { return !thin_rings_[static_cast<std::size_t>(m)].empty(); }

  // Whether p lies within the slice's field of view and the box (PreparedSlice::view).
  bool in_view(const Vec2& p) const {
    for (std::size_t r = 0; r < slice_->view.size(); ++r)
      if (winding_number_in_bands(slice_->view[r], view_bands_[r], p) == 0) return false;
    return true;
  }

  /// How far p is from the box of material m's rings (infinity where it has none; 0 inside).
  double gap_to_material(int m, const Vec2& p) const {
    const auto& [lo, hi] = material_boxes_[static_cast<std::size_t>(m - 1)];
    if (!(lo.x() <= hi.x())) return std::numeric_limits<double>::infinity();
    return (lo - p).cwiseMax(p - hi).cwiseMax(0.0).norm();
  }

  /// The slice moved (the same rings, elsewhere in memory).
  void rebind(const PreparedSlice& slice) { slice_ = &slice; }

  /// Material m's clamp grew: the buckets stay, a query reads more of them.
  void set_truncation(int m, double truncation_mm) {
    truncation_[static_cast<std::size_t>(m - 1)] = truncation_mm;
  }

  /// Material m's signed distance at a known point p (its thin rings dilated).
  double signed_distance(int m, const Vec2& p) const { return signed_at(m, p, label(p)); }

  /// What bounds another slice's samples at p (label `at`): material m's signed distance to its
  /// true boundaries, its thin rings dilated (as distance_below for a material without them).
  double bounding_distance(int m, const Vec2& p, int at) const {
    const double d = unsigned_distance(m, p);
    return with_thin_rings(m, p, at == m ? d : -d);
  }

  /// Inside material m, its distance d to its true boundaries is an upper bound of its
  /// in-plane distance to the surface, and the distance to its edges along unknown regions
  /// (where the surface may lie, as at a rib's edge along its own shadow, or lie beyond) a lower
  /// bound. The value is the mean of the two (kUnseenShare): the upper bound alone let the field
  /// go on into such shadows (the `rock-perfect` rib 0.811 IoU, 0.860 with the mean). The lower
  /// bound alone is worse (rib 0.837, `fan-perfect` spot 0.819 against 0.905), and shares of
  /// 0.25 and 0.75 no better (docs/engine.md section 8).
  double inside_distance(int m, const Vec2& p, double d) const {
    const auto& list = unseen_edges_[static_cast<std::size_t>(m)];
    if (list.empty()) return d;
    double best2 = d * d;
    for (const auto& [a, b] : list) {
      const Vec2 e = b - a;
      const double t = std::clamp((p - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
      best2 = std::min(best2, (a + t * e - p).squaredNorm());
    }
    const double lower = std::sqrt(best2);
    return lower + kUnseenShare * (d - lower);
  }

  /// Whether material m has edges along unknown regions in this slice.
  bool sees_unknown_edges(int m) const {
    return !unseen_edges_[static_cast<std::size_t>(m)].empty();
  }

  bool known(const Vec2& p) const {
    if (slice_->unknown.empty()) return true;
    int winding = 0;
    for (std::size_t r = 0; r < slice_->known.size(); ++r)
      winding += winding_number_in_bands(slice_->known[r], known_bands_[r], p);
    return winding > 0;
  }

  // The material drawn at a known point (0: outside; thin rings as drawn).
  int label(const Vec2& p) const {
    for (int m = 1;
         m <= materials_ && static_cast<std::size_t>(m) < slice_->rings_by_material.size(); ++m) {
      const auto& rings = slice_->rings_by_material[static_cast<std::size_t>(m)];
      int winding = 0;
      for (std::size_t r = 0; r < rings.size(); ++r) {
        const auto& [lo, hi] = slice_->ring_bounds[static_cast<std::size_t>(m)][r];
        if (p.x() < lo.x() || p.y() < lo.y() || p.x() > hi.x() || p.y() > hi.y()) continue;
        winding += winding_number_in_bands(rings[r],
                                           slice_->ring_bands[static_cast<std::size_t>(m)][r], p);
      }
      if (winding > 0) return m;
    }
    return 0;
  }

  /// Material m's distance to its true boundaries at p where it is below both sqrt(cap2) and
  /// the truncation (then equal to what distances() gives), infinity otherwise: a query for a
  /// bound reads only the buckets within the distance that could still tighten.
  double distance_below(int m, const Vec2& p, double cap2) const {
    const double truncation = truncation_[static_cast<std::size_t>(m - 1)];
    const double limit2 = std::min(truncation * truncation, cap2);
    const double none = std::numeric_limits<double>::infinity();
    if (bucket_begin_.empty() || !(limit2 > 0.0)) return none;
    const double best2 = nearest_squared(m, p, limit2);
    return best2 < limit2 ? std::sqrt(best2) : none;
  }

  // Signed distances of every material at p into out[0, K): false where p is unknown.
  bool distances(const Vec2& p, double* out) const {
    if (!known(p)) return false;
    const int at = label(p);
    for (int m = 1; m <= materials_; ++m) out[m - 1] = signed_at(m, p, at);
    return true;
  }

 private:
  // Material m's signed distance at p, whose label is `at`.
  double signed_at(int m, const Vec2& p, int at) const {
    const double d = unsigned_distance(m, p);
    const double drawn = at == m ? inside_distance(m, p, d) : -d;
    return has_thin_rings(m) ? with_thin_rings(m, p, drawn) : drawn;
  }
  // The signed distance to ring r of material m alone (positive inside).
  double ring_signed_distance(int m, std::size_t r, const Vec2& p) const {
    const Ring2& ring = slice_->rings_by_material[static_cast<std::size_t>(m)][r];
    double best2 = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < ring.size(); ++i) {
      const Vec2& a = ring[i];
      const Vec2 e = ring[(i + 1) % ring.size()] - a;
      const double t =
          e.squaredNorm() > 0.0 ? std::clamp((p - a).dot(e) / e.squaredNorm(), 0.0, 1.0) : 0.0;
      best2 = std::min(best2, (a + t * e - p).squaredNorm());
    }
    const bool inside =
        winding_number_in_bands(ring, slice_->ring_bands[static_cast<std::size_t>(m)][r], p) != 0;
    return inside ? std::sqrt(best2) : -std::sqrt(best2);
  }
  // The greatest of `value` (material m's signed distance to its rings as drawn) and each thin
  // ring's own signed distance plus its offset, clamped to the truncation: outside every ring
  // the signed distance to the union of the dilated rings.
  double with_thin_rings(int m, const Vec2& p, double value) const {
    for (const ThinRing& thin : thin_rings_[static_cast<std::size_t>(m)]) {
      const auto& [lo, hi] = slice_->ring_bounds[static_cast<std::size_t>(m)][thin.ring];
      // The ring's value is at most its offset less p's distance to its box.
      const double gap = (lo - p).cwiseMax(p - hi).cwiseMax(0.0).norm();
      if (gap > 0.0 && thin.offset - gap <= value) continue;
      value = std::max(value, thin.offset + ring_signed_distance(m, thin.ring, p));
    }
    const double truncation = truncation_[static_cast<std::size_t>(m - 1)];
    return std::clamp(value, -truncation, truncation);
  }
  double unsigned_distance(int m, const Vec2& p) const {
    const double truncation = truncation_[static_cast<std::size_t>(m - 1)];
    if (bucket_begin_.empty()) return truncation;
    return std::sqrt(nearest_squared(m, p, truncation * truncation));
  }
  // The least of `limit2` and the squared distances from p to material m's true boundaries.
  double nearest_squared(int m, const Vec2& p, double limit2) const {
    const auto& list = edges_[static_cast<std::size_t>(m)];
    double best2 = limit2;
    if (list.empty()) return best2;
    const int cx = cell_x(p.x()), cy = cell_y(p.y());
    const int rx = static_cast<int>(std::ceil(std::sqrt(limit2) / bucket_size_));
    const std::array<int, 4>& range = bucket_ranges_[static_cast<std::size_t>(m)];
    const int x0 = std::max(range[0], cx - rx), x1 = std::min(range[1], cx + rx);
    for (int y = std::max(range[2], cy - rx); y <= std::min(range[3], cy + rx); ++y) {
      const double gy = std::max({0.0, origin_.y() + y * bucket_size_ - p.y(),
                                  p.y() - (origin_.y() + (y + 1) * bucket_size_)});
      for (int x = x0; x <= x1; ++x) {
        // An edge's nearest point to p lies in a bucket that lists it, no nearer than that
        // bucket: a bucket farther than the nearest edge so far is skipped (with a margin
        // for the rounding of its bounds).
        const double gx = std::max({0.0, origin_.x() + x * bucket_size_ - p.x(),
                                    p.x() - (origin_.x() + (x + 1) * bucket_size_)});
        if (gx * gx + gy * gy > best2 * (1.0 + 1e-9)) continue;
        const std::size_t at = bucket_index(m, x, y);
        for (std::uint32_t i = bucket_begin_[at]; i < bucket_begin_[at + 1]; ++i) {
          const auto& [a, b] = list[bucket_edges_[i]];
          const Vec2 d = b - a;
          const double t = std::clamp((p - a).dot(d) / d.squaredNorm(), 0.0, 1.0);
          best2 = std::min(best2, (a + t * d - p).squaredNorm());
        }
      }
    }
    return best2;
  }
  int cell_x(double x) const {
    return std::clamp(static_cast<int>(std::floor((x - origin_.x()) / bucket_size_)), 0, nx_ - 1);
  }
  int cell_y(double y) const {
    return std::clamp(static_cast<int>(std::floor((y - origin_.y()) / bucket_size_)), 0, ny_ - 1);
  }
  std::size_t bucket_index(int m, int x, int y) const {
    return (static_cast<std::size_t>(m) * ny_ + y) * nx_ + x;
  }

  // Buckets of a quarter of the least truncation over [lo, hi], each listing the edges whose
  // box meets it (stored one after the other: bucket_begin_ indexes bucket_edges_). A query
  // reads the buckets within its radius that are nearer than the nearest edge found so far.
  void make_buckets(const Vec2& lo, const Vec2& hi) {
    std::size_t edge_count = 0;
    for (const auto& list : edges_) edge_count += list.size();
    bucket_size_ = 0.25 * *std::min_element(truncation_.begin(), truncation_.end());
    origin_ = lo;
    const Vec2 cells = ((hi - lo) / bucket_size_).array().floor() + 1.0;
    // A truncation tiny against the slice would make too many buckets: grow them instead, so
    // that they are not many more than the edges.
    const double count = cells.x() * cells.y(), most = 4.0 * static_cast<double>(edge_count) + 64.0;
    if (count > most) bucket_size_ *= std::sqrt(count / most);
    nx_ = static_cast<int>(std::floor((hi.x() - lo.x()) / bucket_size_)) + 1;
    ny_ = static_cast<int>(std::floor((hi.y() - lo.y()) / bucket_size_)) + 1;
    const std::size_t buckets =
        static_cast<std::size_t>(nx_) * static_cast<std::size_t>(ny_) * (edges_.size());
    bucket_begin_.assign(buckets + 1, 0);
    auto for_edge_buckets = [&](const auto& body) {
      for (std::size_t m = 1; m < edges_.size(); ++m) {
        const auto& list = edges_[m];
        for (std::uint32_t e = 0; e < list.size(); ++e) {
          const auto& [a, b] = list[e];
          const int x0 = cell_x(std::min(a.x(), b.x())), x1 = cell_x(std::max(a.x(), b.x()));
          const int y0 = cell_y(std::min(a.y(), b.y())), y1 = cell_y(std::max(a.y(), b.y()));
          for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x) body(bucket_index(static_cast<int>(m), x, y), e);
        }
      }
    };
    // Per material, the range of buckets its edges meet: a query reads no bucket outside it.
    bucket_ranges_.assign(edges_.size(), {nx_, -1, ny_, -1});
    for (std::size_t m = 1; m < edges_.size(); ++m)
      for (const auto& [a, b] : edges_[m]) {
        std::array<int, 4>& range = bucket_ranges_[m];
        range[0] = std::min(range[0], cell_x(std::min(a.x(), b.x())));
        range[1] = std::max(range[1], cell_x(std::max(a.x(), b.x())));
        range[2] = std::min(range[2], cell_y(std::min(a.y(), b.y())));
        range[3] = std::max(range[3], cell_y(std::max(a.y(), b.y())));
      }
    for_edge_buckets([&](std::size_t at, std::uint32_t) { ++bucket_begin_[at + 1]; });
    for (std::size_t b = 0; b < buckets; ++b) bucket_begin_[b + 1] += bucket_begin_[b];
    bucket_edges_.resize(bucket_begin_[buckets]);
    std::vector<std::uint32_t> fill(bucket_begin_.begin(), bucket_begin_.end() - 1);
    for_edge_buckets([&](std::size_t at, std::uint32_t e) { bucket_edges_[fill[at]++] = e; });
  }

  const PreparedSlice* slice_;
  int materials_;
  std::vector<double> truncation_;
  std::vector<RingBands> known_bands_;
  std::vector<RingBands> view_bands_;                      // of slice_->view
  std::vector<std::pair<Vec2, Vec2>> material_boxes_;      // per material 1..K: its rings' box
  std::vector<std::vector<std::pair<Vec2, Vec2>>> edges_;  // per material: true boundaries
  std::vector<std::vector<std::pair<Vec2, Vec2>>> unseen_edges_;  // per material: along unknown
  struct ThinRing {
    std::size_t ring = 0;    // in slice_->rings_by_material[m]
    double thickness = 0.0;  // 2 A / P (mm)
    double offset = 0.0;     // mm it is dilated by
  };
  std::vector<std::vector<ThinRing>> thin_candidates_;  // per material: thinner than the thinnest
  std::vector<std::vector<ThinRing>> thin_rings_;       // per material: those dilated
  std::vector<std::vector<char>> whole_rings_;          // per material and ring: every edge true
  Vec2 origin_ = Vec2::Zero();
  double bucket_size_ = 1.0;
  int nx_ = 0, ny_ = 0;
  std::vector<std::uint32_t> bucket_begin_;  // per material, row-major, and one past the last
  std::vector<std::uint32_t> bucket_edges_;
  std::vector<std::array<int, 4>> bucket_ranges_;  // per material: x0, x1, y0, y1
};

// ---------------------------------------------------------------------------------------------
// The grid hierarchy and its operator A = s L^2 + D (s = 2^-level: the coarse grid's L^2 seen
// from the fine one). On the finest level D is the data's exact quadratic form: each sample lies
// where a plane crosses a grid edge and constrains the linear interpolation of the edge's two
// nodes, (1 - t) x0 + t x1 = d, so the data fix the field on the plane and leave its slope across
// the plane free (nodes next to a plane fixed to its value would extrude each slice over a
// slab). Its 2 x 2 blocks are summed per edge: diagonal `data_diagonal` and per axis the edge
// (n, n + axis) in `data_edge[axis][n]`. Coarser levels lump it: `weight` is its row sums,
// restricted.

// The V-cycle runs in single precision: it only preconditions the conjugate gradients, which
// keep their vectors in double, and it is memory-bound, so halving its bytes nearly halves its
// time. The operator's weights are single-precision copies of the data's double sums, the same
// in the conjugate gradients' products, so that both see one matrix.
using Real = float;

struct Level {
  int nx = 0, ny = 0, nz = 0;
  double scale = 1.0;                 // s
  std::vector<Real> weight;           // lumped data weights (finest: the row sums of its D)
  std::vector<double> data_diagonal;  // finest level only: D's sums
  std::array<std::vector<double>, 3> data_edge;    // finest level only
  std::vector<Real> operator_diagonal;             // finest level only: data_diagonal as Real
  std::array<std::vector<Real>, 3> operator_edge;  // finest level only
  std::vector<Real> zero_row;                      // finest level only: nx zeros
  // The smoother's diagonal: 1 / (s * l1 bound of L^2's row + row sum of D).
  std::vector<Real> inverse;
  // Per node, the l1 bound of L^2's row (at most 144): it depends on the grid alone, so it is
  // computed once, and an online update that changed the data weights only divides again.
  std::vector<std::uint8_t> square_bound;
  std::size_t size() const { return static_cast<std::size_t>(nx) * ny * nz; }
  std::size_t index(int i, int j, int k) const {
    return (static_cast<std::size_t>(k) * ny + j) * nx + i;
  }
};

// One V-cycle's vectors on one level: each material solves with its own, so that materials
// can be solved at once (they share the operator).
struct Work {
  std::vector<Real> x, b, r, d, ad;
  void fit(std::size_t count) {
    for (std::vector<Real>* v : {&x, &b, &r, &d, &ad}) v->resize(count);
  }
};

int degree(const Level& g, int i, int j, int k) {
  return (i > 0) + (i < g.nx - 1) + (j > 0) + (j < g.ny - 1) + (k > 0) + (k < g.nz - 1);
}

// The kernels, twice: for the baseline x86-64 and for AVX2 (8 floats per instruction instead
// of 4), chosen at run time.
namespace baseline {
#include "thin_plate_kernels.inc"
}  // namespace baseline

#if (defined(__x86_64__) || defined(__i386__)) && defined(__GNUC__) && !defined(__clang__)
#define SONOSHAPE_THIN_PLATE_AVX2 1
#pragma GCC push_options
#pragma GCC target("avx2")
namespace avx2 {
#include "thin_plate_kernels.inc"
}  // namespace avx2
#pragma GCC pop_options
#endif

using baseline::for_nodes;
using baseline::for_planes;
using baseline::restrict_to_coarse;

// The kernels the conjugate gradients call: AVX2's where the CPU has it and `simd` asks for it.
struct SolverKernels {
  void (*v_cycle)(const std::vector<Level>&, std::vector<Work>&, std::size_t);
  void (*apply_operator)(const Level&, const double*, double*);
};

const SolverKernels& solver_kernels(bool simd) {
  static const SolverKernels plain{baseline::v_cycle, baseline::apply_operator<double>};
#ifdef SONOSHAPE_THIN_PLATE_AVX2
  static const SolverKernels wide{avx2::v_cycle, avx2::apply_operator<double>};
  static const bool have_avx2 = __builtin_cpu_supports("avx2");
  if (simd && have_avx2) return wide;
#else
  (void)simd;
#endif
  return plain;
}

// The finest level's row sums of D into `weight` (all its entries are non-negative).
void lump_finest_data(Level& g) {
  const std::size_t stride[3] = {1, static_cast<std::size_t>(g.nx),
                                 static_cast<std::size_t>(g.nx) * static_cast<std::size_t>(g.ny)};
  const int dims[3] = {g.nx, g.ny, g.nz};
  for_planes(g.nz, [&](int k) {
    for (int j = 0; j < g.ny; ++j)
      for (int i = 0; i < g.nx; ++i) {
        const std::size_t n = g.index(i, j, k);
        const int at[3] = {i, j, k};
        double sum = g.data_diagonal[n];
        for (int a = 0; a < 3; ++a) {
          if (at[a] + 1 < dims[a]) sum += g.data_edge[a][n];
          if (at[a] > 0) sum += g.data_edge[a][n - stride[a]];
        }
        g.weight[n] = static_cast<Real>(sum);
      }
  });
  g.operator_diagonal.assign(g.data_diagonal.begin(), g.data_diagonal.end());
  for (int a = 0; a < 3; ++a)
    g.operator_edge[a].assign(g.data_edge[a].begin(), g.data_edge[a].end());
}

void update_inverse_diagonal(Level& g) {
  if (g.square_bound.size() != g.size()) {
    g.square_bound.resize(g.size());
    for_planes(g.nz, [&](int k) {
      for (int j = 0; j < g.ny; ++j)
        for (int i = 0; i < g.nx; ++i) {
          // Row sum of |L^2| bounded by sum over k in N(n) u {n} of |L_nk| * 2 deg(k): exact
          // inside the grid (144), an upper bound at its faces, so the smoother's D^-1 A has
          // spectrum in (0, 1].
          const int dn = degree(g, i, j, k);
          int bound = 2 * dn * dn;
          if (i > 0) bound += 2 * degree(g, i - 1, j, k);
          if (i < g.nx - 1) bound += 2 * degree(g, i + 1, j, k);
          if (j > 0) bound += 2 * degree(g, i, j - 1, k);
          if (j < g.ny - 1) bound += 2 * degree(g, i, j + 1, k);
          if (k > 0) bound += 2 * degree(g, i, j, k - 1);
          if (k < g.nz - 1) bound += 2 * degree(g, i, j, k + 1);
          g.square_bound[g.index(i, j, k)] = static_cast<std::uint8_t>(bound);
        }
    });
  }
  g.inverse.resize(g.size());
  for_nodes(g.size(), [&](std::size_t n) {
    g.inverse[n] = static_cast<Real>(1.0 / (g.scale * g.square_bound[n] + g.weight[n]));
  });
}

// Deterministic: the ranges and the order of the joins depend on `count` alone. With
// parallel_reduce's automatic partitioning they followed the threads' timing, so the rounding
// of these sums, and through the solve's stopping test the meshes, changed from run to run.
template <typename A, typename B>
double dot(const A* a, const B* b, std::size_t count) {
  return tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, count, 1 << 14), 0.0,
      [&](const tbb::blocked_range<std::size_t>& range, double sum) {
        for (std::size_t n = range.begin(); n < range.end(); ++n)
          sum += static_cast<double>(a[n]) * static_cast<double>(b[n]);
        return sum;
      },
      [](double x, double y) { return x + y; });
}

}  // namespace

std::vector<double> slice_signed_distances(const PreparedSlice& slice, int materials,
                                           double truncation, const std::vector<Vec2>& points,
                                           const std::vector<bool>& shadow_casters) {
  const SliceDistances distances(
      slice, materials, std::vector<double>(static_cast<std::size_t>(materials), truncation),
      shadow_casters, /*thinnest_mm=*/0.0);
  std::vector<double> out(points.size() * static_cast<std::size_t>(materials),
                          std::numeric_limits<double>::quiet_NaN());
  for (std::size_t p = 0; p < points.size(); ++p)
    distances.distances(points[p], out.data() + p * static_cast<std::size_t>(materials));
  return out;
}

// A relative residual at which the solve stops whatever its steps (rounding dominates below).
constexpr double kSolvedResidual = 1e-13;

// The largest solve grid: about 2.5 GB with one material (the default depth gives ~0.3 M).
constexpr double kMaxNodes = 32.0 * 1024 * 1024;

// No truncation below this many solve-grid spacings: the data would not reach a grid node.
constexpr double kMinimumTruncation = 2.0;
// A grid of its own (own_grid_boxes) is rounded out to multiples of this many finest cells.
constexpr double kOwnGridStep = 8.0;
// Only an organ whose extent spans fewer solve cells of the grid over the box than this gets a
// grid of its own (own_grid_boxes).
constexpr double kOwnGridCells = 32.0;

Box3 empty_box() {
  return Box3{Vec3::Constant(std::numeric_limits<double>::infinity()),
              Vec3::Constant(-std::numeric_limits<double>::infinity())};
}

bool is_empty(const Box3& box) { return !(box.min.x() <= box.max.x()); }

// The thinnest section the data keep, as a thickness 2 A / P in solve-grid spacings
// (SliceDistances::dilate_unsampled_rings): a plane's samples lie on lines of nodes a spacing
// apart, so a strip about a spacing wide (a thickness of half a spacing) holds a row of them
// whatever its direction. Just under a half: at 0.5 a section at the end of `fan-perfect`'s
// cheburashka, about a cell across, was dilated by 0.19 mm and the organ lost 0.001 IoU; at 0.4
// fCal's fifth wire stayed in two pieces.
constexpr double kThinnestSectionSpacings = 0.45;

// The least bound a slice puts on another's samples, in solve-grid spacings (tighten()).
constexpr double kLeastBoundSpacings = 0.25;

// Each sample's value is an upper bound of its distance to the surface, signed: its slice's
// true boundaries lie on the surface. So are these, from another slice B at height h above it:
// h where B is known and on the other side at the sample's foot (the segment between them
// crosses the surface), and the distance to B's boundary (hypot(h, B's in-plane distance at
// the foot)). tighten() keeps the least: slices a millimetre apart on either side of an
// organ's end then disagree by about that millimetre, not by twice the truncation (a fill
// through such a jump rings: a bulge before the end, the end short of the last slice).
//
// No bound is taken below `least_mm` (kLeastBoundSpacings): slices nearer than that lie on the
// same grid edges, which cannot place a surface between them, and what they disagree on there
// is the error of the tracking and the outlines. Bounds by their distance turned that into
// values near zero over both sections, whose sign the fill then follows: fCal's wire recording,
// its wires seen on the way out and back a millimetre apart, left blobs beside a wire's tube.
//
// Tightens sample `values` (K materials, at point p) by slice `b`; returns whether any changed.
static bool tighten(const Vec3& p, double* values, const PreparedSlice& b,
                    const SliceDistances& other, double least_mm, std::vector<double>& scratch) {
  const std::size_t k = scratch.size();
  const Vec3 r = p - b.origin;
  const double h = std::max(std::abs(r.dot(b.unit_normal)), least_mm);
  const Vec2 foot(r.dot(b.u), r.dot(b.v));
  // Without a query where the foot is far from B's rings: then B is outside them there (the
  // other side for a sample inside), or too far to bound a sample outside.
  bool query = false, outside = false;
  for (std::size_t m = 0; m < k; ++m) {
    const double limit = std::abs(values[m]);
    if (!(h < limit)) continue;
    const double gap = other.gap_to_material(static_cast<int>(m) + 1, foot);
    if (gap * gap + h * h < limit * limit)
      query = true;
    else if (values[m] > 0.0)
      outside = true;  // gap > 0: B is outside material m at the foot
  }
  bool changed = false;
  if (query) {
    if (!other.known(foot)) return false;
    const int at = other.label(foot);
    for (std::size_t m = 0; m < k; ++m) {
      const double limit = std::abs(values[m]);
      if (!(h < limit)) continue;
      double bound = h;  // B on the other side at the foot (or on its boundary)
      if (other.has_thin_rings(static_cast<int>(m) + 1)) {
        // B's dilated sections decide the side and the distance.
        const double at_foot = other.bounding_distance(static_cast<int>(m) + 1, foot, at);
        if ((at_foot > 0.0) == (values[m] > 0.0)) bound = std::hypot(h, std::abs(at_foot));
      } else if ((at == static_cast<int>(m) + 1) == (values[m] > 0.0)) {
        // The same side: B's boundary bounds the distance where it is nearer than
        // sqrt(limit^2 - h^2) (with a margin far above rounding, so that no bound below the
        // limit is missed).
        const double cap2 = (limit * limit - h * h) + 1e-12 * limit * limit;
        const double gap = other.gap_to_material(static_cast<int>(m) + 1, foot);
        if (gap * gap >= cap2) continue;
        const double d = other.distance_below(static_cast<int>(m) + 1, foot, cap2);
        if (!(d < std::numeric_limits<double>::infinity())) continue;
        bound = std::hypot(h, d);
      }
      if (bound < limit) {
        values[m] = values[m] > 0.0 ? bound : -bound;
        changed = true;
      }
    }
  } else if (outside && other.known(foot)) {
    for (std::size_t m = 0; m < k; ++m)
      if (values[m] > h) {
        values[m] = h;
        changed = true;
      }
  }
  return changed;
}

// The blocks of the solve grid whose change is tracked for re-sampling: nodes per axis. A
// point's interpolation reads 4 nodes per axis, so at most 2 blocks per axis.
constexpr int kBlock = 4;

struct ThinPlateField::Grid {
  std::vector<double> extents_mm;  // per material, what the truncations were set from
  Box3 box;
  int materials = 0;
  ThinPlateOptions options;
  double spacing = 1.0;
  std::vector<double> truncation_mm;  // per material
  std::vector<Level> levels;
  std::vector<double> weighted_targets;       // per material, level 0: the data's right-hand side
  std::vector<std::vector<double>> solution;  // per material, level 0
  // What evaluate() interpolates: per material, the solution as last sampled, taken again per
  // block of kBlock^3 nodes when a node of the block moved by more than the resample tolerance;
  // `block_changed_at` holds the solve (`generation`) at which each block last took it.
  std::vector<std::vector<double>> sampled;
  std::array<int, 3> blocks{};
  std::vector<std::uint32_t> block_changed_at;
  // Per node (i0, j0, k0): the latest block_changed_at over the blocks that the interpolation
  // in the cell with that min corner reads (nodes i0 - 1 .. i0 + 2 per axis), so that a look-up
  // per octree row says whether it is current.
  std::vector<std::uint32_t> stencil_changed_at;
  std::uint32_t generation = 0;
  // Whether `sampled` holds a solution (this grid's first solve, or start_from): until then
  // every block is new at the next solve.
  bool sampled_once = false;
  // Per material, the largest distance between a sample added (or tightened) since the last
  // solve and that solution (NaN-free; 0 when nothing was added), and whether this field solved
  // before: an online update solves again only the materials whose new data the field does not fit
  // yet.
  std::vector<double> misfit_mm;
  bool solved = false;
  std::vector<PreparedSlice> slices;
  bool weights_dirty = true;

  static std::vector<Vec2> in_plane(const std::vector<Vec3>& points, const PreparedSlice& slice) {
    std::vector<Vec2> out;
    out.reserve(points.size());
    for (const Vec3& p : points) {
      const Vec3 r = p - slice.origin;
      out.emplace_back(r.dot(slice.u), r.dot(slice.v));
    }
    return out;
  }
  // The thinnest section the data keep (mm; SliceDistances::dilate_unsampled_rings).
  double thinnest_mm() const { return kThinnestSectionSpacings * spacing; }
  // The least bound tighten() takes (mm).
  double least_bound_mm() const { return kLeastBoundSpacings * spacing; }
  double truncation_for(double extent_mm) const {
    return std::max(options.truncation * truncation_extent(extent_mm),
                    kMinimumTruncation * spacing);
  }
  // solve_one's work vectors, per material (kept across solves: an online update solves every
  // material again).
  struct SolveWork {
    std::vector<Work> levels;
    std::vector<double> residual, direction, product;
  };
  std::vector<SolveWork> solve_work;

  // The data of one slice: the points where its plane crosses the grid's edges along the axis
  // nearest its normal (one per line of nodes along that axis), each with the edge's first node,
  // the position t along it, a weight and the signed distances there.
  struct Contribution {
    int axis = 0;
    std::vector<std::uint32_t> nodes;
    std::vector<double> positions;
    double weight = 0.0;
    std::vector<double> targets;  // materials per sample
    std::vector<Vec3> points;     // per sample, where it is (world mm)
    // The samples lie on lines (jb, jc) of the two other axes: sample e is on column
    // columns[e] of row jc, rows_begin[jc] <= e < rows_begin[jc + 1], and near corner +
    // jb step_b + jc step_c. A sample's height above another plane is affine in (jb, jc), so
    // the samples within a distance of that plane are found per row without visiting the others.
    std::vector<std::uint32_t> columns;
    std::vector<std::uint32_t> rows_begin;
    Vec3 corner = Vec3::Zero(), step_b = Vec3::Zero(), step_c = Vec3::Zero();
  };

  // Calls body(e) for the samples of c that may lie within `reach` (mm) of plane b (a superset:
  // the rows' column ranges are widened by one sample for rounding).
  template <typename Body>
  static void for_samples_near(const Contribution& c, const PreparedSlice& b, double reach,
                               const Body& body) {
    const double h0 = (c.corner - b.origin).dot(b.unit_normal);
    const double gb = c.step_b.dot(b.unit_normal), gc = c.step_c.dot(b.unit_normal);
    for (std::size_t jc = 0; jc + 1 < c.rows_begin.size(); ++jc) {
      const std::uint32_t begin = c.rows_begin[jc], end = c.rows_begin[jc + 1];
      if (begin == end) continue;
      const double row = h0 + static_cast<double>(jc) * gc;
      double lo = -1.0, hi = std::numeric_limits<double>::infinity();
      if (std::abs(gb) * 1e9 > reach) {
        const double x0 = (-reach - row) / gb, x1 = (reach - row) / gb;
        lo = std::floor(std::min(x0, x1)) - 1.0;
        hi = std::ceil(std::max(x0, x1)) + 1.0;
      } else if (std::abs(row) > reach * (1.0 + 1e-9) + 1e-9) {
        continue;
      }
      if (hi < 0.0 || lo > static_cast<double>(c.columns[end - 1])) continue;
      const auto* first = c.columns.data() + begin;
      const auto* last = c.columns.data() + end;
      if (lo > 0.0) first = std::lower_bound(first, last, static_cast<std::uint32_t>(lo));
      if (hi < static_cast<double>(c.columns[end - 1]))
        last = std::upper_bound(first, last, static_cast<std::uint32_t>(hi));
      for (const auto* e = first; e < last; ++e)
        body(static_cast<std::size_t>(e - c.columns.data()));
    }
  }

  // Per slice, kept: its distances answer later slices' queries, and a later slice can tighten
  // its samples' values.
  std::vector<std::unique_ptr<SliceDistances>> distances;
  std::vector<Contribution> data;

  // Tightens slice a's samples by slices [first, last) other than a (tighten()). Returns the
  // changes as (sample * K + material, old value).
  std::vector<std::pair<std::size_t, double>> tighten_slice(std::size_t a, std::size_t first,
                                                            std::size_t last) {
    Contribution& c = data[a];
    const std::size_t k = static_cast<std::size_t>(materials);
    std::vector<double> scratch(k);
    const std::vector<double> before = c.targets;
    // A sample is tightened only by planes nearer than its |value| <= the largest truncation.
    const double reach = *std::max_element(truncation_mm.begin(), truncation_mm.end());
    for (std::size_t b = first; b < last; ++b) {
      if (b == a) continue;
      for_samples_near(c, slices[b], reach, [&](std::size_t e) {
        tighten(c.points[e], c.targets.data() + e * k, slices[b], *distances[b], least_bound_mm(),
                scratch);
      });
    }
    std::vector<std::pair<std::size_t, double>> changes;
    for (std::size_t at = 0; at < before.size(); ++at)
      if (c.targets[at] != before[at]) changes.emplace_back(at, before[at]);
    return changes;
  }

  // The right-hand side follows the changes of slice a's values.
  void retarget(std::size_t a, const std::vector<std::pair<std::size_t, double>>& changes) {
    const Contribution& c = data[a];
    const Level& g = levels[0];
    const std::size_t k = static_cast<std::size_t>(materials);
    const std::size_t stride = c.axis == 0   ? 1
                               : c.axis == 1 ? static_cast<std::size_t>(g.nx)
                                             : static_cast<std::size_t>(g.nx) * g.ny;
    for (const auto& [at, old] : changes) {
      const std::size_t e = at / k, m = at % k;
      const std::size_t n0 = c.nodes[e], n1 = n0 + stride;
      const double delta = c.weight * (c.targets[at] - old), t = c.positions[e];
      weighted_targets[m * g.size() + n0] += (1.0 - t) * delta;
      weighted_targets[m * g.size() + n1] += t * delta;
      // A tightened value is new data too: solve() must not take the material as fitted.
      const double fitted = (1.0 - t) * solution[m][n0] + t * solution[m][n1];
      misfit_mm[m] = std::max(misfit_mm[m], std::abs(c.targets[at] - fitted));
    }
  }

  // A sample's weight against the bending energy. Exact outlines are interpolated; outlines
  // with an error (a segmented frame's) are fitted as a smoothing spline: a sample whose error
  // is a grid spacing weighs as much as one node's bending, so noise that differs from slice
  // to slice is averaged over neighbouring slices instead of bending the surface at each.
  double data_weight(const PreparedSlice& slice) const {
    if (!(slice.outline_sd_mm > 0.0)) return options.data_weight;
    const double spacings = spacing / slice.outline_sd_mm;
    return std::min(options.data_weight, spacings * spacings);
  }

  Contribution slice_data(const PreparedSlice& slice, const SliceDistances& distances) const {
    Contribution out;
    const Level& g = levels[0];
    const Vec3 n = slice.unit_normal;
    int a = 0;
    for (int axis = 1; axis < 3; ++axis)
      if (std::abs(n[axis]) > std::abs(n[a])) a = axis;
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    const int dims[3] = {g.nx, g.ny, g.nz};
    const double margin = 1e-9 * box.diagonal();
    out.axis = a;
    // One sample per spacing^2 of the plane's shadow on the other two axes, so per area of the
    // plane the weight is the same whatever its tilt.
    out.weight = data_weight(slice) / std::abs(n[a]);
    std::vector<double> values(static_cast<std::size_t>(materials));
    // Where the plane crosses line (jb, jc), as an affine function of (jb, jc).
    out.corner = box.min;
    out.corner[a] =
        slice.origin[a] -
        (n[b] * (box.min[b] - slice.origin[b]) + n[c] * (box.min[c] - slice.origin[c])) / n[a];
    out.step_b[b] = spacing;
    out.step_b[a] = -n[b] / n[a] * spacing;
    out.step_c[c] = spacing;
    out.step_c[a] = -n[c] / n[a] * spacing;
    out.rows_begin.reserve(static_cast<std::size_t>(dims[c]) + 1);
    for (int jc = 0; jc < dims[c]; ++jc) {
      out.rows_begin.push_back(static_cast<std::uint32_t>(out.nodes.size()));
      for (int jb = 0; jb < dims[b]; ++jb) {
        Vec3 p = box.min;
        p[b] += jb * spacing;
        p[c] += jc * spacing;
        // Where the plane crosses this line along axis a.
        p[a] = slice.origin[a] -
               (n[b] * (p[b] - slice.origin[b]) + n[c] * (p[c] - slice.origin[c])) / n[a];
        if (((p.array() < box.min.array() - margin) || (p.array() > box.max.array() + margin))
                .any())
          continue;
        const double along = (p[a] - box.min[a]) / spacing;
        int first = std::clamp(static_cast<int>(std::floor(along)), 0, dims[a] - 2);
        const double t = std::clamp(along - first, 0.0, 1.0);
        const Vec2 q((p - slice.origin).dot(slice.u), (p - slice.origin).dot(slice.v));
        if (!distances.distances(q, values.data())) continue;
        int idx[3];
        idx[a] = first;
        idx[b] = jb;
        idx[c] = jc;
        out.nodes.push_back(static_cast<std::uint32_t>(g.index(idx[0], idx[1], idx[2])));
        out.positions.push_back(t);
        out.targets.insert(out.targets.end(), values.begin(), values.end());
        out.points.push_back(p);
        out.columns.push_back(static_cast<std::uint32_t>(jb));
      }
    }
    out.rows_begin.push_back(static_cast<std::uint32_t>(out.nodes.size()));
    return out;
  }

  void add(const Contribution& data) {
    Level& g = levels[0];
    const std::size_t k = static_cast<std::size_t>(materials);
    const std::size_t stride = data.axis == 0   ? 1
                               : data.axis == 1 ? static_cast<std::size_t>(g.nx)
                                                : static_cast<std::size_t>(g.nx) * g.ny;
    const double w = data.weight;
    for (std::size_t e = 0; e < data.nodes.size(); ++e) {
      const std::size_t n0 = data.nodes[e], n1 = n0 + stride;
      const double t = data.positions[e];
      g.data_diagonal[n0] += w * (1.0 - t) * (1.0 - t);
      g.data_diagonal[n1] += w * t * t;
      g.data_edge[static_cast<std::size_t>(data.axis)][n0] += w * t * (1.0 - t);
      for (std::size_t m = 0; m < k; ++m) {
        const double target = data.targets[e * k + m];
        weighted_targets[m * g.size() + n0] += w * (1.0 - t) * target;
        weighted_targets[m * g.size() + n1] += w * t * target;
        // What this sample asks of the last solution (the edge's linear interpolation).
        const double fitted = (1.0 - t) * solution[m][n0] + t * solution[m][n1];
        misfit_mm[m] = std::max(misfit_mm[m], std::abs(target - fitted));
      }
    }
    weights_dirty = true;
  }

  // Priors where the slices say nothing, as quadratic terms w (f - target)^2 on nodes: the
  // closing (-truncation, closing_weight) on and beyond the box's faces across the axes the
  // slices sample, and beyond the slices along an axis they do not sample, their extrusion
  // (extrusion_weight). `prior_weight` (per node) and `prior_target` (per node and material)
  // are what the operator and the right-hand side hold now.
  std::vector<double> prior_weight, prior_target;
  bool priors_all_sampled = false;  // the priors applied: every axis sampled (the closing alone)
  // The box of the data's sample points (world mm).
  Vec3 data_min = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 data_max = -data_min;

  // Whether the slices sample each axis: their samples spread along it at least as far as the
  // box reaches beyond them on the nearer side. Nearly coplanar slices (a probe rocked in its
  // plane) do not sample their normal's axis: the box's extent there is mostly the padding that
  // the other axes' extent set, and nothing in the data says where an organ ends along it.
  std::array<bool, 3> sampled_axes() const {
    std::array<bool, 3> sampled{true, true, true};
    for (int a = 0; a < 3; ++a) {
      if (!(data_min[a] <= data_max[a])) continue;  // no data yet
      const double beyond = std::min(data_min[a] - box.min[a], box.max[a] - data_max[a]);
      sampled[static_cast<std::size_t>(a)] = data_max[a] - data_min[a] >= beyond;
    }
    return sampled;
  }

  // Along `axis` (not sampled): every node of a line of nodes along it that lies beyond the
  // line's outermost sample (past the edge it constrains) takes that sample's values as its
  // target, so that the field goes on as the slices' extrusion (the nearest-slice baseline's
  // assumption) instead of closing just beyond them; the thin-plate energy alone would let a
  // thin section sag away from the slices. Nodes already given a target keep it.
  void add_extrusion_prior(int axis, std::vector<double>& weight,
                           std::vector<double>& target) const {
    const Level& g = levels[0];
    const std::size_t k = static_cast<std::size_t>(materials);
    const int layers = axis == 0 ? g.nx : axis == 1 ? g.ny : g.nz;
    const std::size_t stride = axis == 0   ? 1
                               : axis == 1 ? static_cast<std::size_t>(g.nx)
                                           : static_cast<std::size_t>(g.nx) * g.ny;
    struct End {
      double at = 0.0;  // in layers along the axis
      const double* values = nullptr;
    };
    std::vector<End> lowest(g.size()), highest(g.size());  // per line: by its first node
    for (const Contribution& c : data) {
      if (c.axis != axis) continue;
      for (std::size_t e = 0; e < c.nodes.size(); ++e) {
        const std::size_t layer = c.nodes[e] / stride % static_cast<std::size_t>(layers);
        const std::size_t line = c.nodes[e] - layer * stride;
        const double at = static_cast<double>(layer) + c.positions[e];
        const double* values = c.targets.data() + e * k;
        if (!lowest[line].values || at < lowest[line].at) lowest[line] = {at, values};
        if (!highest[line].values || at > highest[line].at) highest[line] = {at, values};
      }
    }
    for (std::size_t line = 0; line < g.size(); ++line) {
      if (!lowest[line].values) continue;
      for (int layer = 0; layer < layers; ++layer) {
        const End* end = layer >= std::floor(highest[line].at) + 2 ? &highest[line]
                         : layer <= std::ceil(lowest[line].at) - 2 ? &lowest[line]
                                                                   : nullptr;
        const std::size_t node = line + static_cast<std::size_t>(layer) * stride;
        if (!end || weight[node] > 0.0) continue;
        weight[node] = options.extrusion_weight;
        std::copy(end->values, end->values + k, target.begin() + node * k);
      }
    }
  }

  // The closing on and beyond the box's faces: those across sampled axes, and the others where
  // no extrusion reaches.
  void add_closing(const std::array<bool, 3>& sampled, std::vector<double>& weight,
                   std::vector<double>& target) const {
    const Level& g = levels[0];
    const std::size_t k = static_cast<std::size_t>(materials);
    const double margin = 1e-9 * box.diagonal();
    for (int kz = 0; kz < g.nz; ++kz)
      for (int j = 0; j < g.ny; ++j)
        for (int i = 0; i < g.nx; ++i) {
          const Vec3 p = box.min + spacing * Vec3(i, j, kz);
          bool on_face = false, across_sampled = false;
          for (int a = 0; a < 3; ++a) {
            const bool on = p[a] <= box.min[a] + margin || p[a] >= box.max[a] - margin;
            on_face |= on;
            across_sampled |= on && sampled[static_cast<std::size_t>(a)];
          }
          const std::size_t node = g.index(i, j, kz);
          if (!on_face || (!across_sampled && weight[node] > 0.0)) continue;
          weight[node] = options.closing_weight;
          for (std::size_t m = 0; m < k; ++m) target[node * k + m] = -truncation_mm[m];
        }
  }

  // Sets the priors for the data so far, adding their change to the operator and the
  // right-hand side. While every axis is sampled they are the closing alone, set once, unless
  // `targets_moved` (a truncation changed, and with it the closing's target).
  void update_priors(bool targets_moved = false) {
    const std::array<bool, 3> sampled = sampled_axes();
    const bool all_sampled = sampled[0] && sampled[1] && sampled[2];
    if (all_sampled && priors_all_sampled && !targets_moved) return;
    Level& g = levels[0];
    const std::size_t k = static_cast<std::size_t>(materials), size = g.size();
    prior_weight.resize(size, 0.0);
    prior_target.resize(size * k, 0.0);
    std::vector<double> weight(size, 0.0), target(size * k, 0.0);
    for (int a = 0; a < 3; ++a)
      if (!sampled[static_cast<std::size_t>(a)]) add_extrusion_prior(a, weight, target);
    add_closing(sampled, weight, target);
    // A changed weight changes the operator (every material); a changed target, one material.
    bool weights_changed = false;
    std::vector<char> targets_changed(k, 0);
    for (std::size_t node = 0; node < size; ++node) {
      if (weight[node] != prior_weight[node]) {
        g.data_diagonal[node] += weight[node] - prior_weight[node];
        weights_changed = true;
      }
      for (std::size_t m = 0; m < k; ++m) {
        const double before = prior_weight[node] * prior_target[node * k + m];
        const double after = weight[node] * target[node * k + m];
        if (after == before) continue;
        weighted_targets[m * size + node] += after - before;
        targets_changed[m] = 1;
      }
    }
    prior_weight = std::move(weight);
    prior_target = std::move(target);
    priors_all_sampled = all_sampled;
    if (weights_changed) weights_dirty = true;
    // New terms: solve() must not take their materials as fitted.
    for (std::size_t m = 0; m < k; ++m)
      if (weights_changed || targets_changed[m])
        misfit_mm[m] = std::numeric_limits<double>::infinity();
  }

  // Material m's truncation grows to `after` (mm), as if its data had been computed with it:
  // only the samples the old truncation clamped can change (a bound below the old truncation
  // stays the least), so those take their own distance and their bounds by the other slices
  // again, and the right-hand side follows them and the priors.
  void grow_truncation(std::size_t m, double after) {
    const double before = truncation_mm[m];
    truncation_mm[m] = after;
    for (auto& slice_distances : distances)
      slice_distances->set_truncation(static_cast<int>(m) + 1, after);
    std::vector<std::vector<std::pair<std::size_t, double>>> changes(data.size());
    tbb::parallel_for(std::size_t{0}, data.size(),
                      [&](std::size_t a) { changes[a] = reclamp_slice(a, m, before); });
    for (std::size_t a = 0; a < data.size(); ++a) retarget(a, changes[a]);
    // The priors follow: the closing's target is -truncation, an extrusion's the samples'.
    update_priors(/*targets_moved=*/true);
    move_plateaus(solution[m], before, after);
    misfit_mm[m] = std::numeric_limits<double>::infinity();
  }

  // Slice a's samples of material m that the truncation `before` clamped, with their distance
  // and bounds at the current truncation; returns the changes as in tighten_slice.
  std::vector<std::pair<std::size_t, double>> reclamp_slice(std::size_t a, std::size_t m,
                                                            double before) {
    Contribution& c = data[a];
    const PreparedSlice& slice = slices[a];
    const std::size_t k = static_cast<std::size_t>(materials);
    // Per sample, K values of which only material m's is not 0 (a value of 0 is never
    // tightened), so that tighten() bounds material m alone.
    std::vector<double> values(c.targets.size(), 0.0), scratch(k);
    std::vector<std::size_t> clamped;
    for (std::size_t e = 0; e < c.points.size(); ++e) {
      // An inside value below the truncation may still have come from a clamped upper bound
      // (inside_distance): those are taken again too.
      const bool unseen =
          distances[a]->sees_unknown_edges(static_cast<int>(m) + 1) && c.targets[e * k + m] > 0.0;
      if (!unseen && std::abs(c.targets[e * k + m]) < before * (1.0 - 1e-12)) continue;
      const Vec3 r = c.points[e] - slice.origin;
      values[e * k + m] = distances[a]->signed_distance(static_cast<int>(m) + 1,
                                                        Vec2(r.dot(slice.u), r.dot(slice.v)));
      clamped.push_back(e);
    }
    std::vector<std::pair<std::size_t, double>> changes;
    if (clamped.empty()) return changes;
    for (std::size_t b = 0; b < slices.size(); ++b) {
      if (b == a) continue;
      for_samples_near(c, slices[b], truncation_mm[m], [&](std::size_t e) {
        if (values[e * k + m] != 0.0)
          tighten(c.points[e], values.data() + e * k, slices[b], *distances[b], least_bound_mm(),
                  scratch);
      });
    }
    for (const std::size_t e : clamped) {
      double& target = c.targets[e * k + m];
      if (values[e * k + m] == target) continue;
      changes.emplace_back(e * k + m, target);
      target = values[e * k + m];
    }
    return changes;
  }

  // A material's truncation changed from `before` to `after`: its data and closing values at
  // +-before moved to +-after, the distances within it did not. The solution's plateaus are
  // moved with them (linearly from half the old truncation outwards), which leaves the solve
  // the local change only.
  static void move_plateaus(std::vector<double>& values, double before, double after) {
    if (before == after || !(before > 0.0)) return;
    for (double& value : values) {
      const double u = std::clamp(value / before, -1.0, 1.0);
      const double moved = std::copysign(std::max(0.0, 2.0 * std::abs(u) - 1.0), u);
      value += (after - before) * moved;
    }
  }

  void refresh_weights() {
    if (!weights_dirty) return;
    lump_finest_data(levels[0]);
    for (std::size_t l = 1; l < levels.size(); ++l)
      restrict_to_coarse(levels[l - 1], levels[l - 1].weight, levels[l], levels[l].weight);
    for (Level& level : levels) update_inverse_diagonal(level);
    weights_dirty = false;
  }

  std::size_t block_index(int bi, int bj, int bk) const {
    return (static_cast<std::size_t>(bk) * blocks[1] + bj) * blocks[0] + bi;
  }

  // After a solve: the blocks in which some node of some material moved by more than the
  // resample tolerance since it was sampled take the solution again (all of them at the first
  // solve), and are marked as changed by this solve.
  void resample_changed_blocks() {
    ++generation;
    const Level& g = levels[0];
    if (!sampled_once) {
      sampled_once = true;
      sampled = solution;
      block_changed_at.assign(static_cast<std::size_t>(blocks[0]) * blocks[1] * blocks[2],
                              generation);
      stencil_changed_at.assign(levels[0].size(), generation);
      return;
    }
    const double tolerance_mm = options.resample_tolerance * spacing;
    for_planes(blocks[2], [&](int bk) {
      const int k0 = bk * kBlock, k1 = std::min(g.nz, k0 + kBlock);
      for (int bj = 0; bj < blocks[1]; ++bj)
        for (int bi = 0; bi < blocks[0]; ++bi) {
          const int j0 = bj * kBlock, j1 = std::min(g.ny, j0 + kBlock);
          const int i0 = bi * kBlock, i1 = std::min(g.nx, i0 + kBlock);
          auto for_rows = [&](const auto& body) {
            for (std::size_t m = 0; m < solution.size(); ++m)
              for (int k = k0; k < k1; ++k)
                for (int j = j0; j < j1; ++j) {
                  const std::size_t row = g.index(0, j, k);
                  body(solution[m].data() + row, sampled[m].data() + row);
                }
          };
          double moved = 0.0;
          for_rows([&](const double* now, double* before) {
            for (int i = i0; i < i1; ++i) moved = std::max(moved, std::abs(now[i] - before[i]));
          });
          if (!(moved > tolerance_mm)) continue;
          for_rows([&](const double* now, double* before) {
            std::copy(now + i0, now + i1, before + i0);
          });
          block_changed_at[block_index(bi, bj, bk)] = generation;
        }
    });
    spread_block_changes();
  }

  // stencil_changed_at from block_changed_at, one axis after the other: along an axis the
  // nodes i0 - 1 .. i0 + 2 (clamped) lie in one or two neighbouring blocks.
  void spread_block_changes() {
    const Level& g = levels[0];
    const int dims[3] = {g.nx, g.ny, g.nz};
    auto first = [](int i) { return std::max(0, i - 1) / kBlock; };
    auto last = [&](int a, int i) { return std::min(dims[a] - 1, i + 2) / kBlock; };
    // Along x: blocks[2] x blocks[1] rows of nx; then y: blocks[2] x ny rows; then z: the grid.
    std::vector<std::uint32_t> along_x(static_cast<std::size_t>(blocks[2]) * blocks[1] * g.nx);
    for (int bk = 0; bk < blocks[2]; ++bk)
      for (int bj = 0; bj < blocks[1]; ++bj)
        for (int i = 0; i < g.nx; ++i)
          along_x[(static_cast<std::size_t>(bk) * blocks[1] + bj) * g.nx + i] =
              std::max(block_changed_at[block_index(first(i), bj, bk)],
                       block_changed_at[block_index(last(0, i), bj, bk)]);
    std::vector<std::uint32_t> along_y(static_cast<std::size_t>(blocks[2]) * g.ny * g.nx);
    for (int bk = 0; bk < blocks[2]; ++bk)
      for (int j = 0; j < g.ny; ++j)
        for (int i = 0; i < g.nx; ++i) {
          const std::size_t row = static_cast<std::size_t>(bk) * blocks[1];
          along_y[(static_cast<std::size_t>(bk) * g.ny + j) * g.nx + i] = std::max(
              along_x[(row + first(j)) * g.nx + i], along_x[(row + last(1, j)) * g.nx + i]);
        }
    stencil_changed_at.resize(g.size());
    for_planes(g.nz, [&](int k) {
      const std::size_t below = static_cast<std::size_t>(first(k)) * g.ny * g.nx;
      const std::size_t above = static_cast<std::size_t>(last(2, k)) * g.ny * g.nx;
      for (std::size_t n = 0; n < static_cast<std::size_t>(g.ny) * g.nx; ++n)
        stencil_changed_at[g.index(0, 0, k) + n] = std::max(along_y[below + n], along_y[above + n]);
    });
  }

  // The node before `point` (world mm) on each axis, clamped so that [i0, i0 + 1] is a cell of
  // the grid, and the position in that cell (0 on an axis of one node).
  void locate(const Vec3& point, int i0[3], double t[3]) const {
    const Level& g = levels[0];
    const Vec3 q = (point - box.min) / spacing;
    const int dims[3] = {g.nx, g.ny, g.nz};
    for (int a = 0; a < 3; ++a) {
      const double clamped = std::clamp(q[a], 0.0, static_cast<double>(dims[a] - 1));
      i0[a] = std::min(static_cast<int>(std::floor(clamped)), dims[a] - 2);
      i0[a] = std::max(i0[a], 0);
      t[a] = dims[a] > 1 ? clamped - i0[a] : 0.0;
    }
  }

  // The functions at `point` (world mm) into out[0 .. materials]: each material's sampled
  // solution by Catmull-Rom weights per axis over nodes i0 - 1 .. i0 + 2 (clamped at the faces):
  // cubic between the nodes, so the fine vertices see the solution's curvature; out[0], the
  // outside's, is minus the largest.
  void interpolate(const Vec3& point, double* out) const {
    const Level& g = levels[0];
    const int dims[3] = {g.nx, g.ny, g.nz};
    int i0[3];
    double t[3];
    locate(point, i0, t);
    double w[3][4];
    int at[3][4];
    for (int a = 0; a < 3; ++a) {
      const double x = t[a], x2 = x * x, x3 = x2 * x;
      w[a][0] = 0.5 * (-x3 + 2.0 * x2 - x);
      w[a][1] = 0.5 * (3.0 * x3 - 5.0 * x2 + 2.0);
      w[a][2] = 0.5 * (-3.0 * x3 + 4.0 * x2 + x);
      w[a][3] = 0.5 * (x3 - x2);
      for (int o = 0; o < 4; ++o) at[a][o] = std::clamp(i0[a] - 1 + o, 0, dims[a] - 1);
    }
    double best = -std::numeric_limits<double>::infinity();
    // On and beyond the box's faces, every material is outside: an organ that goes through a
    // face (extruded along an axis the slices do not sample) is cut there, and its mesh closed.
    const double margin = 1e-9 * box.diagonal();
    const bool outside =
        ((point.array() <= box.min.array() + margin) || (point.array() >= box.max.array() - margin))
            .any();
    for (int m = 0; m < materials; ++m) {
      const std::vector<double>& f = sampled[static_cast<std::size_t>(m)];
      double value = 0.0;
      for (int c = 0; c < 4; ++c)
        for (int b = 0; b < 4; ++b) {
          const double wcb = w[2][c] * w[1][b];
          const std::size_t row = g.index(0, at[1][b], at[2][c]);
          for (int a = 0; a < 4; ++a)
            value += wcb * w[0][a] * f[row + static_cast<std::size_t>(at[0][a])];
        }
      if (outside) value = std::min(value, -truncation_mm[static_cast<std::size_t>(m)]);
      out[m + 1] = value;
      best = std::max(best, value);
    }
    out[0] = materials > 0 ? -best : 0.0;
  }

  struct StepSums {
    double largest = 0.0;  // mm
    double squares = 0.0;
  };
  // When a solve stops: no iteration moved a node whose value (before or after it) lies within
  // `band_mm` of zero, or changed sign, by more than `tolerance_mm`.
  struct SolveStop {
    double tolerance_mm = 0.0;
    double band_mm = std::numeric_limits<double>::infinity();
  };
  // A field's first solve (a one-shot reconstruction, a rebuild) tests every node at the
  // solver's tolerance; an update's, which starts from this field's last solution, at the online
  // tolerance and only the nodes near material m's zero set, those the mesh reads.
  SolveStop solve_stop(std::size_t m) const {
    if (!solved) return {options.tolerance * spacing, std::numeric_limits<double>::infinity()};
    return {options.online_tolerance * spacing, options.online_band * truncation_mm[m]};
  }

  // Conjugate gradients on A x = b, preconditioned by one V-cycle, from x. Returns the
  // iterations.
  int solve_one(std::vector<double>& x, const double* b, SolveWork& work, const SolveStop& stop) {
    const Level& g = levels[0];
    const std::size_t count = g.size();
    work.levels.resize(levels.size());
    std::vector<double>& r = work.residual;
    std::vector<double>& p = work.direction;
    std::vector<double>& q = work.product;
    r.resize(count);
    p.resize(count);
    q.resize(count);
    const SolverKernels& kernels = solver_kernels(options.simd);
    kernels.apply_operator(g, x.data(), q.data());
    for_nodes(count, [&](std::size_t n) { r[n] = b[n] - q[n]; });
    const double norm_b = std::sqrt(dot(b, b, count));
    if (!(norm_b > 0.0)) {
      std::fill(x.begin(), x.end(), 0.0);
      return 0;
    }
    double residual = std::sqrt(dot(r.data(), r.data(), count)) / norm_b;
    int iteration = 0;
    double rz = 0.0;
    // Converged when an iteration moves no node of the band by more than the tolerance: the
    // iterations converge geometrically, so what is left is of that order.
    const double step_tolerance_mm = stop.tolerance_mm;
    double step_mm = std::numeric_limits<double>::infinity();
    // The V-cycle's right-hand side: the residual in single precision, written by each
    // iteration's update pass after this.
    Work& w = work.levels[0];
    w.fit(count);
    std::copy(r.begin(), r.end(), w.b.begin());
    while (step_mm > step_tolerance_mm && residual > kSolvedResidual &&
           iteration < options.max_iterations) {
      kernels.v_cycle(levels, work.levels, 0);
      const std::vector<Real>& z = w.x;  // the preconditioned residual
      const double rz_next = dot(r.data(), z.data(), count);
      const double beta = iteration == 0 ? 0.0 : rz_next / rz;
      for_nodes(count, [&](std::size_t n) { p[n] = z[n] + beta * p[n]; });
      rz = rz_next;
      kernels.apply_operator(g, p.data(), q.data());
      const double alpha = rz / dot(p.data(), q.data(), count);
      // One pass: the update, the largest step in the band, the residual's squares (in dot()'s
      // ranges and order, so the same sum) and the next V-cycle's right-hand side.
      const StepSums sums = tbb::parallel_deterministic_reduce(
          tbb::blocked_range<std::size_t>(0, count, 1 << 14), StepSums{},
          [&](const tbb::blocked_range<std::size_t>& range, StepSums sum) {
            Real* next_b = w.b.data();
            for (std::size_t n = range.begin(); n < range.end(); ++n) {
              const double before = x[n];
              x[n] += alpha * p[n];
              r[n] -= alpha * q[n];
              next_b[n] = static_cast<Real>(r[n]);
              sum.squares += r[n] * r[n];
              // Within the band before or after the step, or across it (its sign changed).
              if (std::min(std::abs(before), std::abs(x[n])) <= stop.band_mm ||
                  (before < 0.0) != (x[n] < 0.0))
                sum.largest = std::max(sum.largest, std::abs(alpha * p[n]));
            }
            return sum;
          },
          [](const StepSums& a, const StepSums& b) {
            return StepSums{std::max(a.largest, b.largest), a.squares + b.squares};
          });
      step_mm = sums.largest;
      residual = std::sqrt(sums.squares) / norm_b;
      ++iteration;
    }
    if (step_mm > step_tolerance_mm && residual > kSolvedResidual)
      log_warning("thin-plate field: the solve stopped after " + std::to_string(iteration) +
                  " iterations with steps of " + std::to_string(step_mm) + " mm (tolerance " +
                  std::to_string(step_tolerance_mm) + " mm); the surface may be off by about that");
    return iteration;
  }

  Grid(const Box3& grid_box, double spacing_mm, int material_count, ThinPlateOptions grid_options,
       std::vector<double> extents);
  void add_slices(std::vector<PreparedSlice> added);
  ThinPlateSolveStats solve();
  bool start_from(const Grid& other);
  bool grow_extents(const std::vector<double>& extents);
  std::uint32_t changed_at(const Vec3& point) const;
};

double truncation_extent(double extent_mm) {
  if (!(extent_mm > 0.0)) return 0.0;
  return std::exp2(std::ceil(4.0 * std::log2(extent_mm) - 1e-9) / 4.0);
}

std::vector<Box3> material_boxes(const std::vector<PreparedSlice>& slices, int materials) {
  std::vector<Box3> boxes(static_cast<std::size_t>(materials), empty_box());
  for (const PreparedSlice& slice : slices)
    for (int m = 1; m <= materials && static_cast<std::size_t>(m) < slice.rings_by_material.size();
         ++m)
      for (const Ring2& ring : slice.rings_by_material[static_cast<std::size_t>(m)])
        for (const Vec2& p : ring) {
          const Vec3 q = slice.origin + p.x() * slice.u + p.y() * slice.v;
          Box3& box = boxes[static_cast<std::size_t>(m - 1)];
          box.min = box.min.cwiseMin(q);
          box.max = box.max.cwiseMax(q);
        }
  return boxes;
}

std::vector<double> box_extents(const std::vector<Box3>& boxes) {
  std::vector<double> extents;
  for (const Box3& box : boxes)
    extents.push_back(box.min.x() <= box.max.x() ? box.diagonal() : 0.0);
  return extents;
}

std::vector<Box3> own_grid_boxes(const Box3& box, double finest_cell_mm,
                                 const std::vector<Box3>& material_boxes,
                                 const ThinPlateOptions& options) {
  std::vector<Box3> own(material_boxes.size(), empty_box());
  if (!options.own_grids || options.coarsening < 1) return own;
  // Together the materials must sample every axis of the box, as the slices must for the
  // closing (sampled_axes): otherwise the box's padding along an axis is where the extrusion
  // prior carries the organs on, which a box of their own would cut short.
  Box3 all = empty_box();
  for (const Box3& b : material_boxes)
    if (!is_empty(b)) all = {all.min.cwiseMin(b.min), all.max.cwiseMax(b.max)};
  if (is_empty(all)) return own;
  for (int a = 0; a < 3; ++a)
    if (all.max[a] - all.min[a] < std::min(all.min[a] - box.min[a], box.max[a] - all.max[a]))
      return own;
  auto nodes = [](const Box3& b, double spacing) {
    double count = 1.0;
    for (int a = 0; a < 3; ++a) count *= std::ceil(b.size()[a] / spacing - 1e-9) + 1.0;
    return count;
  };
  const double shared_spacing = finest_cell_mm * std::ldexp(1.0, options.coarsening);
  const double shared_nodes = nodes(box, shared_spacing);
  // Rounded out to a lattice of 8 finest cells, so that an organ that grows online keeps its
  // grid over several millimetres (a new box rebuilds that grid).
  const double step = kOwnGridStep * finest_cell_mm;
  for (std::size_t m = 0; m < material_boxes.size(); ++m) {
    // An organ that spans this many solve cells is resolved about as well as by a field of
    // its own (whose default depth gives ~53 across its extent): only smaller ones gain.
    if (is_empty(material_boxes[m]) ||
        material_boxes[m].diagonal() >= kOwnGridCells * shared_spacing)
      continue;
    const Box3 padded = reconstruction_box(material_boxes[m]);
    Box3 rounded;
    for (int a = 0; a < 3; ++a) {
      rounded.min[a] =
          std::max(box.min[a], box.min[a] + step * std::floor((padded.min[a] - box.min[a]) / step));
      rounded.max[a] =
          std::min(box.max[a], box.min[a] + step * std::ceil((padded.max[a] - box.min[a]) / step));
    }
    if (nodes(rounded, finest_cell_mm) <= shared_nodes) own[m] = rounded;
  }
  return own;
}

// ---- One grid -------------------------------------------------------------------------------

ThinPlateField::Grid::Grid(const Box3& grid_box, double spacing_mm, int material_count,
                           ThinPlateOptions grid_options, std::vector<double> extents) {
  box = grid_box;
  materials = material_count;
  options = std::move(grid_options);
  spacing = spacing_mm;
  extents.resize(static_cast<std::size_t>(materials), 0.0);
  for (const double extent : extents) truncation_mm.push_back(truncation_for(extent));
  extents_mm = std::move(extents);
  // Cells per axis, rounded up to a multiple of 2^coarsenings so that every level's nodes are
  // every other node of the finer one; the coarsest keeps at least 4 cells on its shortest axis.
  std::array<int, 3> cells{};
  for (int a = 0; a < 3; ++a)
    cells[static_cast<std::size_t>(a)] =
        std::max(1, static_cast<int>(std::ceil(box.size()[a] / spacing - 1e-9)));
  const int shortest = *std::min_element(cells.begin(), cells.end());
  int coarsenings = 0;
  while (coarsenings < 8 && (shortest >> (coarsenings + 1)) >= 4) ++coarsenings;
  const int multiple = 1 << coarsenings;
  for (int& c : cells) c = (c + multiple - 1) / multiple * multiple;
  const double node_count = (cells[0] + 1.0) * (cells[1] + 1.0) * (cells[2] + 1.0);
  if (node_count > kMaxNodes)
    throw UnsupportedInput("thin-plate field: its grid over the box would have " +
                           std::to_string(static_cast<long long>(node_count)) + " nodes (at most " +
                           std::to_string(static_cast<long long>(kMaxNodes)) +
                           "); reconstruct at a smaller depth (--depth; the default gives finest "
                           "cells of 1/128 of the box diagonal)");
  for (int l = 0; l <= coarsenings; ++l) {
    Level level;
    level.nx = (cells[0] >> l) + 1;
    level.ny = (cells[1] >> l) + 1;
    level.nz = (cells[2] >> l) + 1;
    level.scale = std::ldexp(1.0, -l);
    const std::size_t size = level.size();
    level.weight.assign(size, 0.0);
    if (l == 0) {
      level.data_diagonal.assign(size, 0.0);
      for (auto& edges : level.data_edge) edges.assign(size, 0.0);
      level.zero_row.assign(static_cast<std::size_t>(level.nx), 0.0);
    }
    levels.push_back(std::move(level));
  }
  const std::size_t nodes = levels[0].size();
  blocks = {(levels[0].nx + kBlock - 1) / kBlock, (levels[0].ny + kBlock - 1) / kBlock,
            (levels[0].nz + kBlock - 1) / kBlock};
  weighted_targets.assign(nodes * static_cast<std::size_t>(materials), 0.0);
  for (int m = 0; m < materials; ++m)
    solution.emplace_back(nodes, -truncation_mm[static_cast<std::size_t>(m)]);
  sampled = solution;
  misfit_mm.assign(static_cast<std::size_t>(materials), 0.0);
  block_changed_at.assign(static_cast<std::size_t>(blocks[0]) * blocks[1] * blocks[2], 0);
  stencil_changed_at.assign(nodes, 0);
  update_priors();
}

void ThinPlateField::Grid::add_slices(std::vector<PreparedSlice> added) {
  const std::size_t first = slices.size();
  for (PreparedSlice& slice : added) slices.push_back(std::move(slice));
  const std::size_t count = slices.size();
  for (std::size_t k = 0; k < first; ++k) distances[k]->rebind(slices[k]);
  distances.resize(count);
  data.resize(count);
  // Each slice's data in parallel, then tightened by the other slices (the new ones by all, the
  // earlier ones by the new ones); each slice writes only its own values, and a value's bound
  // is a minimum (exact in any order), so the data are the same whatever the threads and
  // whether the slices came one by one or at once.
  tbb::parallel_for(first, count, [&](std::size_t k) {
    distances[k] = std::make_unique<SliceDistances>(slices[k], materials, truncation_mm,
                                                    options.shadow_casters, thinnest_mm());
    data[k] = slice_data(slices[k], *distances[k]);
    if (distances[k]->dilate_unsampled_rings(in_plane(data[k].points, slices[k])))
      data[k] = slice_data(slices[k], *distances[k]);
  });
  std::vector<std::vector<std::pair<std::size_t, double>>> changes(first);
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t a) {
    if (a < first)
      changes[a] = tighten_slice(a, first, count);
    else
      tighten_slice(a, 0, count);
  });
  // Added in slice order: the same sums whatever the threads.
  for (std::size_t a = 0; a < first; ++a) retarget(a, changes[a]);
  for (std::size_t k = first; k < count; ++k) add(data[k]);
  for (std::size_t k = first; k < count; ++k)
    for (const Vec3& p : data[k].points) {
      data_min = data_min.cwiseMin(p);
      data_max = data_max.cwiseMax(p);
    }
  update_priors();
}

ThinPlateSolveStats ThinPlateField::Grid::solve() {
  ThinPlateSolveStats stats;
  Stopwatch clock;
  const std::size_t count = levels[0].size();
  const double fitted_mm = options.online_tolerance * spacing;
  std::vector<std::size_t> solved_materials;
  for (std::size_t m = 0; m < misfit_mm.size(); ++m) {
    // The field already fits this material's new data to the online tolerance, and nothing
    // else changed since its last solve (no removal: a rebuilt field has not solved yet): a
    // solve would move it by about as much as its tolerance allows.
    if (solved && misfit_mm[m] <= fitted_mm)
      ++stats.unchanged_materials;
    else
      solved_materials.push_back(m);
    misfit_mm[m] = 0.0;
  }
  // Not when every material is left as it is: the next solve does it.
  if (!solved_materials.empty()) refresh_weights();
  std::vector<SolveStop> stops;
  for (const std::size_t m : solved_materials) stops.push_back(solve_stop(m));
  // The materials at once, each with its own work vectors (the operator is shared): one solve's
  // passes over the grid scale poorly across threads (a 207k-node grid: 1.4 times as fast on
  // two), two solves side by side well. Each solve is the same whatever runs beside it.
  solve_work.resize(misfit_mm.size());
  std::vector<int> iterations(solved_materials.size(), 0);
  tbb::parallel_for(std::size_t{0}, solved_materials.size(), [&](std::size_t i) {
    const std::size_t m = solved_materials[i];
    iterations[i] =
        solve_one(solution[m], weighted_targets.data() + m * count, solve_work[m], stops[i]);
  });
  for (const int n : iterations) stats.iterations += n;
  solved = true;
  resample_changed_blocks();
  stats.solve_s = clock.seconds();
  stats.nodes = count;
  return stats;
}

bool ThinPlateField::Grid::start_from(const Grid& other) {
  if (materials != other.materials || spacing != other.spacing || box.min != other.box.min ||
      box.max != other.box.max || levels[0].nx != other.levels[0].nx ||
      levels[0].ny != other.levels[0].ny || levels[0].nz != other.levels[0].nz)
    return false;
  solution = other.solution;
  for (std::size_t m = 0; m < solution.size(); ++m)
    move_plateaus(solution[m], other.truncation_mm[m], truncation_mm[m]);
  sampled = other.sampled;
  sampled_once = other.sampled_once;
  block_changed_at = other.block_changed_at;
  stencil_changed_at = other.stencil_changed_at;
  generation = other.generation;
  return true;
}

bool ThinPlateField::Grid::grow_extents(const std::vector<double>& extents) {
  if (extents.size() != extents_mm.size()) return false;
  std::vector<double> truncations;
  for (std::size_t m = 0; m < extents.size(); ++m) {
    truncations.push_back(truncation_for(extents[m]));
    if (truncations[m] < truncation_mm[m]) return false;
  }
  for (std::size_t m = 0; m < truncations.size(); ++m)
    if (truncations[m] != truncation_mm[m]) grow_truncation(m, truncations[m]);
  extents_mm = extents;
  return true;
}

std::uint32_t ThinPlateField::Grid::changed_at(const Vec3& point) const {
  int i0[3];
  double t[3];
  locate(point, i0, t);
  return stencil_changed_at[levels[0].index(i0[0], i0[1], i0[2])];
}

// ---- The field: a grid over the box, and the grids of small organs --------------------------

struct ThinPlateField::Impl {
  // One grid and the field's materials that it solves (0-based, ascending).
  struct Part {
    std::unique_ptr<Grid> grid;
    std::vector<std::size_t> materials;
    bool own = false;  // a material's own grid (else the grid over the box)
    // An own grid's material is -truncation beyond its box: the solve (generation) after which
    // that value last changed, for changed_at.
    std::uint32_t outside_changed_at = 0;
  };
  Box3 box;
  int materials = 0;
  double finest_cell_mm = 1.0;
  ThinPlateOptions options;
  std::vector<Part> parts;
  std::vector<Box3> own_boxes;  // per material (empty: none)
  std::vector<double> extents_mm;
  std::vector<PreparedSlice> slices;
  std::uint32_t generation = 0;

  Impl(const Box3& field_box, double finest_cell, int material_count,
       ThinPlateOptions field_options, std::vector<Box3> own, const std::vector<double>& extents)
      : box(field_box),
        materials(material_count),
        finest_cell_mm(finest_cell),
        options(std::move(field_options)),
        own_boxes(std::move(own)) {
    build(extents);
  }

  void build(const std::vector<double>& extents) {
    extents_mm = extents;
    extents_mm.resize(static_cast<std::size_t>(materials), 0.0);
    own_boxes.resize(static_cast<std::size_t>(materials), empty_box());
    Part shared;
    for (std::size_t m = 0; m < own_boxes.size(); ++m)
      if (is_empty(own_boxes[m])) shared.materials.push_back(m);
    // The grid over the box always exists (node_counts, sample_values), even with no material.
    const double spacing = finest_cell_mm * std::ldexp(1.0, std::max(0, options.coarsening));
    shared.grid = make_grid(box, spacing, shared.materials);
    parts.push_back(std::move(shared));
    for (std::size_t m = 0; m < own_boxes.size(); ++m)
      if (!is_empty(own_boxes[m])) {
        Part own{make_grid(own_boxes[m], finest_cell_mm, {m}), {m}, true};
        parts.push_back(std::move(own));
      }
  }

  std::unique_ptr<Grid> make_grid(const Box3& grid_box, double spacing,
                                  const std::vector<std::size_t>& subset) const {
    ThinPlateOptions grid_options = options;
    grid_options.shadow_casters.clear();
    std::vector<double> extents;
    for (const std::size_t m : subset) {
      grid_options.shadow_casters.push_back(m < options.shadow_casters.size() &&
                                            options.shadow_casters[m]);
      extents.push_back(extents_mm[m]);
    }
    return std::make_unique<Grid>(grid_box, spacing, static_cast<int>(subset.size()),
                                  std::move(grid_options), std::move(extents));
  }

  // `slice` with the materials of `subset` alone (renumbered 1..): another material's region
  // is outside to them, as it is across their true boundaries.
  static PreparedSlice restricted(const PreparedSlice& slice,
                                  const std::vector<std::size_t>& subset) {
    PreparedSlice out;
    out.origin = slice.origin;
    out.u = slice.u;
    out.v = slice.v;
    out.unit_normal = slice.unit_normal;
    out.unknown = slice.unknown;
    out.known = slice.known;
    out.outline_sd_mm = slice.outline_sd_mm;
    out.view = slice.view;
    out.rings_by_material.resize(subset.size() + 1);
    out.ring_bounds.resize(subset.size() + 1);
    out.ring_bands.resize(subset.size() + 1);
    for (std::size_t i = 0; i < subset.size(); ++i) {
      const std::size_t m = subset[i] + 1;
      if (m < slice.rings_by_material.size())
        out.rings_by_material[i + 1] = slice.rings_by_material[m];
      if (m < slice.ring_bounds.size()) out.ring_bounds[i + 1] = slice.ring_bounds[m];
      if (m < slice.ring_bands.size()) out.ring_bands[i + 1] = slice.ring_bands[m];
    }
    return out;
  }

  void add_slices(std::vector<PreparedSlice> added) {
    for (Part& part : parts) {
      if (part.materials.empty()) continue;  // every material has a grid of its own
      if (part.materials.size() == static_cast<std::size_t>(materials)) {
        part.grid->add_slices(added);
        continue;
      }
      std::vector<PreparedSlice> subset(added.size());
      tbb::parallel_for(std::size_t{0}, added.size(),
                        [&](std::size_t k) { subset[k] = restricted(added[k], part.materials); });
      part.grid->add_slices(std::move(subset));
    }
    for (PreparedSlice& slice : added) slices.push_back(std::move(slice));
  }

  // The materials' extents grew to `extents` and their own grids' boxes to `own` (the same
  // materials own grids): each grid takes its new truncations in place, and an own grid whose
  // box changed is built again over its new box from every slice held (its material's data
  // alone, on its small grid: the other grids keep theirs). False, and nothing changed, where a
  // truncation would shrink.
  bool grow(const std::vector<double>& extents, const std::vector<Box3>& own) {
    if (extents.size() != extents_mm.size()) return false;
    std::vector<std::vector<double>> per_part(parts.size());
    std::vector<bool> moved(parts.size(), false);
    for (std::size_t p = 0; p < parts.size(); ++p) {
      const Part& part = parts[p];
      for (const std::size_t m : part.materials) per_part[p].push_back(extents[m]);
      for (std::size_t i = 0; i < per_part[p].size(); ++i)
        if (part.grid->truncation_for(per_part[p][i]) < part.grid->truncation_mm[i]) return false;
      if (part.own) {
        const Box3& next = own[part.materials[0]];
        moved[p] = next.min != part.grid->box.min || next.max != part.grid->box.max;
      }
    }
    extents_mm = extents;
    own_boxes = own;
    for (std::size_t p = 0; p < parts.size(); ++p) {
      Part& part = parts[p];
      if (moved[p]) {
        rebuild_own(part);
        continue;
      }
      const std::vector<double> before = part.grid->truncation_mm;
      part.grid->grow_extents(per_part[p]);
      if (part.grid->truncation_mm != before) part.outside_changed_at = generation + 1;
    }
    return true;
  }

  // An own grid over the material's box in own_boxes, from every slice held; its blocks and
  // the points beyond its box are new at the next solve.
  void rebuild_own(Part& part) {
    const std::size_t m = part.materials[0];
    part.grid = make_grid(own_boxes[m], finest_cell_mm, part.materials);
    part.grid->generation = generation;
    part.outside_changed_at = generation + 1;
    std::vector<PreparedSlice> subset(slices.size());
    tbb::parallel_for(std::size_t{0}, slices.size(),
                      [&](std::size_t k) { subset[k] = restricted(slices[k], part.materials); });
    part.grid->add_slices(std::move(subset));
  }

  // Values of the K + 1 functions at `point`: each material from its grid (outside, at
  // -truncation, beyond its own grid's box), f_0 = -max.
  void interpolate(const Vec3& point, double* out, std::vector<double>& scratch) const {
    // One grid for every material (the common case): its values are the field's.
    if (parts.size() == 1) return parts[0].grid->interpolate(point, out);
    double best = -std::numeric_limits<double>::infinity();
    for (const Part& part : parts) {
      const Grid& g = *part.grid;
      if (part.materials.empty()) continue;
      const bool inside =
          ((point.array() >= g.box.min.array()) && (point.array() <= g.box.max.array())).all();
      if (part.own && !inside) {
        out[part.materials[0] + 1] = -g.truncation_mm[0];
      } else {
        scratch.resize(part.materials.size() + 1);
        g.interpolate(point, scratch.data());
        for (std::size_t i = 0; i < part.materials.size(); ++i)
          out[part.materials[i] + 1] = scratch[i + 1];
      }
      for (const std::size_t m : part.materials) best = std::max(best, out[m + 1]);
    }
    out[0] = materials > 0 ? -best : 0.0;
  }
};

ThinPlateField::ThinPlateField(const Box3& box, double finest_cell_mm, int materials,
                               ThinPlateOptions options, std::vector<double> extents_mm)
    : impl_(std::make_unique<Impl>(box, finest_cell_mm, materials, std::move(options),
                                   std::vector<Box3>{}, extents_mm)) {}

ThinPlateField::ThinPlateField(const Box3& box, double finest_cell_mm, int materials,
                               ThinPlateOptions options, const std::vector<Box3>& material_boxes)
    : impl_(std::make_unique<Impl>(box, finest_cell_mm, materials, options,
                                   own_grid_boxes(box, finest_cell_mm, material_boxes, options),
                                   box_extents(material_boxes))) {}

ThinPlateField::~ThinPlateField() = default;
ThinPlateField::ThinPlateField(ThinPlateField&&) noexcept = default;
ThinPlateField& ThinPlateField::operator=(ThinPlateField&&) noexcept = default;

void ThinPlateField::add_slices(std::vector<PreparedSlice> slices) {
  impl_->add_slices(std::move(slices));
}

ThinPlateSolveStats ThinPlateField::solve() {
  Impl& s = *impl_;
  Stopwatch clock;
  // The grids side by side: a small organ's grid alone scales poorly across threads.
  std::vector<ThinPlateSolveStats> each(s.parts.size());
  tbb::parallel_for(std::size_t{0}, s.parts.size(), [&](std::size_t p) {
    if (!s.parts[p].materials.empty()) each[p] = s.parts[p].grid->solve();
  });
  ++s.generation;
  ThinPlateSolveStats stats;
  for (std::size_t p = 0; p < each.size(); ++p) {
    stats.iterations += each[p].iterations;
    stats.nodes += each[p].nodes;
    // A grid without materials counts none unchanged.
    stats.unchanged_materials += each[p].unchanged_materials;
  }
  stats.solve_s = clock.seconds();
  return stats;
}

void ThinPlateField::evaluate(const std::vector<Vec3>& points, double* values) const {
  const Impl& s = *impl_;
  const std::size_t fc = static_cast<std::size_t>(s.materials) + 1;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      std::vector<double> scratch;
                      for (std::size_t p = range.begin(); p < range.end(); ++p)
                        s.interpolate(points[p], values + p * fc, scratch);
                    });
}

bool ThinPlateField::start_from(const ThinPlateField& other) {
  Impl& s = *impl_;
  const Impl& o = *other.impl_;
  if (s.materials != o.materials || s.finest_cell_mm != o.finest_cell_mm ||
      s.box.min != o.box.min || s.box.max != o.box.max || s.parts.size() != o.parts.size())
    return false;
  for (std::size_t p = 0; p < s.parts.size(); ++p)
    if (s.parts[p].materials != o.parts[p].materials) return false;
  // A grid whose box changed (an organ outgrew its own) starts afresh, its blocks all new at
  // the next solve; the others go on from their last solution.
  for (std::size_t p = 0; p < s.parts.size(); ++p) {
    Impl::Part& part = s.parts[p];
    part.outside_changed_at = o.parts[p].outside_changed_at;
    if (part.grid->start_from(*o.parts[p].grid)) continue;
    part.grid->generation = o.generation;
    part.outside_changed_at = o.generation + 1;
  }
  s.generation = o.generation;
  return true;
}

bool ThinPlateField::grow_extents(const std::vector<double>& extents_mm) {
  return impl_->grow(extents_mm, impl_->own_boxes);
}

bool ThinPlateField::grow_boxes(const std::vector<Box3>& material_boxes) {
  Impl& s = *impl_;
  if (material_boxes.size() != s.own_boxes.size()) return false;
  const std::vector<Box3> own = own_grid_boxes(s.box, s.finest_cell_mm, material_boxes, s.options);
  // Another choice of which materials have grids of their own: a rebuild.
  for (std::size_t m = 0; m < own.size(); ++m)
    if (is_empty(own[m]) != is_empty(s.own_boxes[m])) return false;
  return s.grow(box_extents(material_boxes), own);
}

std::vector<double> ThinPlateField::sample_values() const {
  std::vector<double> values;
  for (const Grid::Contribution& c : impl_->parts[0].grid->data)
    values.insert(values.end(), c.targets.begin(), c.targets.end());
  return values;
}

std::vector<std::vector<Vec3>> ThinPlateField::sample_points() const {
  std::vector<std::vector<Vec3>> points;
  for (const Grid::Contribution& c : impl_->parts[0].grid->data) points.push_back(c.points);
  return points;
}

std::uint32_t ThinPlateField::generation() const { return impl_->generation; }

std::uint32_t ThinPlateField::changed_at(const Vec3& point) const {
  std::uint32_t latest = 0;
  for (const Impl::Part& part : impl_->parts) {
    const Grid& g = *part.grid;
    if (part.own &&
        !((point.array() >= g.box.min.array()) && (point.array() <= g.box.max.array())).all())
      latest = std::max(latest, part.outside_changed_at);
    else
      latest = std::max(latest, g.changed_at(point));
  }
  return latest;
}

int ThinPlateField::function_count() const { return impl_->materials + 1; }
const std::vector<double>& ThinPlateField::extents() const { return impl_->extents_mm; }
const std::vector<PreparedSlice>& ThinPlateField::slices() const { return impl_->slices; }
std::array<int, 3> ThinPlateField::node_counts() const {
  const Level& g = impl_->parts[0].grid->levels[0];
  return {g.nx, g.ny, g.nz};
}
std::vector<Box3> ThinPlateField::own_boxes() const { return impl_->own_boxes; }

}  // namespace sonoshape::recon
