#pragma once
// The mean-value field of every label inside the cells of the arrangement (Bermano et al. 2011,
// Sections 4.2-4.4 and 6): face images (each slice's labelled regions clipped to each of its
// faces) and the CPU reference evaluator.
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "arrangement.hpp"
#include "chain_tree.hpp"
#include "mean_value.hpp"
#include "sonoshape/core/slice.hpp"
#include "triangle_tree.hpp"
#include "unknown_regions.hpp"

namespace sonoshape::recon {

/// A ring's edges by horizontal band, so that a face image tests only the edges near its face
/// (every face on a slice tested every edge of the slice's rings: a fifth of the offline time at
/// 200 random slices, perf). Band b holds, in ring order, every edge i (ring[i] -> ring[i + 1])
/// whose y-span grown by half its length meets the band: the edges that can decide
/// winding_number at a point of the band (one with the point on it lies within half its length
/// of the point) and every edge whose box meets the band.
struct RingBands {
  double y0 = 0.0, height = 1.0;
  std::vector<std::uint32_t> offsets;  ///< band b: edges[offsets[b], offsets[b + 1])
  std::vector<std::uint32_t> edges;
  /// The band of y (clamped to the first and last).
  std::size_t band(double y) const;
};
/// The bands of `ring` (about four edges per band, at most 256 bands).
RingBands make_ring_bands(const Ring2& ring);
/// winding_number(ring, p) from the edges of p's band only: the same result.
int winding_number_in_bands(const Ring2& ring, const RingBands& bands, const Vec2& p);

/// A slice prepared for the engine: its frame and, per material index (1..K), the rings of its
/// regions, outer rings counter-clockwise and holes clockwise in (u, v).
struct PreparedSlice {
  Vec3 origin;
  Vec3 u, v;
  Vec3 unit_normal;
  std::vector<std::vector<Ring2>> rings_by_material;            ///< index 0 unused (outside)
  std::vector<std::vector<std::pair<Vec2, Vec2>>> ring_bounds;  ///< (min, max) of each ring
  std::vector<std::vector<RingBands>> ring_bands;               ///< the edges of each ring by band
  std::vector<UnknownComponent> unknown;  ///< unknown set (regions and outside the fov)
  std::vector<Ring2> known;  ///< the known set when `unknown` is not empty (SlicePartition::known)
  double outline_sd_mm = 0.0;  ///< LabeledSlice::outline_sd_mm (the thin-plate field's alone)
  /// When `unknown` is not empty: the field of view (if any) and the plane's polygon in the box,
  /// any orientation. A point of the unknown set inside every one of them lies in one of the
  /// slice's unknown regions (a shadow, noise), not beyond where the slice looks.
  std::vector<Ring2> view;
};

/// Converts the slices: material ids -> dense indices 1..K (`material_ids[k-1]` is the id of k).
/// Slices with unknown regions or a field of view are partitioned inside `box`.
std::vector<PreparedSlice> prepare_slices(const SliceSet& set, const std::vector<int>& material_ids,
                                          const Box3& box);
/// One slice of prepare_slices; `index` names it in errors.
PreparedSlice prepare_slice(const LabeledSlice& slice, std::size_t index,
                            const std::vector<int>& material_ids, const Box3& box);

/// A 2D frame of a plane: point -> ((p - origin).u, (p - origin).v), height |(p - origin).n|.
struct PlaneFrame {
  Vec3 origin, u, v, unit_normal;
};

/// One face's image: its polygon and, per material, the oriented rings of the material inside it.
struct FaceImage {
  int frame = -1;
  std::uint32_t polygon_begin = 0, polygon_count = 0;  ///< in points (counter-clockwise)
  struct Part {
    int material = 0;
    std::uint32_t begin = 0, count = 0;           ///< one ring in points
    std::uint32_t tree_root = 0, tree_count = 0;  ///< far-field tree in tree_nodes (count 0: none)
    /// +1 / -1: the ring is the face polygon itself (reversed for -1, a hole around the face),
    /// so its integral is +/- the polygon's; 0: a clipped ring.
    int polygon_copy = 0;
  };
  std::vector<Part> parts;
  std::vector<Part> unknown_parts;  ///< the unknown set clipped to the face (material unused)
  /// The known set clipped to the face (material unused), for the completion's 3D part, when the
  /// slice has an unknown set (known_clipped); otherwise the whole face is known.
  std::vector<Part> known_parts;
  bool known_clipped = false;
  bool fully_unknown = false;                            ///< no known data on the face at all
  std::uint32_t triangle_begin = 0, triangle_count = 0;  ///< completed unknown triangles
  /// Far-field tree of the triangles (root first) and its moments, held by the slice's
  /// completion (null: none, summed directly).
  const TriangleNode* triangle_tree = nullptr;
  const double* triangle_tree_moments = nullptr;
};

/// Clips a closed ring to the convex region { p : a_i.p + c_i >= 0 for all i } (Sutherland-
/// Hodgman). The result may contain degenerate back-and-forth edges along the clip lines; these
/// cancel in every boundary integral, which is all the field needs. Empty if nothing is inside.
Ring2 clip_ring_to_convex(const Ring2& ring, const std::vector<Eigen::Vector3d>& half_planes);

/// Field of all labels over the arrangement. evaluate() is thread-safe (read-only).
class CellField {
 public:
  /// The field of `slices` over `arrangement` (whose planes refer to them by index): every face
  /// image and the completion of the unknown regions.
  CellField(const Arrangement& arrangement, const std::vector<PreparedSlice>& slices,
            int material_count);
  /// An empty field over `arrangement`; slices come with add_slice() and refresh().
  CellField(const Arrangement& arrangement, int material_count);

