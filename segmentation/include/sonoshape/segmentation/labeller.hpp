#pragma once
// The spatially regularised labelling of a sweep's frames: each frame's pixel evidence (grey
// likelihoods under per-organ appearance models that are learnt and updated as the sweep goes),
// an optional prior label map (what the surfaces already reconstructed predict of the frame),
// and a contrast-sensitive Potts smoothness, minimised together by a multi-label graph cut
// (alpha-expansion over Boost.Graph's Boykov-Kolmogorov max-flow) on a grid of cells of about
// `cell_mm`. It refines segment_frame's threshold labelling, which seeds it; shadows and areas
// without signal stay unknown, and strong reflectors keep the threshold method's sections.
#include <memory>

#include "sonoshape/core/image.hpp"
#include "sonoshape/segmentation/config.hpp"
#include "sonoshape/segmentation/segmenter.hpp"

namespace sonoshape::seg {

/// Keeps what the labelling carries from frame to frame: the grid's graph (built for the
/// geometry once) and the appearance models. One per sweep; not thread-safe.
class GraphCutLabeller {
 public:
  /// Throws std::invalid_argument for an invalid configuration or geometry.
  GraphCutLabeller(const SegmentationConfig& config, const ImageGeometry& geometry,
                   const GraphCutOptions& options = {});
  ~GraphCutLabeller();
  GraphCutLabeller(GraphCutLabeller&&) noexcept;
  GraphCutLabeller& operator=(GraphCutLabeller&&) noexcept;

  /// Segments one frame: segment_frame's labelling refined by the graph cut. `prior`, when
  /// given, is a label map of the frame's size (0 background, material ids, kLabelPixelUnknown
  /// where nothing is predicted); a frame before any surface exists passes none.
  Segmentation segment(const GreyImage& image, const LabelImage* prior = nullptr);

  const SegmentationConfig& config() const;
  const ImageGeometry& geometry() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::seg
