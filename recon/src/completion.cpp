// Completion of unknown regions (Bermano et al. 2011, Section 5): triangulation of the unknown
// part of every face, cell groups, and the values at the triangle corners.
#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <map>
#include <numeric>
#include <unordered_set>

#include <tbb/parallel_for.h>

#include "cell_field.hpp"
#include "mean_value.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::recon {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_2<Kernel>;
using Fb = CGAL::Constrained_triangulation_face_base_2<Kernel>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Exact_predicates_tag: constraints that cross (unknown boundaries and face edges) are split at
// their intersection points.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<Kernel, Tds, CGAL::Exact_predicates_tag>;

// Largest edge of the unknown triangles: the completed values live at the corners and are
// interpolated linearly, so the triangles must be small enough to follow the completion across
// the region, not only along its boundary: an eighth of the side of the slice's unknown area,
// between these fractions of the box diagonal (large unknown areas, such as everything outside a
// field of view, get coarser triangles, which keeps the field's cost bounded).
constexpr double kUnknownTriangleFraction = 0.125;
constexpr double kUnknownTriangleMin = 0.03, kUnknownTriangleMax = 0.12;
// Lattice points closer than this many triangle sizes to the unknown boundary are left out.
constexpr double kLatticeClearance = 0.5;

// The completion reads the known faces of the cells within this many group-adjacency steps of a
// triangle's face. With fields of view every slice has unknown parts and groups grow to the whole
// arrangement; the nearby faces carry the weight (it falls off with distance), and the bound
// keeps completion linear in the number of triangles.
constexpr int kGroupHops = 1;

int find_root(std::vector<int>& parent, int x) {
  while (parent[static_cast<std::size_t>(x)] != x) {
    parent[static_cast<std::size_t>(x)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(x)])];
    x = parent[static_cast<std::size_t>(x)];
  }
  return x;
}

bool in_convex_ccw(const Vec2* polygon, std::size_t count, const Vec2& p) {
  for (std::size_t i = 0; i < count; ++i) {
    const Vec2& a = polygon[i];
    const Vec2& b = polygon[(i + 1) % count];
    if ((b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x()) < 0.0) return false;
  }
  return true;
}

}  // namespace

