#pragma once
// Test fixtures of `--labels`: label maps written as 3D Slicer saves a segmentation sequence
// (`.seq.nrrd`: 4D, `kinds: domain domain domain list`, `axis 3 index values` the frame times,
// `DataNodeClassName:=vtkMRMLSegmentationNode`, the Segment<i>_* keys of a segmentation), and
// rectangles of labels that change from frame to frame so that a frame paired with the wrong
// label map shows.
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "sonoshape/core/image.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::testing {

/// Writes `maps` (one label map per frame, all of one size) as a Slicer segmentation sequence:
/// 16-bit `short` samples (as Slicer writes label maps) when `sixteen_bit`, else `unsigned char`;
/// raw encoding; the index values `times_s` (none when empty); `Segment<i>_Name` /
/// `Segment<i>_LabelValue` / `Segment<i>_Layer` per entry of `names`.
inline void write_slicer_label_sequence(const std::filesystem::path& path,
                                        const std::vector<LabelImage>& maps,
                                        const std::vector<double>& times_s,
                                        const std::map<int, std::string>& names,
                                        bool sixteen_bit = true) {
  const int w = maps.at(0).width, h = maps.at(0).height;
  std::ostringstream header;
  header.precision(17);
  header << "NRRD0004\n# Complete NRRD file format specification at:\n"
         << "# http://teem.sourceforge.net/nrrd/format.html\n"
         << "type: " << (sixteen_bit ? "short" : "unsigned char") << "\ndimension: 4\n"
         << "space: left-posterior-superior\n"
         << "sizes: " << w << " " << h << " 1 " << maps.size() << "\n"
         << "space directions: (0.3,0,0) (0,0.3,0) (0,0,1) none\n"
         << "kinds: domain domain domain list\n"
         << "labels: \"\" \"\" \"\" \"frame\"\n"
         << "endian: little\nencoding: raw\nspace origin: (0,0,0)\n"
         << "DataNodeClassName:=vtkMRMLSegmentationNode\n";
  if (!times_s.empty()) {
    header << "axis 3 index type:=numeric\naxis 3 index values:=";
    for (std::size_t k = 0; k < times_s.size(); ++k) header << (k ? " " : "") << times_s[k];
    header << "\n";
  }
  header << "axis 3 quantity:=time\naxis 3 unit:=s\n";
  int i = 0;
  for (const auto& [value, name] : names) {
    const std::string key = "Segment" + std::to_string(i++) + "_";
    header << key << "Name:=" << name << "\n"
           << key << "LabelValue:=" << value << "\n"
           << key << "Layer:=0\n"
           << key << "Color:=0.5 0.5 0.5\n";
  }
  header << "\n";
  std::ofstream out(path, std::ios::binary);
  out << header.str();
  for (const LabelImage& map : maps)
    for (const std::uint8_t v : map.pixels) {
      out.put(static_cast<char>(v));
      if (sixteen_bit) out.put(0);  // little-endian high byte
    }
}

/// A rectangle of label pixels: columns [x0, x0 + w), rows [y0, y0 + h).
struct LabelRect {
  int label = 1;
  int x0 = 0, y0 = 0, w = 0, h = 0;
};

/// Fills the rectangles (later ones over earlier ones) into a `width` x `height` label map of
/// zeros.
inline LabelImage label_rectangles(int width, int height, const std::vector<LabelRect>& rects) {
  LabelImage map(width, height, 0);
  for (const LabelRect& r : rects)
    for (int j = r.y0; j < r.y0 + r.h; ++j)
      for (int i = r.x0; i < r.x0 + r.w; ++i) map.at(i, j) = static_cast<std::uint8_t>(r.label);
  return map;
}

/// The rectangles of frame k in the fixtures of a `width` x `height` image: organ `first`
/// growing by 3 columns a frame, organ `second` moving down by 3 rows a frame, and one block of
/// `unknown` (a shadow) of fixed size; all inside the image and apart for k in 0..7 (frame k
/// takes the pattern of k mod 8).
inline std::vector<LabelRect> fixture_rectangles(int frame, int width, int height, int first,
                                                 int second, int unknown) {
  const int k = frame % 8;
  return {{first, width / 8, height / 6, width / 5 + 3 * k, height / 4},
          {second, width / 2, height / 6 + 3 * k, width / 4, height / 6},
          {unknown, width / 8, (2 * height) / 3, width / 4, height / 8}};
}

/// Area (mm²) and centroid (u, v mm) of one label's regions in a slice.
struct LabelShape {
  double area_mm2 = 0.0;
  Vec2 centroid_mm = Vec2::Zero();
};

/// The shapes of every label of `slice` (unknown under kUnknownLabel); holes subtracted.
inline std::map<int, LabelShape> label_shapes(const LabeledSlice& slice) {
  std::map<int, LabelShape> out;
  std::map<int, Vec2> moment;
  const auto add_ring = [&](int label, const Ring2& ring, double sign) {
    double twice = 0.0;
    Vec2 m = Vec2::Zero();
    for (std::size_t i = 0; i < ring.size(); ++i) {
      const Vec2& a = ring[i];
      const Vec2& b = ring[(i + 1) % ring.size()];
      const double cross = a.x() * b.y() - b.x() * a.y();
      twice += cross;
      m += cross * (a + b);
    }
    const double orientation = twice < 0.0 ? -1.0 : 1.0;
    out[label].area_mm2 += sign * std::abs(twice) / 2.0;
    // (Eigen leaves a default-constructed vector uninitialised.)
    const auto [at, fresh] = moment.try_emplace(label, Vec2::Zero());
    at->second += sign * orientation * m / 6.0;
  };
  for (const Region& r : slice.regions) {
    add_ring(r.label, r.outer, 1.0);
    for (const Ring2& hole : r.holes) add_ring(r.label, hole, -1.0);
  }
  for (auto& [label, shape] : out) shape.centroid_mm = moment[label] / shape.area_mm2;
  return out;
}

/// The centre of a rectangle in pixel coordinates (column, row; pixel centres at integers).
inline Vec2 rect_centre_px(const LabelRect& r) {
  return Vec2(r.x0 + 0.5 * (r.w - 1), r.y0 + 0.5 * (r.h - 1));
}

}  // namespace sonoshape::testing
