#pragma once
// segment_frame with a step between classification and cleaning, for the graph-cut labeller.
#include <functional>
#include <opencv2/core.hpp>

#include "sonoshape/segmentation/segmenter.hpp"

namespace sonoshape::segmentation::detail {

/// A class (background or material) whose grey mean stands this far above every other's is a
/// strong reflector (bone): its thin band is found on the median-filtered grey and its
/// cross-section drawn from its thickness (segment_frame); the graph cut keeps it as drawn.
constexpr double kReflectorGapGrey = 60.0;

/// Called with the classified label map (CV_8U, changed in place), the smoothed (median, then
/// Gaussian) and depth-compensated grey that the classification read (CV_32F), the low-confidence
/// mask and the sector mask (CV_8U, 255 = set), before the morphological cleaning; it may set
/// `keep` (CV_8U) to the pixels whose small components the cleaning must keep.
using RefineStep = std::function<void(cv::Mat& map, const cv::Mat& grey, const cv::Mat& low,
                                      const cv::Mat& sector, cv::Mat& keep)>;

/// segment_frame, with `refine` (when set) run between classification and cleaning.
Segmentation segment_frame(const GreyImage& image, const ImageGeometry& geometry,
                           const SegmentationConfig& config, const RefineStep& refine);

}  // namespace sonoshape::segmentation::detail