  /// Appends a slice: its index is the number of slices before the call.
  void add_slice(PreparedSlice slice);
  /// Brings the images up to date after planes were inserted into the arrangement (online
  /// engine): builds the images of the faces created since the last refresh, rebuilds those of
  /// `split_faces` (older faces whose polygon the new planes cut; an image depends on its face's
  /// polygon and slice only, so the other faces keep theirs) and redoes the completion of the
  /// unknown regions. Returns the cells whose faces' completed values changed: their field
  /// changed too.
  std::vector<int> refresh(const std::vector<int>& split_faces);
  /// Drops the images of `faces`, which no cell reads any more (faces an on-demand arrangement
  /// retired), so that the next refresh reclaims their points.
  void release_images(const std::vector<int>& faces);

  /// Number of functions: materials + 1 (index 0 is the outside).
  int function_count() const { return material_count_ + 1; }
  /// f_l(p) for l = 0..K into `out` (function_count() doubles), each in [-1, 1]; outside the
  /// box (and on it) the outside label holds. Returns the cell used (-1 outside the box).
  int evaluate(const Vec3& p, double* out) const;
  /// evaluate() in a given cell: `cell` must contain p (the arrangement's locate or
  /// construct_cell of p), with the images of its faces built (refresh after construct_cell).
  /// Returns `cell` (-1 outside the box).
  int evaluate_in(int cell, const Vec3& p, double* out) const;
  /// Unknown-region statistics: triangles, cell groups, completion seconds.
  std::size_t unknown_triangle_count() const { return triangles_.size(); }
  std::size_t group_count() const { return group_count_; }
  double completion_seconds() const { return completion_seconds_; }
  /// Slices whose unknown regions the last refresh triangulated and completed again.
  std::size_t recompleted_slice_count() const { return recompleted_slices_; }
  /// Completed value of function l at corner k of unknown triangle t.
  double corner_value(std::size_t t, int k, int l) const {
    return corner_values_[(t * 3 + static_cast<std::size_t>(k)) *
                              static_cast<std::size_t>(function_count()) +
                          static_cast<std::size_t>(l)];
  }
  const std::vector<UnknownTriangle>& unknown_triangles() const { return triangles_; }
  const FaceImage& face_image(int face) const { return images_[static_cast<std::size_t>(face)]; }
  const std::vector<Vec2>& points() const { return points_; }
  const std::vector<PreparedSlice>& slices() const { return slices_; }