void CellField::triangulate_unknown(int slice,
                                    std::vector<std::vector<UnknownTriangle>>& per_face) const {
  const PreparedSlice& s = slices_[static_cast<std::size_t>(slice)];
  double unknown_area = 0.0;
  for (const UnknownComponent& component : s.unknown)
    for (const Ring2& ring : component.rings) unknown_area += signed_area(ring);
  const double diagonal = arrangement_.box().diagonal();
  const double triangle_size =
      std::clamp(kUnknownTriangleFraction * std::sqrt(std::max(unknown_area, 0.0)),
                 kUnknownTriangleMin * diagonal, kUnknownTriangleMax * diagonal);

  // Why not CGAL::Delaunay_mesher_2: its refinement is only guaranteed to end for input angles of
  // 60 degrees and more, and with inexact constructions it crashed (Refine_edges_with_clusters)
  // on the real PLUS sweep, whose segmented outlines have near-touching vertices and hairline
  // spikes. The completion only needs corners spread over the region at about triangle_size, not
  // well-shaped triangles, so the boundary edges are split to that length and a triangular
  // lattice of that spacing fills the inside, kept away from the boundary; a plain constrained
  // Delaunay triangulation of these points (exact predicates, no refinement) always ends.
  Cdt cdt;
  Vec2 lo = Vec2::Constant(std::numeric_limits<double>::infinity());
  Vec2 hi = -lo;
  std::vector<std::pair<Vec2, Vec2>> boundary;  // the split boundary edges, for the clearance test
  for (const UnknownComponent& component : s.unknown)
    for (const Ring2& ring : component.rings)
      for (std::size_t i = 0; i < ring.size(); ++i) {
        const Vec2& a = ring[i];
        const Vec2& b = ring[(i + 1) % ring.size()];
        lo = lo.cwiseMin(a);
        hi = hi.cwiseMax(a);
        if (a == b) continue;
        const int pieces = std::max(1, static_cast<int>(std::ceil((b - a).norm() / triangle_size)));
        Vec2 previous = a;
        for (int k = 1; k <= pieces; ++k) {
          const Vec2 next = k == pieces ? b : Vec2(a + (b - a) * (static_cast<double>(k) / pieces));
          cdt.insert_constraint(Kernel::Point_2(previous.x(), previous.y()), Kernel::Point_2(next.x(), next.y()));
          boundary.emplace_back(previous, next);
          previous = next;
        }
      }
  if (boundary.empty()) return;
  // Lattice points inside the unknown set, at least kLatticeClearance * triangle_size from its
  // boundary (closer ones would only make slivers along it). Boundary edges are bucketed by
  // lattice row so each point tests the few edges near it.
  const double row_step = triangle_size * std::sqrt(3.0) / 2.0;
  const double clearance = kLatticeClearance * triangle_size;
  const int rows = static_cast<int>(std::floor((hi.y() - lo.y()) / row_step)) + 1;
  std::vector<std::vector<std::size_t>> edges_near_row(static_cast<std::size_t>(rows));
  for (std::size_t e = 0; e < boundary.size(); ++e) {
    const double y0 = std::min(boundary[e].first.y(), boundary[e].second.y()) - clearance;
    const double y1 = std::max(boundary[e].first.y(), boundary[e].second.y()) + clearance;
    const int r0 = std::max(0, static_cast<int>(std::ceil((y0 - lo.y()) / row_step)));
    const int r1 = std::min(rows - 1, static_cast<int>(std::floor((y1 - lo.y()) / row_step)));
    for (int r = r0; r <= r1; ++r) edges_near_row[static_cast<std::size_t>(r)].push_back(e);
  }
  const auto clear_of_boundary = [&](const Vec2& p, const std::vector<std::size_t>& edges) {
    for (const std::size_t e : edges) {
      const Vec2& a = boundary[e].first;
      const Vec2 ab = boundary[e].second - a;
      const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
      if ((a + t * ab - p).squaredNorm() < clearance * clearance) return false;
    }
    return true;
  };
  std::vector<Kernel::Point_2> lattice;
  for (int r = 0; r < rows; ++r) {
    const double y = lo.y() + r * row_step;
    const double x_offset = (r % 2) * 0.5 * triangle_size;
    for (double x = lo.x() + x_offset; x <= hi.x(); x += triangle_size) {
      const Vec2 p(x, y);
      bool inside = false;
      for (const UnknownComponent& component : s.unknown) {
        int winding = 0;
        for (const Ring2& ring : component.rings) winding += winding_number(ring.data(), ring.size(), p);
        if (winding > 0) {
          inside = true;
          break;
        }
      }
      if (inside && clear_of_boundary(p, edges_near_row[static_cast<std::size_t>(r)])) lattice.emplace_back(x, y);
    }
  }
  cdt.insert(lattice.begin(), lattice.end());
  // The faces of this slice, as constraints too, so that every triangle lies in one face.
  struct SliceFace {
    int id;
    Vec2 lo, hi;
  };
  std::vector<SliceFace> faces;
  for (std::size_t f = 0; f < images_.size(); ++f) {
    const FaceImage& image = images_[f];
    if (arrangement_.plane(image.frame).slice != slice) continue;
    SliceFace face{static_cast<int>(f), points_[image.polygon_begin], points_[image.polygon_begin]};
    for (std::uint32_t k = 0; k < image.polygon_count; ++k) {
      face.lo = face.lo.cwiseMin(points_[image.polygon_begin + k]);
      face.hi = face.hi.cwiseMax(points_[image.polygon_begin + k]);
    }
    if ((face.lo.array() > hi.array()).any() || (face.hi.array() < lo.array()).any()) continue;
    faces.push_back(face);
    for (std::uint32_t k = 0; k < image.polygon_count; ++k) {
      const Vec2& a = points_[image.polygon_begin + k];
      const Vec2& b = points_[image.polygon_begin + (k + 1) % image.polygon_count];
      if (a != b) cdt.insert_constraint(Kernel::Point_2(a.x(), a.y()), Kernel::Point_2(b.x(), b.y()));
    }
  }
  for (auto it = cdt.finite_faces_begin(); it != cdt.finite_faces_end(); ++it) {
    UnknownTriangle triangle;
    for (int k = 0; k < 3; ++k)
      triangle.corners[k] = Vec2(it->vertex(k)->point().x(), it->vertex(k)->point().y());
    const Vec2 centroid = (triangle.corners[0] + triangle.corners[1] + triangle.corners[2]) / 3.0;
    for (std::size_t c = 0; c < s.unknown.size() && triangle.component < 0; ++c) {
      int winding = 0;
      for (const Ring2& ring : s.unknown[c].rings) winding += winding_number(ring.data(), ring.size(), centroid);
      if (winding > 0) triangle.component = static_cast<int>(c);
    }
    if (triangle.component < 0) continue;
    const double area = signed_area(Ring2{triangle.corners[0], triangle.corners[1], triangle.corners[2]});
    // Slivers from constraint intersections rounded onto each other cover nothing.
    const double longest_sq = std::max({(triangle.corners[1] - triangle.corners[0]).squaredNorm(),
                                        (triangle.corners[2] - triangle.corners[1]).squaredNorm(),
                                        (triangle.corners[0] - triangle.corners[2]).squaredNorm()});
    const double box_diagonal = arrangement_.box().diagonal();
    if (!(std::abs(area) > 1e-12 * longest_sq) || std::abs(area) < 1e-14 * box_diagonal * box_diagonal)
      continue;
    if (area < 0.0) std::swap(triangle.corners[1], triangle.corners[2]);  // counter-clockwise
    for (const SliceFace& face : faces) {
      if ((centroid.array() < face.lo.array()).any() || (centroid.array() > face.hi.array()).any()) continue;
      const FaceImage& image = images_[static_cast<std::size_t>(face.id)];
      if (!in_convex_ccw(points_.data() + image.polygon_begin, image.polygon_count, centroid)) continue;
      per_face[static_cast<std::size_t>(face.id)].push_back(triangle);
      break;
    }
  }
}

