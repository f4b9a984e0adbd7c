// Completion of unknown regions (Bermano et al. 2011, Section 5): triangulation of the unknown
// part of every face, cell groups, and the values at the triangle corners.
#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Delaunay_mesh_face_base_2.h>
#include <CGAL/Delaunay_mesh_size_criteria_2.h>
#include <CGAL/Delaunay_mesh_vertex_base_2.h>
#include <CGAL/Delaunay_mesher_2.h>
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
using Vb = CGAL::Delaunay_mesh_vertex_base_2<Kernel>;
using Fb = CGAL::Delaunay_mesh_face_base_2<Kernel>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Exact_predicates_tag: constraints that cross (unknown boundaries and face edges) are split at
// their intersection points.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<Kernel, Tds, CGAL::Exact_predicates_tag>;
using MeshCriteria = CGAL::Delaunay_mesh_size_criteria_2<Cdt>;

// Largest edge of the unknown triangles: the completed values live at the corners and are
// interpolated linearly, so the triangles must be small enough to follow the completion across
// the region, not only along its boundary: an eighth of the side of the slice's unknown area,
// between these fractions of the box diagonal (large unknown areas, such as everything outside a
// field of view, get coarser triangles, which keeps the field's cost bounded).
constexpr double kUnknownTriangleFraction = 0.125;
constexpr double kUnknownTriangleMin = 0.03, kUnknownTriangleMax = 0.12;
// CGAL's shape bound b (smallest angle asin(sqrt(b))): 0.01 allows angles down to 5.7 degrees, so
// the short edges of segmented contours do not spawn rings of refinement (0.125, CGAL's
// default for 20.7 degrees, made ten times more triangles on segmented sweeps).
constexpr double kUnknownTriangleShape = 0.01;
// Refinement points allowed per point the size criterion alone would need (see the loop).
constexpr double kRefinementBudget = 8.0;

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
  Cdt cdt;
  Vec2 lo = Vec2::Constant(std::numeric_limits<double>::infinity());
  Vec2 hi = -lo;
  for (const UnknownComponent& component : s.unknown)
    for (const Ring2& ring : component.rings)
      for (std::size_t i = 0; i < ring.size(); ++i) {
        const Vec2& a = ring[i];
        const Vec2& b = ring[(i + 1) % ring.size()];
        lo = lo.cwiseMin(a);
        hi = hi.cwiseMax(a);
        if (a != b) cdt.insert_constraint(Kernel::Point_2(a.x(), a.y()), Kernel::Point_2(b.x(), b.y()));
      }
  // Interior points (conforming Delaunay refinement of the unknown set and the areas it encloses).
  // Seeds inside the holes of the unknown set keep the known areas it encloses unrefined.
  std::vector<Kernel::Point_2> known_seeds;
  for (const UnknownComponent& component : s.unknown)
    for (std::size_t r = 1; r < component.rings.size(); ++r)
      if (const auto p = interior_point(component.rings[r])) known_seeds.emplace_back(p->x(), p->y());
  double unknown_area = 0.0;
  for (const UnknownComponent& component : s.unknown)
    for (const Ring2& ring : component.rings) unknown_area += signed_area(ring);
  const double diagonal = arrangement_.box().diagonal();
  const double triangle_size =
      std::clamp(kUnknownTriangleFraction * std::sqrt(std::max(unknown_area, 0.0)),
                 kUnknownTriangleMin * diagonal, kUnknownTriangleMax * diagonal);
  // Delaunay refinement is only guaranteed to end for input angles of 60 degrees and more;
  // segmented contours and sector outlines have far sharper ones (the real PLUS sweep made it
  // insert points forever), so the refinement runs step by step under a budget of many times
  // the points the size criterion asks for.
  CGAL::Delaunay_mesher_2<Cdt, MeshCriteria> mesher(cdt, MeshCriteria(kUnknownTriangleShape, triangle_size));
  mesher.set_seeds(known_seeds.begin(), known_seeds.end(), false);
  mesher.init();
  const std::size_t budget =
      static_cast<std::size_t>(kRefinementBudget * (std::max(unknown_area, 0.0) / (triangle_size * triangle_size) +
                                                    static_cast<double>(cdt.number_of_vertices()))) +
      1000;
  const std::size_t start_vertices = cdt.number_of_vertices();
  while (!mesher.is_refinement_done()) {
    if (cdt.number_of_vertices() - start_vertices > budget) {
      log_warning("completion: slice " + std::to_string(slice) +
                  ": the refinement of its unknown region stopped at " + std::to_string(budget) +
                  " points (very sharp angles in its outline); the completion is coarser there");
      break;
    }
    mesher.try_one_step_refine_mesh();
  }
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
