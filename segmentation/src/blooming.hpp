#pragma once
// Where two tissues meet, the probe's point-spread function mixes their echo power; after log
// compression the mixed grey lies nearer the brighter tissue's, so a classifier of grey puts the
// boundary inside the darker tissue. This step moves every such boundary back.
#include <opencv2/core.hpp>
#include <vector>

namespace sonoshape::segmentation::detail {

/// A label value and its grey mean.
struct GreyClass {
  std::uint8_t value = 0;
  double grey_mean = 0.0;
};

/// The shift (mm) of the grey-midpoint crossing into the darker tissue at a boundary between
/// tissues of grey means `dark_grey` < `bright_grey`, blurred by a Gaussian point-spread
/// function of `psf_sigma_mm` in echo power and log-compressed over `dynamic_range_db`: with
/// r the power ratio, the grey midpoint is the geometric mean power, reached where the blurred
/// step has risen to 1 / (sqrt(r) + 1), that is at sigma * Phi^-1(1 / (sqrt(r) + 1)).
double blooming_shift_mm(double dark_grey, double bright_grey, double psf_sigma_mm,
                         double dynamic_range_db);

/// Gives the pixels of each class in `classes` (not `excluded`) whose centre lies within the
/// blooming shift of the grey midpoint to a darker class, next to a pixel of that class, back to
/// it (the nearest darker class first). The distance to the midpoint is measured on `grey`
/// (CV_32F, the grey the classes were decided on): the grey's excess over the midpoint over its
/// slope, to a fraction of a pixel. `map` CV_8U; only pixels where `sector` is non-zero change.
void undo_blooming(cv::Mat& map, const cv::Mat& sector, const cv::Mat& grey,
                   const std::vector<GreyClass>& classes, double psf_sigma_mm,
                   double dynamic_range_db, double spacing_mm, int excluded);

}  // namespace sonoshape::segmentation::detail