bool CellField::known_weights(int face, const Vec3& p, double& total, double* materials,
                              double& unknown) const {
  const FaceImage& image = images_[static_cast<std::size_t>(face)];
  const PlaneFrame& frame = frames_[static_cast<std::size_t>(image.frame)];
  const Vec3 d = p - frame.origin;
  const double height = std::abs(d.dot(frame.unit_normal));
  if (height <= on_face_height_) return false;
  const Vec2 foot(d.dot(frame.u), d.dot(frame.v));
  const double inv_height = 1.0 / height;
  total = projected_angle(points_.data() + image.polygon_begin, image.polygon_count, foot, height) * inv_height;
  for (const FaceImage::Part& part : image.parts)
    materials[part.material] += part_angle(part, foot, height) * inv_height;
  unknown = 0.0;
  for (const FaceImage::Part& part : image.unknown_parts)
    unknown += part_angle(part, foot, height) * inv_height;
  return true;
}

void CellField::build_unknown_images() {
  bool any = false;
  for (const PreparedSlice& s : slices_) any |= !s.unknown.empty();
  if (!any) return;
  Stopwatch clock;
  std::vector<std::vector<UnknownTriangle>> per_face(images_.size());
  for (std::size_t s = 0; s < slices_.size(); ++s)
    if (!slices_[s].unknown.empty()) triangulate_unknown(static_cast<int>(s), per_face);
  for (std::size_t f = 0; f < per_face.size(); ++f) {
    images_[f].triangle_begin = static_cast<std::uint32_t>(triangles_.size());
    images_[f].triangle_count = static_cast<std::uint32_t>(per_face[f].size());
    triangles_.insert(triangles_.end(), per_face[f].begin(), per_face[f].end());
  }
  complete_unknown();
  completion_seconds_ = clock.seconds();
}

