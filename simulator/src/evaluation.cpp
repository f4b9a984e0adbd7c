#include "sonoshape/simulator/evaluation.hpp"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Simple_cartesian.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <sstream>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::simulator {
namespace {

using Epick = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point2 = Epick::Point_2;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr std::uint64_t kSampleSeed = 0x5eed5a3d1e5ULL;

// ---- The sample grid --------------------------------------------------------------------

// Cell centres of an n^3 grid over the box. Columns are shifted in x and y by a tiny irrational
// fraction of a cell so that they do not run exactly through mesh vertices or edges placed on
// a grid of the same box (marching-cubes output, axis-aligned test shapes).
struct SampleGrid {
  int n = 0;
  Vec3 first;  // position of sample (0, 0, 0)
  Vec3 step;

  SampleGrid(const Box3& box, int resolution) : n(resolution) {
    step = box.size() / resolution;
    first = box.min + 0.5 * step;
    first.x() += (std::numbers::sqrt2 - 1.0) * 1e-5 * step.x();
    first.y() += (std::numbers::pi - 3.0) * 1e-5 * step.y();
  }
  std::size_t columns() const { return static_cast<std::size_t>(n) * n; }
  std::size_t size() const { return columns() * n; }
  // Samples are stored column by column: index = column * n + iz, column = iy * n + ix.
  double x(int ix) const { return first.x() + ix * step.x(); }
  double y(int iy) const { return first.y() + iy * step.y(); }
  double z(int iz) const { return first.z() + iz * step.z(); }
};

// The triangles whose xy box covers each z column of the grid, as a compact table: column c's
// are bucket[first[c] .. first[c + 1]). Two passes (count, then fill).
struct ColumnTable {
  std::vector<std::uint32_t> first, bucket;
};
ColumnTable bin_triangles_by_column(const TriangleMesh& mesh, const SampleGrid& grid) {
  const int n = grid.n;
  auto column_range = [&](double lo, double hi, double first, double step, int& i0, int& i1) {
    // Clamped as doubles first: a mesh far outside the box must not overflow the cast.
    i0 = static_cast<int>(std::clamp(std::ceil((lo - first) / step), 0.0, double(n)));
    i1 = static_cast<int>(std::clamp(std::floor((hi - first) / step), -1.0, double(n - 1)));
  };
  ColumnTable table;
  std::vector<std::uint32_t>& count = table.first;
  count.assign(grid.columns() + 1, 0);
  struct Span {
    int x0, x1, y0, y1;
  };
  std::vector<Span> spans(mesh.triangles.size());
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    const Vec3& a = mesh.vertices[tri[0]];
    const Vec3& b = mesh.vertices[tri[1]];
    const Vec3& c = mesh.vertices[tri[2]];
    Span& s = spans[t];
    column_range(std::min({a.x(), b.x(), c.x()}), std::max({a.x(), b.x(), c.x()}), grid.first.x(),
                 grid.step.x(), s.x0, s.x1);
    column_range(std::min({a.y(), b.y(), c.y()}), std::max({a.y(), b.y(), c.y()}), grid.first.y(),
                 grid.step.y(), s.y0, s.y1);
    for (int iy = s.y0; iy <= s.y1; ++iy)
      for (int ix = s.x0; ix <= s.x1; ++ix) ++count[static_cast<std::size_t>(iy) * n + ix + 1];
  }
  for (std::size_t c = 0; c < grid.columns(); ++c) count[c + 1] += count[c];
  table.bucket.resize(count.back());
  std::vector<std::uint32_t> cursor(count.begin(), count.end() - 1);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Span& s = spans[t];
    for (int iy = s.y0; iy <= s.y1; ++iy)
      for (int ix = s.x0; ix <= s.x1; ++ix)
        table.bucket[cursor[static_cast<std::size_t>(iy) * n + ix]++] =
            static_cast<std::uint32_t>(t);
  }
  return table;
}

