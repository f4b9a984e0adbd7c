// Variants of a slice set's exact cuts that take one of a segmentation's losses at a time, to
// split an organ's shortfall of scan IoU below its exact-cut figure (docs/segmentation.md, "The
// default scan"): EXACT holds the exact cuts of the truth meshes by the planes of OURS (the
// segmented slices, the same slices in the same order; bench/field_table.py's exact_slices).
//   --shadow         every organ's exact cut minus OURS' unknown regions, which are added (the
//                    shadows and unknown margins the segmentation leaves)
//   --offset-mm D    moves the outlines of --label L outwards by D mm (inwards when negative)
//   --ends           drops --label L from the slices where OURS has none of it
//   --others-ours    the other organs' regions as OURS has them (only --label L exact)
// Usage: sonoshape_slice_variants EXACT OURS --label L [--shadow] [--offset-mm D] [--ends]
//                                 [--others-ours] -o OUT
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <polyclipping/clipper.hpp>
#include <string>

#include "sonoshape/core/slice_io.hpp"

namespace {

using namespace sonoshape;
using ClipperLib::Path;
using ClipperLib::Paths;

constexpr double kScale = 1e4;  // mm to Clipper's integers (0.1 um)

Path to_path(const Ring2& ring) {
  Path path;
  for (const Vec2& p : ring)
    path.push_back({static_cast<ClipperLib::cInt>(std::llround(p.x() * kScale)),
                    static_cast<ClipperLib::cInt>(std::llround(p.y() * kScale))});
  return path;
}

Ring2 to_ring(const Path& path) {
  Ring2 ring;
  for (const auto& q : path) ring.emplace_back(q.X / kScale, q.Y / kScale);
  return ring;
}

Paths paths_of(const LabeledSlice& slice, int label) {
  Paths paths;
  for (const Region& r : slice.regions)
    if (r.label == label) {
      paths.push_back(to_path(r.outer));
      for (const Ring2& hole : r.holes) paths.push_back(to_path(hole));
    }
  return paths;
}

// Regions (outer rings with their holes) of an even-odd set of paths.
void add_regions(const Paths& paths, int label, std::vector<Region>& regions) {
  ClipperLib::Clipper clipper;
  clipper.AddPaths(paths, ClipperLib::ptSubject, true);
  ClipperLib::PolyTree tree;
  clipper.Execute(ClipperLib::ctUnion, tree, ClipperLib::pftEvenOdd, ClipperLib::pftEvenOdd);
  for (const ClipperLib::PolyNode* node = tree.GetFirst(); node; node = node->GetNext()) {
    if (node->IsHole() || std::abs(ClipperLib::Area(node->Contour)) < kScale * kScale * 1e-3)
      continue;
    Region region{label, to_ring(node->Contour), {}};
    for (const ClipperLib::PolyNode* hole : node->Childs)
      region.holes.push_back(to_ring(hole->Contour));
    regions.push_back(std::move(region));
  }
}

Paths difference(const Paths& a, const Paths& b) {
  ClipperLib::Clipper clipper;
  clipper.AddPaths(a, ClipperLib::ptSubject, true);
  clipper.AddPaths(b, ClipperLib::ptClip, true);
  Paths out;
  clipper.Execute(ClipperLib::ctDifference, out, ClipperLib::pftEvenOdd, ClipperLib::pftNonZero);
  return out;
}

Paths offset(const Paths& paths, double mm) {
  ClipperLib::ClipperOffset offsetter;
  ClipperLib::Paths simple;
  ClipperLib::SimplifyPolygons(paths, simple, ClipperLib::pftEvenOdd);
  offsetter.AddPaths(simple, ClipperLib::jtRound, ClipperLib::etClosedPolygon);
  offsetter.ArcTolerance = 0.01 * kScale;
  Paths out;
  offsetter.Execute(out, mm * kScale);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::filesystem::path exact_path, ours_path, out_path;
  int label = 1, positional = 0;
  bool shadow = false, ends = false, others_ours = false;
  double offset_mm = 0.0;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    auto next = [&]() -> std::string { return k + 1 < argc ? argv[++k] : ""; };
    if (a == "--label")
      label = std::atoi(next().c_str());
    else if (a == "--shadow")
      shadow = true;
    else if (a == "--ends")
      ends = true;
    else if (a == "--others-ours")
      others_ours = true;
    else if (a == "--offset-mm")
      offset_mm = std::atof(next().c_str());
    else if (a == "-o")
      out_path = next();
    else if (positional++ == 0)
      exact_path = a;
    else
      ours_path = a;
  }
  if (positional != 2 || out_path.empty()) {
    std::cerr << "usage: sonoshape_slice_variants EXACT OURS --label L [--shadow] "
                 "[--offset-mm D] [--ends] [--others-ours] -o OUT\n";
    return 2;
  }
  auto exact = read_slice_set(exact_path);
  auto ours = read_slice_set(ours_path);
  if (!exact || !ours || exact->slices.size() != ours->slices.size()) {
    std::cerr << "error: "
              << (!exact  ? exact.message()
                  : !ours ? ours.message()
                          : "")
              << " (EXACT and OURS must hold the same slices)\n";
    return 1;
  }
  for (std::size_t k = 0; k < exact->slices.size(); ++k) {
    LabeledSlice& slice = exact->slices[k];
    const LabeledSlice& segmented = ours->slices[k];
    const Paths unknown = shadow ? paths_of(segmented, kUnknownLabel) : Paths{};
    std::vector<Region> regions;
    for (const int id : exact->material_ids()) {
      if (id != label && others_ours) {
        for (const Region& r : segmented.regions)
          if (r.label == id) regions.push_back(r);
        continue;
      }
      Paths paths = paths_of(slice, id);
      if (id == label && ends && paths_of(segmented, id).empty()) continue;
      if (id == label && offset_mm != 0.0) paths = offset(paths, offset_mm);
      if (!unknown.empty()) paths = difference(paths, unknown);
      add_regions(paths, id, regions);
    }
    // Ours' unknown regions on the same 0.1 um grid as the cuts clipped by them, so that the
    // two share their edges exactly (smoothed outlines do not lie on any grid).
    if (!unknown.empty()) add_regions(unknown, kUnknownLabel, regions);
    slice.regions = std::move(regions);
  }
  if (const Status written = write_slice_set_json(*exact, out_path); !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  return 0;
}