void CellField::complete_unknown() {
  const std::size_t fc = static_cast<std::size_t>(function_count());
  corner_values_.assign(triangles_.size() * 3 * fc, 0.0);
  // Cell groups: cells joined through faces that hold unknown triangles.
  std::vector<int> parent(arrangement_.cell_count());
  std::iota(parent.begin(), parent.end(), 0);
  std::vector<std::vector<int>> unknown_neighbours(arrangement_.cell_count());
  for (std::size_t f = 0; f < images_.size(); ++f) {
    if (images_[f].triangle_count == 0) continue;
    const ArrangementFace& face = arrangement_.face(static_cast<int>(f));
    if (face.cell_positive < 0 || face.cell_negative < 0) continue;
    parent[static_cast<std::size_t>(find_root(parent, face.cell_positive))] = find_root(parent, face.cell_negative);
    unknown_neighbours[static_cast<std::size_t>(face.cell_positive)].push_back(face.cell_negative);
    unknown_neighbours[static_cast<std::size_t>(face.cell_negative)].push_back(face.cell_positive);
  }
  std::unordered_set<int> roots;
  for (std::size_t f = 0; f < images_.size(); ++f)
    if (images_[f].triangle_count > 0) roots.insert(find_root(parent, arrangement_.face(static_cast<int>(f)).cell_positive));
  group_count_ = roots.size();

  std::vector<std::size_t> faces_with_triangles;
  for (std::size_t f = 0; f < images_.size(); ++f)
    if (images_[f].triangle_count > 0) faces_with_triangles.push_back(f);
  // Faces complete independently (each writes only its own triangles' corners).
  tbb::parallel_for(std::size_t{0}, faces_with_triangles.size(), [&](std::size_t index) {
    const std::size_t f = faces_with_triangles[index];
    std::vector<double> n3(fc), n2(fc);
    const FaceImage& image = images_[f];
    const ArrangementFace& face = arrangement_.face(static_cast<int>(f));
    const int slice = arrangement_.plane(face.plane).slice;
    const PreparedSlice& s = slices_[static_cast<std::size_t>(slice)];
    // The known faces near this face within its group (breadth-first over group adjacency).
    std::vector<int> cells{face.cell_positive, face.cell_negative};
    std::unordered_set<int> seen(cells.begin(), cells.end());
    std::vector<int> frontier = cells;
    for (int hop = 0; hop < kGroupHops; ++hop) {
      std::vector<int> next;
      for (const int c : frontier)
        for (const int n : unknown_neighbours[static_cast<std::size_t>(c)])
          if (seen.insert(n).second) next.push_back(n);
      cells.insert(cells.end(), next.begin(), next.end());
      frontier = std::move(next);
    }
    std::vector<int> local_faces;
    for (const int c : cells)
      for (const int g : arrangement_.cell(c).faces)
        // Faces without known data add nothing to the 3D part.
        if (arrangement_.face(g).plane != face.plane && !images_[static_cast<std::size_t>(g)].fully_unknown)
          local_faces.push_back(g);
    std::sort(local_faces.begin(), local_faces.end());
    local_faces.erase(std::unique(local_faces.begin(), local_faces.end()), local_faces.end());

    std::map<std::pair<double, double>, std::vector<double>> part_3d;  // per corner point: N3, W3
    for (std::uint32_t t = image.triangle_begin; t < image.triangle_begin + image.triangle_count; ++t) {
      const UnknownTriangle& triangle = triangles_[t];
      const Vec2 centroid = (triangle.corners[0] + triangle.corners[1] + triangle.corners[2]) / 3.0;
      const UnknownComponent& component = s.unknown[static_cast<std::size_t>(triangle.component)];
      for (int k = 0; k < 3; ++k) {
        const Vec2& corner = triangle.corners[k];
        // (a) 3D mean-value interpolant of the known faces around, at the corner itself.
        auto [it, inserted] = part_3d.try_emplace({corner.x(), corner.y()});
        if (inserted) {
          std::vector<double>& n3w = it->second;
          n3w.assign(fc + 1, 0.0);
          const Vec3 x = s.origin + corner.x() * s.u + corner.y() * s.v;
          std::fill(n3.begin(), n3.end(), 0.0);
          for (const int g : local_faces) {
            double total = 0.0, unknown = 0.0;
            std::fill(n2.begin(), n2.end(), 0.0);  // scratch for the materials of face g
            if (!known_weights(g, x, total, n2.data(), unknown)) continue;
            double materials = 0.0;
            for (std::size_t l = 1; l < fc; ++l) {
              n3w[l] += 0.5 * n2[l];
              materials += n2[l];
            }
            n3w[0] += 0.5 * (total - materials - unknown);
            n3w[fc] += 0.5 * (total - unknown);
          }
        }
        const std::vector<double>& n3w = it->second;
        // (b) 2D mean-value interpolant of the unknown component in its slice, from the known
        // labels across its boundary; read just inside the triangle's corner, so that a corner
        // on the boundary takes the limit from its own side (Section 5.1).
        const Vec2 p = corner + 1e-4 * (centroid - corner);
        std::fill(n2.begin(), n2.end(), 0.0);
        double w2 = 0.0;
        for (std::size_t r = 0; r < component.rings.size(); ++r) {
          const Ring2& ring = component.rings[r];
          for (std::size_t i = 0; i < ring.size(); ++i) {
            const double w = edge_weight_2d(ring[i], ring[(i + 1) % ring.size()], p);
            n2[static_cast<std::size_t>(component.edge_labels[r][i])] += w;
            w2 += w;
          }
        }
        // Formula 7: the normalised blend of both.
        const double denominator = n3w[fc] + w2;
        double* out = &corner_values_[(t * 3 + static_cast<std::size_t>(k)) * fc];
        for (std::size_t l = 0; l < fc; ++l)
          out[l] = denominator > 0.0 ? 2.0 * (n3w[l] + n2[l]) / denominator - 1.0 : (l == 0 ? 1.0 : -1.0);
      }
    }
  });
}

}  // namespace sonoshape::recon