// Whether the column through q crosses triangle `tri` (winding `turn` in the xy projection),
// with each edge evaluated in one canonical direction (lower vertex index first, zero counted
// as positive), so that a column through a shared edge hits exactly one of two triangles.
bool column_hits(const std::array<std::uint32_t, 3>& tri, CGAL::Orientation turn,
                 const std::vector<Point2>& projected, const Point2& q) {
  if (turn == CGAL::COLLINEAR) return false;  // seen edge-on: no area to cross
  for (int e = 0; e < 3; ++e) {
    const std::uint32_t a = tri[e];
    const std::uint32_t b = tri[(e + 1) % 3];
    CGAL::Orientation side =
        CGAL::orientation(projected[std::min(a, b)], projected[std::max(a, b)], q);
    if (side == CGAL::COLLINEAR) side = CGAL::LEFT_TURN;
    if (a > b) side = -side;
    if (side != turn) return false;
  }
  return true;
}

// Height of the plane of `tri` above (qx, qy), from barycentric coordinates.
double height_above(const TriangleMesh& mesh, const std::array<std::uint32_t, 3>& tri, double qx,
                    double qy) {
  const Vec3& a = mesh.vertices[tri[0]];
  const Vec3& b = mesh.vertices[tri[1]];
  const Vec3& c = mesh.vertices[tri[2]];
  const double area = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
  const double wb = ((qx - a.x()) * (c.y() - a.y()) - (qy - a.y()) * (c.x() - a.x())) / area;
  const double wc = ((b.x() - a.x()) * (qy - a.y()) - (b.y() - a.y()) * (qx - a.x())) / area;
  return a.z() + wb * (b.z() - a.z()) + wc * (c.z() - a.z());
}

// Inside/outside of every grid sample for a closed mesh, by crossing parity along z columns.
// Each triangle is binned into the columns its xy box covers; the point-in-triangle test uses
// exact orientations (column_hits), so a column never falls through a crack.
std::vector<std::uint8_t> classify(const TriangleMesh& mesh, const SampleGrid& grid) {
  const int n = grid.n;
  std::vector<std::uint8_t> inside(grid.size(), 0);
  if (mesh.empty()) return inside;
  const ColumnTable table = bin_triangles_by_column(mesh, grid);
  std::vector<Point2> projected;
  projected.reserve(mesh.vertices.size());
  for (const Vec3& p : mesh.vertices) projected.emplace_back(p.x(), p.y());
  std::vector<CGAL::Orientation> winding(mesh.triangles.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.triangles.size()), [&](const auto& r) {
    for (std::size_t t = r.begin(); t != r.end(); ++t) {
      const auto& tri = mesh.triangles[t];
      winding[t] = CGAL::orientation(projected[tri[0]], projected[tri[1]], projected[tri[2]]);
    }
  });
  tbb::enumerable_thread_specific<std::vector<double>> hits_per_thread;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, grid.columns()), [&](const auto& range) {
    std::vector<double>& hits = hits_per_thread.local();
    for (std::size_t column = range.begin(); column != range.end(); ++column) {
      const int ix = static_cast<int>(column % n);
      const int iy = static_cast<int>(column / n);
      const Point2 q(grid.x(ix), grid.y(iy));
      hits.clear();
      for (std::uint32_t k = table.first[column]; k < table.first[column + 1]; ++k) {
        const auto& tri = mesh.triangles[table.bucket[k]];
        if (column_hits(tri, winding[table.bucket[k]], projected, q))
          hits.push_back(height_above(mesh, tri, q.x(), q.y()));
      }
      if (hits.empty()) continue;
      std::sort(hits.begin(), hits.end());
      std::size_t below = 0;
      std::uint8_t* out = inside.data() + column * n;
      for (int iz = 0; iz < n; ++iz) {
        const double z = grid.z(iz);
        while (below < hits.size() && hits[below] < z) ++below;
        out[iz] = static_cast<std::uint8_t>(below % 2);
      }
    }
  });
  return inside;
}

// 6-connected components of the inside samples of an n^3 grid (index (ix + iy n) n + iz).
int component_count(const std::vector<std::uint8_t>& inside, int n) {
  const std::size_t size = inside.size();
  const std::size_t un = static_cast<std::size_t>(n);
  std::vector<std::uint8_t> seen(size, 0);
  std::vector<std::size_t> stack;
  int components = 0;
  for (std::size_t start = 0; start < size; ++start) {
    if (!inside[start] || seen[start]) continue;
    ++components;
    seen[start] = 1;
    stack.push_back(start);
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      const std::size_t iz = i % un, ix = (i / un) % un, iy = i / (un * un);
      auto visit = [&](std::size_t j) {
        if (inside[j] && !seen[j]) {
          seen[j] = 1;
          stack.push_back(j);
        }
      };
      if (iz > 0) visit(i - 1);
      if (iz + 1 < un) visit(i + 1);
      if (ix > 0) visit(i - un);
      if (ix + 1 < un) visit(i + un);
      if (iy > 0) visit(i - un * un);
      if (iy + 1 < un) visit(i + un * un);
    }
  }
  return components;
}

