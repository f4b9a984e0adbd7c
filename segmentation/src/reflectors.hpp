#pragma once
// Strong reflectors (bone): the probe sees only the surface band facing it and a shadow behind,
// so the label map gets the organ's cross-section from that band and the organ's thickness.
#include <opencv2/core.hpp>

namespace sonoshape::segmentation::detail {

/// Replaces every surface band of `label` in `map` (CV_8U; connected components of that value
/// at least `min_width_px` columns wide) by the organ's cross-section: an ellipse whose axis
/// along the image columns is `thickness_px`, whose top is the band's shallowest surface point
/// (the mean depth of the band down each column weighted by the grey `grey`, CV_32F: sub-pixel,
/// so that a coarse pixel size does not flatten the arc), and whose width is fitted to that
/// surface (the visible upper arc of the section). Only pixels where `sector` is
/// non-zero change. A rib or a long bone cut at any angle has such a section: its extent along
/// the beam stays the bone's thickness while its width grows with obliquity.
void fill_reflector_sections(cv::Mat& map, const cv::Mat& grey, const cv::Mat& sector,
                             std::uint8_t label, double thickness_px, int min_width_px);

}  // namespace sonoshape::segmentation::detail
