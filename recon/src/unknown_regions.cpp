#include "unknown_regions.hpp"

#include <CGAL/Boolean_set_operations_2.h>
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Polygon_set_2.h>
#include <CGAL/Polygon_with_holes_2.h>

#include <algorithm>
#include <optional>

#include "cell_field.hpp"
#include "mean_value.hpp"
#include "sonoshape/core/errors.hpp"

namespace sonoshape::recon {
namespace {

using Polygon = CGAL::Polygon_2<ExactKernel>;
using PolygonWithHoles = CGAL::Polygon_with_holes_2<ExactKernel>;
using PolygonSet = CGAL::Polygon_set_2<ExactKernel>;

Polygon to_polygon(const Ring2& ring) {
  Polygon p;
  for (const Vec2& q : ring) p.push_back(ExactKernel::Point_2(q.x(), q.y()));
  if (p.is_clockwise_oriented()) p.reverse_orientation();
  return p;
}

Ring2 to_ring(const Polygon& polygon) {
  Ring2 ring;
  for (auto it = polygon.vertices_begin(); it != polygon.vertices_end(); ++it)
    ring.emplace_back(CGAL::to_double(it->x()), CGAL::to_double(it->y()));
  return ring;
}

// Outer rings counter-clockwise and holes clockwise, as the field's integrals expect.
std::vector<Ring2> to_rings(const PolygonSet& set) {
  std::vector<PolygonWithHoles> parts;
  set.polygons_with_holes(std::back_inserter(parts));
  std::vector<Ring2> rings;
  for (const PolygonWithHoles& part : parts) {
    Ring2 outer = to_ring(part.outer_boundary());
    if (signed_area(outer) < 0) std::reverse(outer.begin(), outer.end());
    rings.push_back(std::move(outer));
    for (auto h = part.holes_begin(); h != part.holes_end(); ++h) {
      Ring2 hole = to_ring(*h);
      if (signed_area(hole) > 0) std::reverse(hole.begin(), hole.end());
      rings.push_back(std::move(hole));
    }
  }
  return rings;
}

PolygonSet region_set(const Region& region) {
  PolygonWithHoles pwh(to_polygon(region.outer));
  for (const Ring2& hole : region.holes) {
    Polygon h = to_polygon(hole);
    h.reverse_orientation();  // holes clockwise
    pwh.add_hole(h);
  }
  PolygonSet set;
  set.insert(pwh);
  return set;
}

}  // namespace

std::optional<Vec2> interior_point(const Ring2& ring) {
  double lo = ring[0].y(), hi = ring[0].y();
  for (const Vec2& p : ring) {
    lo = std::min(lo, p.y());
    hi = std::max(hi, p.y());
  }
  const double y = lo + (hi - lo) * 0.5004321;  // off-centre: rarely through a vertex
  std::vector<double> xs;
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const Vec2& a = ring[i];
    const Vec2& b = ring[(i + 1) % ring.size()];
    if ((a.y() <= y) != (b.y() <= y))
      xs.push_back(a.x() + (y - a.y()) / (b.y() - a.y()) * (b.x() - a.x()));
  }
  std::sort(xs.begin(), xs.end());
  std::optional<Vec2> best;
  double best_width = 0.0;
  for (std::size_t i = 0; i + 1 < xs.size(); i += 2) {
    if (xs[i + 1] - xs[i] > best_width) {
      best_width = xs[i + 1] - xs[i];
      best = Vec2(0.5 * (xs[i] + xs[i + 1]), y);
    }
  }
  return best;
}

Ring2 plane_box_polygon(const Vec3& origin, const Vec3& u, const Vec3& v, const Box3& box) {
  // A square covering the box's projection, clipped by the six box faces.
  const Vec3 center = 0.5 * (box.min + box.max);
  const Vec2 c((center - origin).dot(u), (center - origin).dot(v));
  const double r = box.diagonal();
  const Ring2 square{c + Vec2(-r, -r), c + Vec2(r, -r), c + Vec2(r, r), c + Vec2(-r, r)};
  std::vector<Eigen::Vector3d> half_planes;
  for (int axis = 0; axis < 3; ++axis) {
    // x_axis(a, b) = origin + a u + b v along the axis, inside when >= min and <= max.
    half_planes.emplace_back(u[axis], v[axis], origin[axis] - box.min[axis]);
    half_planes.emplace_back(-u[axis], -v[axis], box.max[axis] - origin[axis]);
  }
  Ring2 clipped = clip_ring_to_convex(square, half_planes);
  if (std::abs(signed_area(clipped)) <= 1e-12 * r * r) clipped.clear();
  return clipped;
}

SlicePartition partition_slice(const LabeledSlice& slice, const std::vector<int>& material_ids,
                               const Ring2& plane_in_box) {
  SlicePartition out;
  out.materials.resize(material_ids.size() + 1);
  if (plane_in_box.size() < 3) return out;
  PolygonSet box_set;
  box_set.insert(to_polygon(plane_in_box));

  PolygonSet unknown;
  if (slice.fov) {
    unknown = box_set;
    unknown.difference(to_polygon(*slice.fov));
  }
  for (const Region& region : slice.regions)
    if (region.label == kUnknownLabel) unknown.join(region_set(region));
  unknown.intersection(box_set);

  std::vector<PolygonSet> material_sets(material_ids.size() + 1);
  for (const Region& region : slice.regions) {
    if (region.label == kUnknownLabel) continue;
    const auto it = std::find(material_ids.begin(), material_ids.end(), region.label);
    if (it == material_ids.end())
      throw GeometryError("label " + std::to_string(region.label) +
                          " is not a material of the set");
    material_sets[static_cast<std::size_t>(it - material_ids.begin()) + 1].join(region_set(region));
  }
  for (std::size_t m = 1; m < material_sets.size(); ++m) {
    material_sets[m].intersection(box_set);
    material_sets[m].difference(unknown);
    out.materials[m] = to_rings(material_sets[m]);
  }

  PolygonSet known = box_set;
  known.difference(unknown);
  out.known = to_rings(known);

  // Unknown components and the known label across each of their edges.
  std::vector<PolygonWithHoles> parts;
  unknown.polygons_with_holes(std::back_inserter(parts));
  const double size = std::sqrt(std::max(1e-300, std::abs(signed_area(plane_in_box))));
  auto known_label = [&](const Vec2& q) {
    for (std::size_t m = 1; m < out.materials.size(); ++m) {
      int winding = 0;
      for (const Ring2& ring : out.materials[m])
        winding += winding_number(ring.data(), ring.size(), q);
      if (winding > 0) return static_cast<int>(m);
    }
    return 0;
  };
  for (const PolygonWithHoles& part : parts) {
    PolygonSet one;
    one.insert(part);
    UnknownComponent component;
    component.rings = to_rings(one);
    for (const Ring2& ring : component.rings) {
      std::vector<int> labels;
      for (std::size_t i = 0; i < ring.size(); ++i) {
        const Vec2& a = ring[i];
        const Vec2& b = ring[(i + 1) % ring.size()];
        const Vec2 d = b - a;
        // The unknown side is on the left of every ring edge; probe just to the right.
        const Vec2 probe = 0.5 * (a + b) + Vec2(d.y(), -d.x()).normalized() * (1e-7 * size);
        labels.push_back(known_label(probe));
      }
      component.edge_labels.push_back(std::move(labels));
    }
    out.unknown.push_back(std::move(component));
  }
  return out;
}

}  // namespace sonoshape::recon