std::string format_length(double mm) {
  std::ostringstream text;
  text << mm << " mm";
  return text.str();
}

double iou_of(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
  std::size_t both = 0, either = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    both += a[i] & b[i];
    either += a[i] | b[i];
  }
  // No sample inside either mesh says nothing about their overlap (two small meshes far apart
  // in a huge box): undefined, not a perfect 1.
  return either == 0 ? std::numeric_limits<double>::quiet_NaN()
                     : static_cast<double>(both) / static_cast<double>(either);
}

// ---- Closest-point baseline ------------------------------------------------------------

// Point-in-region queries on one slice: region edges bucketed into horizontal rows; a
// horizontal ray to +a counts crossings per region (outer ring and holes together, so the
// parity is odd exactly inside the region).
class SliceRegions {
 public:
  explicit SliceRegions(const LabeledSlice& slice) : slice_(&slice) {
    normal_ = slice.normal().normalized();
    double lo = std::numeric_limits<double>::infinity();
    double hi = -lo;
    struct RawEdge {
      Point2 low, high;
      int region;
    };
    std::vector<RawEdge> raw;
    for (std::size_t r = 0; r < slice.regions.size(); ++r) {
      const Region& region = slice.regions[r];
      labels_.push_back(region.label >= 1 ? region.label : kOutsideLabel);
      auto add_ring = [&](const Ring2& ring) {
        for (std::size_t i = 0; i < ring.size(); ++i) {
          Vec2 p = ring[i], q = ring[(i + 1) % ring.size()];
          if (p.y() == q.y()) continue;  // horizontal edges never cross a horizontal ray
          if (p.y() > q.y()) std::swap(p, q);
          raw.push_back({Point2(p.x(), p.y()), Point2(q.x(), q.y()), static_cast<int>(r)});
          lo = std::min(lo, p.y());
          hi = std::max(hi, q.y());
        }
      };
      add_ring(region.outer);
      for (const Ring2& hole : region.holes) add_ring(hole);
    }
    if (raw.empty()) return;
    rows_ = std::clamp(static_cast<int>(raw.size() / 2), 1, 4096);
    row_first_ = lo;
    row_height_ = std::max((hi - lo) / rows_, std::numeric_limits<double>::min());
    std::vector<std::uint32_t> count(rows_ + 1, 0);
    for (const RawEdge& e : raw)
      for (int r = row_of(e.low.y()); r <= row_of(e.high.y()); ++r) ++count[r + 1];
    for (int r = 0; r < rows_; ++r) count[r + 1] += count[r];
    row_start_ = count;
    edges_.resize(count.back());
    for (const RawEdge& e : raw)
      for (int r = row_of(e.low.y()); r <= row_of(e.high.y()); ++r)
        edges_[count[r]++] = Edge{e.low, e.high, e.region};
  }

  double distance(const Vec3& p) const { return std::abs((p - slice_->origin_mm).dot(normal_)); }

  /// Label at the projection of `p` (kOutsideLabel outside every material region).
  int label_at(const Vec3& p, std::vector<int>& crossed) const {
    if (edges_.empty()) return kOutsideLabel;
    const Vec2 a = slice_->to_plane(p);
    const double row_position = (a.y() - row_first_) / row_height_;
    if (row_position < 0.0 || row_position >= rows_ + 1.0) return kOutsideLabel;
    const int row = std::min(static_cast<int>(row_position), rows_ - 1);
    const Point2 q(a.x(), a.y());
    crossed.clear();
    for (std::uint32_t k = row_start_[row]; k < row_start_[row + 1]; ++k) {
      const Edge& e = edges_[k];
      // Half-open in y so a ray through a vertex counts it once.
      if (q.y() < e.low.y() || q.y() >= e.high.y()) continue;
      if (CGAL::orientation(e.low, e.high, q) == CGAL::LEFT_TURN) crossed.push_back(e.region);
    }
    std::sort(crossed.begin(), crossed.end());
    for (std::size_t i = 0; i < crossed.size();) {
      std::size_t j = i;
      while (j < crossed.size() && crossed[j] == crossed[i]) ++j;
      if ((j - i) % 2 == 1) return labels_[crossed[i]];
      i = j;
    }
    return kOutsideLabel;
  }

