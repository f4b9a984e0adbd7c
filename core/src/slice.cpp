#include "sonoshape/core/slice.hpp"

#include <algorithm>
#include <limits>
#include <set>

#include "sonoshape/core/reconstruction_box.hpp"
#include "sonoshape/core/slice_compare.hpp"

namespace sonoshape {

std::vector<int> SliceSet::material_ids() const {
  std::set<int> ids;
  for (const LabelInfo& l : labels) ids.insert(l.id);
  for (const LabeledSlice& s : slices)
    for (const Region& r : s.regions)
      if (r.label >= 1) ids.insert(r.label);
  return {ids.begin(), ids.end()};
}

std::string SliceSet::label_name(int id) const {
  for (const LabelInfo& l : labels)
    if (l.id == id && !l.name.empty()) return l.name;
  return "label_" + std::to_string(id);
}

LabelInfo SliceSet::label_info(int id) const {
  LabelInfo info{id, label_name(id)};
  for (const LabelInfo& l : labels)
    if (l.id == id) info.casts_shadow = info.casts_shadow || l.casts_shadow;
  return info;
}

Box3 SliceSet::effective_bounds() const {
  if (bounds) return *bounds;
  Box3 box{Vec3::Constant(std::numeric_limits<double>::infinity()),
           Vec3::Constant(-std::numeric_limits<double>::infinity())};
  bool any = false;
  for (const LabeledSlice& s : slices) {
    auto add_ring = [&](const Ring2& ring) {
      for (const Vec2& p : ring) {
        const Vec3 w = s.to_world(p);
        box.min = box.min.cwiseMin(w);
        box.max = box.max.cwiseMax(w);
        any = true;
      }
    };
    for (const Region& r : s.regions) {
      add_ring(r.outer);
      for (const Ring2& h : r.holes) add_ring(h);
    }
  }
  if (!any) return Box3{Vec3::Constant(-1.0), Vec3::Constant(1.0)};
  return reconstruction_box(box);
}

bool identical_slices(const LabeledSlice& a, const LabeledSlice& b) {
  if (a.origin_mm != b.origin_mm || a.u != b.u || a.v != b.v || a.fov != b.fov ||
      a.outline_sd_mm != b.outline_sd_mm || a.regions.size() != b.regions.size())
    return false;
  for (std::size_t r = 0; r < a.regions.size(); ++r)
    if (a.regions[r].label != b.regions[r].label || a.regions[r].outer != b.regions[r].outer ||
        a.regions[r].holes != b.regions[r].holes)
      return false;
  return true;
}

}  // namespace sonoshape
