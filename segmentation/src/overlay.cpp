#include "sonoshape/segmentation/overlay.hpp"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "raster_ops.hpp"
#include "sonoshape/core/png_file.hpp"

namespace sonoshape::segmentation {
namespace {

using detail::wrap;

// Outline colours (BGR) per material; the truth's outline is white.
cv::Vec3b label_colour(std::uint8_t label) {
  switch (label % 6) {
    case 1:
      return {60, 160, 255};  // orange
    case 2:
      return {80, 220, 80};  // green
    case 3:
      return {255, 120, 60};  // blue
    case 4:
      return {220, 80, 220};  // magenta
    case 5:
      return {60, 220, 255};  // yellow
    default:
      return {255, 220, 60};  // cyan
  }
}
const cv::Vec3b kTruthColour(255, 255, 255);

// Pixels of a material whose 4-neighbour holds another value: its outline, one pixel wide.
bool on_outline(const cv::Mat& map, int i, int j) {
  const std::uint8_t v = map.at<std::uint8_t>(j, i);
  if (v == kLabelPixelOutside || v == kLabelPixelUnknown) return false;
  const int w = map.cols, h = map.rows;
  return (i > 0 && map.at<std::uint8_t>(j, i - 1) != v) ||
         (i + 1 < w && map.at<std::uint8_t>(j, i + 1) != v) ||
         (j > 0 && map.at<std::uint8_t>(j - 1, i) != v) ||
         (j + 1 < h && map.at<std::uint8_t>(j + 1, i) != v);
}

}  // namespace

Status write_overlay(const std::filesystem::path& path, const GreyImage& frame,
                     const LabelImage& ours, const ImageU8& sector, const LabelImage* truth) {
  for (const ImageU8* image : {&ours, &sector, truth})
    if (image && (image->width != frame.width || image->height != frame.height))
      return Status::error("overlay " + path.string() + ": the label maps (" +
                           std::to_string(image->width) + "x" + std::to_string(image->height) +
                           ") and the frame (" + std::to_string(frame.width) + "x" +
                           std::to_string(frame.height) + ") differ in size");
  cv::Mat picture;
  cv::cvtColor(wrap(frame), picture, cv::COLOR_GRAY2BGR);
  const cv::Mat map = wrap(ours), inside = wrap(sector);
  for (int j = 0; j < picture.rows; ++j)
    for (int i = 0; i < picture.cols; ++i) {
      cv::Vec3b& p = picture.at<cv::Vec3b>(j, i);
      const std::uint8_t v = map.at<std::uint8_t>(j, i);
      if (v == kLabelPixelUnknown && inside.at<std::uint8_t>(j, i))
        p = cv::Vec3b(static_cast<std::uint8_t>(p[0] / 2 + 60), static_cast<std::uint8_t>(p[1] / 2),
                      static_cast<std::uint8_t>(p[2] / 2 + 40));  // purple tint: unknown
      if (truth && on_outline(wrap(*truth), i, j)) p = kTruthColour;
      if (on_outline(map, i, j)) p = label_colour(v);
    }
  if (truth) {
    const double scale = std::max(0.35, picture.cols / 1200.0);
    cv::putText(picture, "white: truth   colour: ours   purple: unknown", cv::Point(6, 18),
                cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  const Status written =
      write_png(path, PngPixels::kBgr, picture.cols, picture.rows, picture.ptr<std::uint8_t>(0),
                static_cast<std::ptrdiff_t>(picture.step));
  if (!written) return Status::error("overlay: " + written.message());
  return Status::ok();
}

}  // namespace sonoshape::segmentation