 private:
  struct Edge {
    Point2 low, high;
    int region;
  };
  int row_of(double y) const {
    return std::clamp(static_cast<int>((y - row_first_) / row_height_), 0, rows_ - 1);
  }

  const LabeledSlice* slice_;
  Vec3 normal_;
  std::vector<int> labels_;
  int rows_ = 0;
  double row_first_ = 0.0;
  double row_height_ = 1.0;
  std::vector<std::uint32_t> row_start_;
  std::vector<Edge> edges_;
};

// Label of every grid sample under the closest-point baseline.
std::vector<int> baseline_labels(const SliceSet& slices, const SampleGrid& grid) {
  std::vector<int> labels(grid.size(), kOutsideLabel);
  if (slices.slices.empty()) return labels;
  std::vector<SliceRegions> index;
  index.reserve(slices.slices.size());
  for (const LabeledSlice& s : slices.slices) index.emplace_back(s);
  const int n = grid.n;
  tbb::enumerable_thread_specific<std::vector<int>> crossed_per_thread;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, grid.columns()), [&](const auto& range) {
    std::vector<int>& crossed = crossed_per_thread.local();
    for (std::size_t column = range.begin(); column != range.end(); ++column) {
      const double x = grid.x(static_cast<int>(column % n));
      const double y = grid.y(static_cast<int>(column / n));
      for (int iz = 0; iz < n; ++iz) {
        const Vec3 p(x, y, grid.z(iz));
        std::size_t nearest = 0;
        double best = std::numeric_limits<double>::infinity();
        for (std::size_t s = 0; s < index.size(); ++s) {
          const double d = index[s].distance(p);
          if (d < best) {
            best = d;
            nearest = s;
          }
        }
        labels[column * n + iz] = index[nearest].label_at(p, crossed);
      }
    }
  });
  return labels;
}

// ---- Surface distances --------------------------------------------------------------------

using Simple = CGAL::Simple_cartesian<double>;
using Triangle3 = Simple::Triangle_3;
using TrianglePrimitive =
    CGAL::AABB_triangle_primitive<Simple, std::vector<Triangle3>::const_iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Simple, TrianglePrimitive>>;

// Closest-point queries on a mesh; built once, then queried from many threads.
class SurfaceDistance {
 public:
  explicit SurfaceDistance(const TriangleMesh& mesh) {
    for (const auto& t : mesh.triangles) {
      const Vec3& a = mesh.vertices[t[0]];
      const Vec3& b = mesh.vertices[t[1]];
      const Vec3& c = mesh.vertices[t[2]];
      if ((b - a).cross(c - a).squaredNorm() == 0.0) continue;  // no area: nothing to be near
      triangles_.emplace_back(Simple::Point_3(a.x(), a.y(), a.z()),
                              Simple::Point_3(b.x(), b.y(), b.z()),
                              Simple::Point_3(c.x(), c.y(), c.z()));
    }
    if (triangles_.empty()) return;
    tree_ = std::make_unique<Tree>(triangles_.begin(), triangles_.end());
    tree_->build();
    // Built here, before any parallel query, because building lazily is not thread-safe.
    tree_->accelerate_distance_queries();
  }
  bool empty() const { return !tree_; }
  double operator()(const Vec3& p) const {
    return std::sqrt(tree_->squared_distance(Simple::Point_3(p.x(), p.y(), p.z())));
  }

 private:
  std::vector<Triangle3> triangles_;
  std::unique_ptr<Tree> tree_;
};

