#include "sonoshape/scan/label_prior.hpp"

#include <algorithm>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "sonoshape/core/log.hpp"
#include "sonoshape/core/mesh_slicer.hpp"

namespace sonoshape::scan {
namespace {

constexpr int kSubpixelBits = 4;  // fillPoly's fixed-point vertices: 1/16 pixel

double ring_area(const Ring2& ring) { return std::abs(signed_area(ring)); }

}  // namespace

LabelImage predict_label_map(const MeshSet& meshes, const segmentation::ImagePlane& plane,
                             const segmentation::ImageGeometry& geometry) {
  std::vector<LabeledMesh> labelled;
  for (const auto& entry : meshes.meshes)
    if (!entry.mesh.triangles.empty()) labelled.push_back({entry.label, entry.name, entry.mesh});
  LabeledSlice cut;
  if (!labelled.empty()) cut = slice_meshes(labelled, {plane.origin_mm, plane.u, plane.v});
  // Plane mm -> pixel: the inverse of the image plane's affine map.
  const Eigen::Matrix2d to_pixel = plane.pixel_to_plane.leftCols<2>().inverse();
  const Vec2 offset = plane.pixel_to_plane.col(2);
  auto pixel_points = [&](const Ring2& ring) {
    std::vector<cv::Point> points;
    for (const Vec2& p : ring) {
      const Vec2 px = to_pixel * (p - offset);
      points.emplace_back(static_cast<int>(std::lround(px.x() * (1 << kSubpixelBits))),
                          static_cast<int>(std::lround(px.y() * (1 << kSubpixelBits))));
    }
    return points;
  };
  cv::Mat map(geometry.height_px, geometry.width_px, CV_8U, cv::Scalar(kLabelPixelOutside));
  // Larger regions first: a nested organ's region (inside a hole of its host) is drawn later,
  // over the host's hole.
  std::vector<const Region*> regions;
  for (const Region& r : cut.regions)
    if (r.label != kUnknownLabel) regions.push_back(&r);
  std::sort(regions.begin(), regions.end(), [](const Region* a, const Region* b) {
    return ring_area(a->outer) > ring_area(b->outer);
  });
  for (const Region* r : regions) {
    cv::fillPoly(map, std::vector<std::vector<cv::Point>>{pixel_points(r->outer)},
                 cv::Scalar(r->label), cv::LINE_8, kSubpixelBits);
    for (const Ring2& hole : r->holes)
      cv::fillPoly(map, std::vector<std::vector<cv::Point>>{pixel_points(hole)},
                   cv::Scalar(kLabelPixelOutside), cv::LINE_8, kSubpixelBits);
  }
  LabelImage out(geometry.width_px, geometry.height_px);
  for (int j = 0; j < geometry.height_px; ++j)
    for (int i = 0; i < geometry.width_px; ++i)
      out.at(i, j) = geometry.sector.at(i, j) ? map.at<std::uint8_t>(j, i) : kLabelPixelUnknown;
  return out;
}

ReconstructionPrior::ReconstructionPrior(recon::ReconstructorOptions options)
    : reconstructor_(std::move(options)) {}

void ReconstructionPrior::add(const LabeledSlice& slice) {
  try {
    reconstructor_.add_slice(slice);
    pending_ = true;
  } catch (const std::invalid_argument& e) {
    // A slice the engine refuses only costs its frame's contribution to later priors.
    log_warning(std::string("segment: the prior's reconstruction skips a slice: ") + e.what());
  }
}

std::optional<LabelImage> ReconstructionPrior::predict(
    const segmentation::ImagePlane& plane, const segmentation::ImageGeometry& geometry) {
  if (pending_) {
    pending_ = false;
    try {
      reconstructor_.update();
    } catch (const std::exception& e) {
      log_warning(std::string("segment: the prior's reconstruction kept its last meshes: ") +
                  e.what());
    }
  }
  const MeshSet& meshes = reconstructor_.mesh();
  const bool any = std::any_of(meshes.meshes.begin(), meshes.meshes.end(),
                               [](const MeshSet::Entry& e) { return !e.mesh.triangles.empty(); });
  if (!any) return std::nullopt;
  return predict_label_map(meshes, plane, geometry);
}

}  // namespace sonoshape::scan
