#include "sonoshape/scan/stages.hpp"

#include <stdexcept>
#include <utility>

#include "sonoshape/segmentation/contours.hpp"

namespace sonoshape::scan {

SegmenterStage::SegmenterStage(ScanSetup setup) : setup_(std::move(setup)) {
  setup_.geometry.check();
  if (const Status valid = setup_.segmentation.validate(); !valid)
    throw std::invalid_argument("segmentation configuration: " + valid.message());
}

Result<LabeledSlice> SegmenterStage::segment(const TrackedFrame& frame) {
  const seg::ImageGeometry& g = setup_.geometry;
  const GreyImage& image = frame.frame.image;
  if (image.width != g.width_px || image.height != g.height_px)
    return Status::error("frame " + std::to_string(frame.frame.index) + " is " +
                         std::to_string(image.width) + "x" + std::to_string(image.height) +
                         " but the setup expects " + std::to_string(g.width_px) + "x" +
                         std::to_string(g.height_px) + " (wrong probe preset?)");
  const seg::Segmentation segmentation = seg::segment_frame(image, g, setup_.segmentation);
  const Eigen::Matrix4d T_reference_probe = frame.T_reference_probe.matrix();
  const seg::ImagePlane plane = seg::image_plane(T_reference_probe * setup_.T_probe_image,
                                                 T_reference_probe.block<3, 1>(0, 3));
  repairs_.clear();
  auto slice = seg::make_slice(segmentation.labels, g.sector, g.sector_px, plane,
                               setup_.segmentation.simplify_mm, &repairs_);
  if (!slice) return slice.status();
  slice->timestamp_s = frame.frame.timestamp_s;
  return slice;
}

std::vector<Repair> SegmenterStage::take_repairs() { return std::exchange(repairs_, {}); }

}  // namespace sonoshape::scan