// Area-weighted uniform samples on a mesh surface (deterministic).
std::vector<Vec3> sample_surface(const TriangleMesh& mesh, int count, std::uint64_t seed) {
  std::vector<double> cumulative;
  cumulative.reserve(mesh.triangles.size());
  double total = 0.0;
  for (const auto& t : mesh.triangles) {
    const Vec3& a = mesh.vertices[t[0]];
    total += 0.5 * (mesh.vertices[t[1]] - a).cross(mesh.vertices[t[2]] - a).norm();
    cumulative.push_back(total);
  }
  std::vector<Vec3> samples;
  if (total <= 0.0 || count <= 0) return samples;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  samples.reserve(count);
  for (int i = 0; i < count; ++i) {
    const double r = unit(rng) * total;
    const std::size_t t = std::min<std::size_t>(
        std::upper_bound(cumulative.begin(), cumulative.end(), r) - cumulative.begin(),
        cumulative.size() - 1);
    const auto& tri = mesh.triangles[t];
    // sqrt warps the unit square onto the triangle uniformly.
    const double s = std::sqrt(unit(rng));
    const double w = unit(rng);
    samples.push_back((1.0 - s) * mesh.vertices[tri[0]] + s * (1.0 - w) * mesh.vertices[tri[1]] +
                      s * w * mesh.vertices[tri[2]]);
  }
  return samples;
}

struct DistanceStats {
  double sum = 0.0;
  double max = 0.0;
  std::size_t count = 0;
};

DistanceStats distances(const std::vector<Vec3>& points, const SurfaceDistance& surface) {
  std::vector<double> d(points.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size()), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) d[i] = surface(points[i]);
  });
  DistanceStats stats;
  for (double x : d) {
    stats.sum += x;
    stats.max = std::max(stats.max, x);
  }
  stats.count = d.size();
  return stats;
}

double distance_to_ring(const Ring2& ring, const Vec2& p) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const Vec2& a = ring[i];
    const Vec2 d = ring[(i + 1) % ring.size()] - a;
    const double t = std::clamp((p - a).dot(d) / std::max(d.squaredNorm(), 1e-300), 0.0, 1.0);
    best = std::min(best, (a + t * d - p).norm());
  }
  return best;
}

// Points along every contour of `label` in the slices, vertices included, in world coordinates.
// Boundaries with unknown regions and the field of view are not contours of the object and are
// left out.
std::vector<Vec3> contour_points(const SliceSet& slices, int label, double step_mm) {
  std::vector<Vec3> points;
  for (const LabeledSlice& s : slices.slices)
    for (const Region& region : s.regions) {
      if (region.label != label) continue;
      std::vector<const Ring2*> not_contours;
      if (s.fov) not_contours.push_back(&*s.fov);
      for (const Region& r : s.regions)
        if (r.label == kUnknownLabel) {
          not_contours.push_back(&r.outer);
          for (const Ring2& h : r.holes) not_contours.push_back(&h);
        }
      auto add_ring = [&](const Ring2& ring) {
        for (std::size_t i = 0; i < ring.size(); ++i) {
          const Vec2& a = ring[i];
          const Vec2& b = ring[(i + 1) % ring.size()];
          const int pieces = std::max(1, static_cast<int>(std::ceil((b - a).norm() / step_mm)));
          for (int k = 0; k < pieces; ++k) {
            const Vec2 p = a + (static_cast<double>(k) / pieces) * (b - a);
            bool on_unknown = false;
            for (const Ring2* other : not_contours)
              on_unknown |= distance_to_ring(*other, p) <= 1e-6 * step_mm;
            if (!on_unknown) points.push_back(s.to_world(p));
          }
        }
      };
      add_ring(region.outer);
      for (const Ring2& hole : region.holes) add_ring(hole);
    }
  return points;
}

const TriangleMesh* find_mesh(const MeshSet& set, int label) {
  for (const auto& e : set.meshes)
    if (e.label == label) return &e.mesh;
  return nullptr;
}

}  // namespace

