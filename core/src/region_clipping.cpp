#include "sonoshape/core/region_clipping.hpp"

#include <CGAL/Boolean_set_operations_2.h>
#include <CGAL/Polygon_set_2.h>

#include <iterator>

#include "exact_polygons.hpp"

// In core's exact-polygon unit (core/CMakeLists.txt), beside the validation's Boolean operations
// on the same types, so that CGAL's templates are compiled once for both (recon's CGAL unit has
// its own).
namespace sonoshape {
namespace {

using detail::EK;
using detail::ExactPolygon;
using detail::ExactPolygonWithHoles;

Ring2 rounded_ring(const ExactPolygon& polygon) {
  Ring2 ring;
  for (auto it = polygon.vertices_begin(); it != polygon.vertices_end(); ++it)
    ring.emplace_back(CGAL::to_double(it->x()), CGAL::to_double(it->y()));
  return ring;
}

}  // namespace

std::vector<Region> clip_region(const Region& region, const Ring2& shape, bool keep_inside) {
  CGAL::Polygon_set_2<EK> set;
  set.insert(detail::to_exact(region.outer, region.holes));
  const ExactPolygon cut = detail::to_exact(shape, CGAL::COUNTERCLOCKWISE);
  if (keep_inside)
    set.intersection(cut);
  else
    set.difference(cut);
  std::vector<ExactPolygonWithHoles> parts;
  set.polygons_with_holes(std::back_inserter(parts));
  std::vector<Region> regions;
  for (const ExactPolygonWithHoles& part : parts) {
    Region r;
    r.label = region.label;
    r.outer = rounded_ring(part.outer_boundary());
    for (auto h = part.holes_begin(); h != part.holes_end(); ++h)
      r.holes.push_back(rounded_ring(*h));
    regions.push_back(std::move(r));
  }
  return regions;
}

}  // namespace sonoshape
