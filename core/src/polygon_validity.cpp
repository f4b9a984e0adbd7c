#include "polygon_validity.hpp"

#include <CGAL/Boolean_set_operations_2.h>

namespace sonoshape::detail {

bool valid_for_boolean_ops(const CGAL::Polygon_with_holes_2<CGAL::Epeck>& pwh) {
  return CGAL::is_valid_polygon_with_holes(pwh, CGAL::Gps_segment_traits_2<CGAL::Epeck>());
}

}  // namespace sonoshape::detail
