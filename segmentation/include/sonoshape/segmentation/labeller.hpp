#pragma once
// The spatially regularised labelling of a sweep's frames: each frame's pixel evidence (grey
// likelihoods under per-organ appearance models that are learnt and updated as the sweep goes),
// an optional prior label map (what the surfaces already reconstructed predict of the frame),
// and a contrast-sensitive Potts smoothness, minimised together by a multi-label graph cut
// (alpha-expansion over Boost.Graph's Boykov-Kolmogorov max-flow) on a grid of cells of about
// `cell_mm`. It refines segment_frame's threshold labelling, which seeds it; shadows and areas
// without signal stay unknown, and strong reflectors keep the threshold method's sections.
#include <memory>
#include <optional>

#include "sonoshape/core/image.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/segmentation/config.hpp"
#include "sonoshape/segmentation/contours.hpp"
#include "sonoshape/segmentation/segmenter.hpp"

namespace sonoshape::segmentation {

/// What the surfaces already reconstructed predict of a new frame: the prior of the graph cut.
/// Implemented where a reconstruction lives (the scan pipeline, `segment`).
class LabelPredictor {
 public:
  virtual ~LabelPredictor() = default;
  /// The label map the reconstruction predicts for a frame lying in `plane`, of the geometry's
  /// size (0 background, material ids, kLabelPixelUnknown outside the sector); none while
  /// nothing is reconstructed.
  virtual std::optional<LabelImage> predict(const ImagePlane& plane,
                                            const ImageGeometry& geometry) = 0;
  /// Adds the slice of a segmented frame to the reconstruction behind the predictions.
  virtual void add(const LabeledSlice& slice) = 0;
};

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
  /// where nothing is predicted); a frame before any surface exists passes none. `plane` (the
  /// frame's placement) lets the labels' seeds name look-alike organs; see assign_identities.
  ///
  /// Organs whose grey models the image cannot tell apart ("look-alikes": means closer than
  /// half their spread) are classified as one tissue (their models averaged) and get their
  /// identity from where they are: each connected region of such
  /// labels takes the label the prior predicts over it (split between the predicted organs,
  /// pixel by nearest prediction, where it overlaps several), else the label of the nearest
  /// seed (LabelModel::seed_mm) to its centroid, else keeps the cut's label.
  Segmentation segment(const GreyImage& image, const LabelImage* prior = nullptr,
                       const ImagePlane* plane = nullptr);

  const SegmentationConfig& config() const;
  const ImageGeometry& geometry() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::segmentation