  /// What a device evaluator copies to its memory (device_field.cpp), read-only. `version`
  /// changes at every refresh() and is unique across fields: the arrays are as they were while
  /// it stays the same. Between two compactions `points` and `tree_nodes` only grow (a rebuilt
  /// image appends its own), and `image_generations[f]` changes when face f's image is rebuilt:
  /// a device copies what is new.
  struct Internals {
    const Arrangement& arrangement;
    const std::vector<PlaneFrame>& frames;
    const std::vector<FaceImage>& images;
    const std::vector<std::uint64_t>& image_generations;
    const std::vector<Vec2>& points;
    const std::vector<ChainNode>& tree_nodes;
    std::uint64_t compactions;
    const std::vector<UnknownTriangle>& triangles;
    const std::vector<double>& corner_values;
    double on_face_height;
    std::uint64_t version;
  };
  Internals internals() const {
    return {arrangement_, frames_,    images_,        image_generations_, points_, tree_nodes_,
            compactions_, triangles_, corner_values_, on_face_height_,    version_};
  }

 private:
  // The unknown triangles and completed values of one slice, and what they were computed from.
  struct SliceCompletion {
    std::vector<std::pair<int, std::uint64_t>> inputs;    // (face, image generation) read
    std::vector<int> faces;                               // faces that got triangles
    std::vector<std::vector<UnknownTriangle>> triangles;  // per entry of faces
    std::vector<std::vector<double>> values;              // 3 x function_count() per triangle
    // Per entry of faces: the far-field tree of its triangles (empty: too few for one; the
    // triangles and values are in its order) and an order-independent hash of the triangles
    // and values, which tells a refresh whose completion changed.
    std::vector<std::vector<TriangleNode>> tree_nodes;
    std::vector<std::vector<double>> tree_moments;
    std::vector<std::uint64_t> hashes;
  };
  // Builds the images of `faces` (on the calling arena's threads, the same result on any number).
  void build_images(const std::vector<int>& faces);
  // Builds the image of one face, its points and trees appended to `points` and `trees` (offsets
  // into those); writes images_[face_id] only.
  void build_face_image(int face_id, std::vector<Vec2>& points, std::vector<ChainNode>& trees);
  bool outside_box(const Vec3& p, double* out) const;
  // Gives a long part its far-field tree.
  static void add_tree(FaceImage::Part& part, const std::vector<Vec2>& points,
                       std::vector<ChainNode>& trees);
  // The plain edge sum (projected_angle_plain) of a part, through its tree when it has one. The
  // field and the completion add these into sums over a cell's faces, of order 1 / height of the
  // nearest face, and divide by their total: an absolute error of rounding in each term is all
  // they need. The split form that keeps a small term's relative accuracy (a foot outside the
  // part at small height) cost about a tenth of a sector sweep's update time.
  double part_angle(const FaceImage::Part& part, const Vec2& foot, double height) const {
    if (part.tree_count == 0) {
      if (part.count < 2 || !(height > 0.0)) return 0.0;
      return projected_angle_plain(points_.data() + part.begin, part.count, foot, height);
    }
    return projected_angle_tree_plain(points_.data() + part.begin, part.count, tree_nodes_.data(),
                                      part.tree_root, foot, height);
  }
  // part_angle from four (foot, height) at once (heights > 0), each result part_angle's to the bit.
  void part_angle4(const FaceImage::Part& part, const double (&foot_x)[4],
                   const double (&foot_y)[4], const double (&height)[4], double (&out)[4]) const {
    if (part.tree_count != 0) {
      for (std::size_t k = 0; k < 4; ++k)
        out[k] = part_angle(part, Vec2(foot_x[k], foot_y[k]), height[k]);
    } else if (part.count < 2) {
      std::fill(out, out + 4, 0.0);
    } else {
      projected_angle_plain4(points_.data() + part.begin, part.count, foot_x, foot_y, height, out);
    }
  }
  // The field at a point on face `image` (foot: its position in the face's plane): the face's
  // own data (evaluate_in's first step for points within on_face_height_).
  void value_on_face(const FaceImage& image, const Vec2& foot, double* out) const;
  // Adds the completed unknown triangles' shares of face `image`, seen from (foot, height), to
  // w[l] (face_w: function_count() doubles of scratch) and returns the unknown part's weight.
  double add_unknown_shares(const FaceImage& image, const Vec2& foot, double height, double* face_w,
                            double* w) const;
  void update_frames();
  void compact_points();
  // Completes the stale slices (with their trees and hashes, see SliceCompletion) and gathers
  // every slice's triangles into the face images; face_completion_hashes_ follows.
  void build_unknown_images();
  // The steps of build_unknown_images (completion.cpp). The slices with unknown regions whose
  // completion read a face image rebuilt since (`inputs[s]`: the faces slice s reads now, with
  // their generations).
  std::vector<int> stale_slices(
      const std::vector<int>& slices_with_unknown, const std::vector<std::vector<int>>& slice_faces,
      const std::vector<std::vector<int>>& local_faces,
      std::vector<std::vector<std::pair<int, std::uint64_t>>>& inputs) const;
  // Triangulates and completes slice `slice` again, with its trees and hashes.
  void complete_slice(int slice, const std::vector<int>& slice_faces,
                      const std::vector<std::vector<int>>& local_faces,
                      std::vector<std::pair<int, std::uint64_t>> inputs);
  // Gathers the triangles, values and trees of every slice into the face images.
  void install_completions(const std::vector<int>& slices_with_unknown);
  // Triangulates the unknown set of a slice, one list per face, and completes the corners of
  // every triangle (values: 3 x function_count() per triangle); `local_faces[f]`: the known
  // faces around face f, sorted (a corner reads those of all the faces it lies on).
  void triangulate_unknown(int slice, const std::vector<int>& slice_faces,
                           const std::vector<std::vector<int>>& local_faces,
                           SliceCompletion& out) const;
  // The parts of formula 7 at the corners of one slice (completion.cpp).
  struct CornerCache;
  // The steps of triangulate_unknown and their working state (completion.cpp).
  class UnknownTriangulator;
  // Computes the parts of formula 7 that `cache` lists for this refinement round of slice s, in
  // parallel; the j-th 3D part reads the union of the sorted lists of known faces corner_faces[j].
  void complete_round(const PreparedSlice& s,
                      const std::vector<std::vector<std::span<const int>>>& corner_faces,
                      CornerCache& cache) const;
  // Known weights of face f seen from up to four points at once (`count`, 1 to 4; units of
  // projected_angle / height): the known part of the face and each material's part (added to
  // materials[k * function_count() + material] for point k). ok[k] is false where point k is on
  // f's plane (or k >= count); those lanes' outputs are meaningless.
  void known_weights4(int face, const Vec3 (&points)[4], std::size_t count, double (&known)[4],
                      double* materials, bool (&ok)[4]) const;
  // Prefetches the records of the faces after faces[i] that known_weights4 will read.
  void prefetch_known_reads(std::span<const int> faces, std::size_t i) const;

