#include "sonoshape/segmentation/contours.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/slice_io.hpp"

namespace sonoshape::seg {
namespace {

// Below this many pixels of area a ring is a line or a point, not a region.
constexpr double kMinRingAreaPx = 0.5;

Ring2 to_ring(const std::vector<cv::Point>& contour, double epsilon_px, const ImagePlane& plane) {
  std::vector<cv::Point> simplified;
  if (epsilon_px > 0.0) cv::approxPolyDP(contour, simplified, epsilon_px, true);
  const std::vector<cv::Point>& points = epsilon_px > 0.0 ? simplified : contour;
  if (points.size() < 3 || std::abs(cv::contourArea(points)) < kMinRingAreaPx) return {};
  Ring2 ring;
  ring.reserve(points.size());
  for (const cv::Point& p : points) ring.push_back(plane.to_plane(p.x, p.y));
  return ring;
}

}  // namespace

double ImagePlane::spacing_mm() const {
  return std::sqrt(std::abs(pixel_to_plane.leftCols<2>().determinant()));
}

ImagePlane image_plane(const Eigen::Matrix4d& T_reference_image, const Vec3& probe_origin_mm) {
  const Vec3 a = T_reference_image.block<3, 1>(0, 0);  // one column step, mm
  const Vec3 b = T_reference_image.block<3, 1>(0, 1);  // one row step, mm
  const Vec3 t = T_reference_image.block<3, 1>(0, 3);  // pixel (0, 0)
  if (!a.allFinite() || !b.allFinite() || !t.allFinite() ||
      a.cross(b).norm() <= 1e-12 * std::max(1.0, a.squaredNorm() + b.squaredNorm()))
    throw GeometryError(
        "image_plane: the calibrated pixel axes are degenerate or not finite; "
        "check the ImageToProbe calibration");
  ImagePlane plane;
  plane.u = a.normalized();
  plane.v = (b - b.dot(plane.u) * plane.u).normalized();
  const Vec3 n = plane.u.cross(plane.v);
  plane.origin_mm = probe_origin_mm - n.dot(probe_origin_mm - t) * n;
  const Vec3 offset = t - plane.origin_mm;
  plane.pixel_to_plane << a.dot(plane.u), b.dot(plane.u), offset.dot(plane.u),  //
      a.dot(plane.v), b.dot(plane.v), offset.dot(plane.v);
  return plane;
}

std::vector<Region> label_map_regions(const LabelImage& labels, const ImageU8& sector,
                                      const ImagePlane& plane, double tolerance_mm) {
  if (labels.width != sector.width || labels.height != sector.height ||
      labels.pixels.size() != sector.pixels.size())
    throw std::invalid_argument("label_map_regions: label map and sector differ in size");
  const cv::Mat map(labels.height, labels.width, CV_8U,
                    const_cast<std::uint8_t*>(labels.pixels.data()));
  const cv::Mat in_sector = cv::Mat(sector.height, sector.width, CV_8U,
                                    const_cast<std::uint8_t*>(sector.pixels.data())) > 0;
  std::array<bool, 256> present{};
  for (std::size_t p = 0; p < labels.pixels.size(); ++p)
    if (sector.pixels[p]) present[labels.pixels[p]] = true;
  const double epsilon_px = tolerance_mm / plane.spacing_mm();
  std::vector<Region> regions;
  for (int value = 1; value < 256; ++value) {
    if (!present[static_cast<std::size_t>(value)]) continue;
    // Outside the sector is unknown through the fov; only unknown inside it needs regions.
    const cv::Mat mask = (map == value) & in_sector;
    std::vector<std::vector<cv::Point>> contours;
    std::vector<cv::Vec4i> hierarchy;  // next, previous, first child, parent
    cv::findContours(mask, contours, hierarchy, cv::RETR_CCOMP, cv::CHAIN_APPROX_SIMPLE);
    for (std::size_t k = 0; k < contours.size(); ++k) {
      if (hierarchy[k][3] >= 0) continue;  // a hole: taken with its outer ring
      Region region;
      region.label = value == kLabelPixelUnknown ? kUnknownLabel : value;
      region.outer = to_ring(contours[k], epsilon_px, plane);
      if (region.outer.empty()) continue;
      for (int child = hierarchy[k][2]; child >= 0;
           child = hierarchy[static_cast<std::size_t>(child)][0]) {
        Ring2 hole = to_ring(contours[static_cast<std::size_t>(child)], epsilon_px, plane);
        if (!hole.empty()) region.holes.push_back(std::move(hole));
      }
      regions.push_back(std::move(region));
    }
  }
  return regions;
}

Result<LabeledSlice> make_slice(const LabelImage& labels, const ImageU8& sector,
                                const Ring2& sector_px, const ImagePlane& plane,
                                double tolerance_mm) {
  LabeledSlice slice;
  slice.origin_mm = plane.origin_mm;
  slice.u = plane.u;
  slice.v = plane.v;
  Ring2 fov;
  for (const Vec2& p : sector_px) fov.push_back(plane.to_plane(p.x(), p.y()));
  slice.fov = std::move(fov);
  // Simplification may make neighbouring outlines cross or a ring touch itself: fall back to
  // smaller tolerances, down to the exact pixel outlines (which the label map keeps simple).
  std::vector<double> tolerances;
  for (double t = tolerance_mm; t > 0.05 * plane.spacing_mm(); t *= 0.5) tolerances.push_back(t);
  tolerances.push_back(0.0);
  Status last;
  for (const double tolerance : tolerances) {
    slice.regions = label_map_regions(labels, sector, plane, tolerance);
    SliceSet one;
    one.slices.push_back(slice);
    last = validate_slice_set(one, "segmented frame");
    if (last) return slice;
  }
  return last;
}

}  // namespace sonoshape::seg