namespace {

// The mean and Hausdorff distances between the two surfaces, from samples of each against the
// other, and from the slices' contours of `label` to the reconstruction (percent of the box's
// diagonal: `to_percent` = 100 / diagonal); NaN where there is nothing to sample.
void score_distances(const TriangleMesh& recon, const TriangleMesh& truth, const SliceSet* slices,
                     int label, const EvaluationOptions& options, double diagonal,
                     LabelScore& score) {
  const double to_percent = 100.0 / diagonal;
  const SurfaceDistance to_recon(recon);
  const SurfaceDistance to_truth(truth);
  const std::uint64_t seed = kSampleSeed + static_cast<std::uint64_t>(label);
  const std::vector<Vec3> truth_samples = sample_surface(truth, options.surface_samples, seed);
  const std::vector<Vec3> recon_samples =
      sample_surface(recon, options.surface_samples, seed + 7919);
  if (to_recon.empty() || to_truth.empty() || truth_samples.empty() || recon_samples.empty()) {
    score.mean_surface_distance = score.hausdorff_distance = kNaN;
  } else {
    const DistanceStats forward = distances(truth_samples, to_recon);
    const DistanceStats backward = distances(recon_samples, to_truth);
    score.mean_surface_distance =
        0.5 * (forward.sum / forward.count + backward.sum / backward.count) * to_percent;
    score.hausdorff_distance = std::max(forward.max, backward.max) * to_percent;
  }
  score.contour_mean = score.contour_max = kNaN;
  if (slices == nullptr || to_recon.empty()) return;
  const std::vector<Vec3> points =
      contour_points(*slices, label, options.contour_step_fraction * diagonal);
  if (points.empty()) return;
  const DistanceStats contour = distances(points, to_recon);
  score.contour_mean = contour.sum / contour.count * to_percent;
  score.contour_max = contour.max * to_percent;
}

// The scores of one label without a reconstructed mesh: IoU 0, distances NaN.
void score_missing(const TriangleMesh* recon, int label, LabelScore& score) {
  log_warning("evaluate: the reconstruction has no mesh for label " + std::to_string(label) +
              "; its IoU is 0");
  score.reconstructed = false;
  score.iou = 0.0;
  score.mean_surface_distance = score.hausdorff_distance = kNaN;
  score.contour_mean = score.contour_max = kNaN;
  if (recon != nullptr) score.health = check_mesh_health(*recon);
}

}  // namespace

std::vector<LabelScore> evaluate(const MeshSet& reconstruction, const MeshSet& truth,
                                 const SliceSet* slices, const Box3& box,
                                 const EvaluationOptions& options) {
  if (options.grid_resolution < 1)
    throw GeometryError("evaluate: grid_resolution must be at least 1");
  if (!box.size().allFinite() || (box.size().array() <= 0.0).any())
    throw GeometryError("evaluate: the evaluation box must have a positive size on every axis");
  const double diagonal = box.diagonal();
  const SampleGrid grid(box, options.grid_resolution);
  std::vector<int> baseline;
  if (slices != nullptr) baseline = baseline_labels(*slices, grid);
  for (const auto& e : reconstruction.meshes)
    if (find_mesh(truth, e.label) == nullptr)
      log_warning("evaluate: the reconstruction has label " + std::to_string(e.label) +
                  ", which the ground truth lacks; it is not scored");

  std::vector<LabelScore> scores;
  for (const auto& entry : truth.meshes) {
    LabelScore score;
    score.label = entry.label;
    const std::vector<std::uint8_t> truth_inside = classify(entry.mesh, grid);
    score.truth_components = component_count(truth_inside, grid.n);
    score.baseline_iou = kNaN;
    if (slices != nullptr) {
      std::vector<std::uint8_t> baseline_inside(grid.size());
      for (std::size_t i = 0; i < baseline.size(); ++i)
        baseline_inside[i] = baseline[i] == entry.label;
      score.baseline_iou = iou_of(baseline_inside, truth_inside);
      score.baseline_components = component_count(baseline_inside, grid.n);
    }
    const TriangleMesh* recon = find_mesh(reconstruction, entry.label);
    if (recon == nullptr || recon->empty()) {
      score_missing(recon, entry.label, score);
      scores.push_back(score);
      continue;
    }
    score.health = check_mesh_health(*recon);
    const std::vector<std::uint8_t> recon_inside = classify(*recon, grid);
    score.iou = iou_of(recon_inside, truth_inside);
    if (std::isnan(score.iou))
      log_warning("evaluate: label " + std::to_string(entry.label) +
                  ": no grid sample falls inside the reconstruction or the truth, so the IoU is "
                  "undefined; the evaluation box (diagonal " +
                  format_length(diagonal) +
                  ") is too large for these meshes: give --slices for a box around the data, "
                  "or check that the two meshes are in the same place and units");
    score.components = component_count(recon_inside, grid.n);
    score_distances(*recon, entry.mesh, slices, entry.label, options, diagonal, score);
    scores.push_back(score);
  }
  return scores;
}

}  // namespace sonoshape::simulator
