#pragma once
// A specular echo: where the beam meets a boundary between tissues of different impedance it
// reflects as from a mirror, a thin bright line along the boundary (an organ's capsule), brighter
// than the tissues on both sides. A classifier of grey gives the line to the brighter tissue, so
// a hypoechoic organ loses the line's width at its top and bottom and a hyperechoic one gains it.
// Internal to the segmentation module.
#include <opencv2/core.hpp>

namespace sonoshape::segmentation::detail {

/// `grey` (CV_8U) with its boundary echoes replaced: a pixel of the sector whose grey, averaged
/// over about 2 mm across the beam (the image rows), exceeds by more than `contrast_grey` the
/// same average about 1 mm above and 1 mm below it belongs to a line brighter than both sides;
/// each run of such pixels down a column (at most as long as those 2 mm) is filled by the linear
/// interpolation between the averages just above and just below it, so that the boundary lies
/// at the line's middle. Pixels outside the sector are kept.
cv::Mat fill_boundary_echoes(const cv::Mat& grey, const cv::Mat& sector, double spacing_mm,
                             double contrast_grey);

}  // namespace sonoshape::segmentation::detail