  const Arrangement& arrangement_;
  std::vector<PreparedSlice> slices_;
  int material_count_;
  double on_face_height_;                  // below this height a point is on the face
  std::size_t next_compaction_check_ = 0;  // compact_points counts live points from this size
  std::vector<PlaneFrame> frames_;         // one per arrangement plane
  std::vector<Vec2> points_;
  std::vector<ChainNode> tree_nodes_;  // far-field trees of the long parts
  std::vector<FaceImage> images_;
  std::vector<UnknownTriangle> triangles_;
  std::vector<double> corner_values_;                  // 3 corners x function_count() per triangle
  std::vector<std::uint64_t> face_completion_hashes_;  // per face (0: no triangles)
  std::size_t group_count_ = 0;
  double completion_seconds_ = 0.0;
  // When each face image was last built: a slice's completion is redone only when an image it
  // reads (its own faces and their local faces) was rebuilt since.
  std::vector<std::uint64_t> image_generations_;
  std::uint64_t last_image_generation_ = 0;
  std::vector<SliceCompletion> slice_completions_;  // per slice
  std::size_t recompleted_slices_ = 0;
  bool images_released_ = false;   // release_images() since the last refresh
  std::uint64_t version_ = 0;      // see Internals
  std::uint64_t compactions_ = 0;  // compact_points() calls that moved the points
};

}  // namespace sonoshape::recon
