#include "cell_field.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <limits>
#include <span>

#include "grow.hpp"
#include "mean_value.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::recon {

PreparedSlice prepare_slice(const LabeledSlice& slice, std::size_t s,
                            const std::vector<int>& material_ids, const Box3& box) {
  {
    PreparedSlice p;
    p.origin = slice.origin_mm;
    p.u = slice.u;
    p.v = slice.v;
    p.unit_normal = slice.u.cross(slice.v).normalized();
    p.outline_sd_mm = slice.outline_sd_mm;
    p.rings_by_material.resize(material_ids.size() + 1);
    const bool has_unknown =
        slice.fov || std::any_of(slice.regions.begin(), slice.regions.end(),
                                 [](const Region& r) { return r.label == kUnknownLabel; });
    if (has_unknown) {
      // Known materials inside the fov and outside unknown regions, and the unknown set.
      Ring2 plane_in_box = plane_box_polygon(p.origin, p.u, p.v, box);
      SlicePartition partition = partition_slice(slice, material_ids, plane_in_box);
      p.rings_by_material = std::move(partition.materials);
      p.unknown = std::move(partition.unknown);
      if (!p.unknown.empty()) {
        p.known = std::move(partition.known);
        if (slice.fov) p.view.push_back(*slice.fov);
        p.view.push_back(std::move(plane_in_box));
      }
    }
    for (const Region& region : slice.regions) {
      if (has_unknown) break;
      const auto it = std::find(material_ids.begin(), material_ids.end(), region.label);
      if (it == material_ids.end())
        throw GeometryError("slice " + std::to_string(s) + ": label " +
                            std::to_string(region.label) + " is not a material of the set");
      auto& rings = p.rings_by_material[static_cast<std::size_t>(it - material_ids.begin()) + 1];
      Ring2 outer = region.outer;
      if (signed_area(outer) < 0.0) std::reverse(outer.begin(), outer.end());
      rings.push_back(std::move(outer));
      for (Ring2 hole : region.holes) {
        if (signed_area(hole) > 0.0) std::reverse(hole.begin(), hole.end());
        rings.push_back(std::move(hole));
      }
    }
    p.ring_bounds.resize(p.rings_by_material.size());
    p.ring_bands.resize(p.rings_by_material.size());
    for (std::size_t m = 0; m < p.rings_by_material.size(); ++m)
      for (const Ring2& ring : p.rings_by_material[m]) {
        p.ring_bands[m].push_back(make_ring_bands(ring));
        Vec2 lo = ring[0], hi = ring[0];
        for (const Vec2& q : ring) {
          lo = lo.cwiseMin(q);
          hi = hi.cwiseMax(q);
        }
        p.ring_bounds[m].emplace_back(lo, hi);
      }
    return p;
  }
}

std::size_t RingBands::band(double y) const {
  const double b = std::floor((y - y0) / height);
  const std::size_t last = offsets.size() - 2;
  return !(b > 0.0) ? 0 : (b >= static_cast<double>(last) ? last : static_cast<std::size_t>(b));
}

RingBands make_ring_bands(const Ring2& ring) {
  // Each edge's y-span grown by half its length (and a little more for the rounding of the
  // tests), so that the bands hold every edge that can decide a test in them.
  const std::size_t n = ring.size();
  std::vector<std::pair<double, double>> spans(n);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2& a = ring[i];
    const Vec2& b = ring[i + 1 < n ? i + 1 : 0];
    const double grow =
        0.5 * (b - a).norm() * (1.0 + 1e-6) + 1e-9 * (std::abs(a.y()) + std::abs(b.y()) + 1.0);
    spans[i] = {std::min(a.y(), b.y()) - grow, std::max(a.y(), b.y()) + grow};
    lo = std::min(lo, spans[i].first);
    hi = std::max(hi, spans[i].second);
  }
  RingBands bands;
  const std::size_t count = std::clamp<std::size_t>(n / 4, 1, 256);
  bands.y0 = lo;
  bands.height = hi > lo ? (hi - lo) / static_cast<double>(count) : 1.0;
  bands.offsets.assign(count + 1, 0);
  // Two passes: the number of edges per band, then the edges in ring order.
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::uint32_t> at(bands.offsets.begin(), bands.offsets.end() - 1);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t b = bands.band(spans[i].first); b <= bands.band(spans[i].second); ++b) {
        if (pass == 0)
          ++bands.offsets[b + 1];
        else
          bands.edges[at[b]++] = static_cast<std::uint32_t>(i);
      }
    if (pass == 0) {
      for (std::size_t b = 0; b < count; ++b) bands.offsets[b + 1] += bands.offsets[b];
      bands.edges.resize(bands.offsets.back());
    }
  }
  return bands;
}

int winding_number_in_bands(const Ring2& ring, const RingBands& bands, const Vec2& p) {
  // winding_number's loop over the edges of p's band: the others neither cross p's row nor
  // have p on them.
  const std::size_t b = bands.band(p.y());
  const std::size_t n = ring.size();
  int winding = 0;
  for (std::uint32_t k = bands.offsets[b]; k < bands.offsets[b + 1]; ++k) {
    const std::size_t i = bands.edges[k];
    const Vec2& a = ring[i];
    const Vec2& c = ring[i + 1 < n ? i + 1 : 0];
    const double side = (c.x() - a.x()) * (p.y() - a.y()) - (p.x() - a.x()) * (c.y() - a.y());
    if (side == 0.0 && (p - a).dot(p - c) <= 0.0) return 1;  // on the edge
    if (a.y() <= p.y()) {
      if (c.y() > p.y() && side > 0.0) ++winding;
    } else if (c.y() <= p.y() && side < 0.0) {
      --winding;
    }
  }
  return winding;
}

std::vector<PreparedSlice> prepare_slices(const SliceSet& set, const std::vector<int>& material_ids,
                                          const Box3& box) {
  std::vector<PreparedSlice> out;
  out.reserve(set.slices.size());
  for (std::size_t s = 0; s < set.slices.size(); ++s)
    out.push_back(prepare_slice(set.slices[s], s, material_ids, box));
  return out;
}

Ring2 clip_ring_to_convex(const Ring2& ring, const std::vector<Eigen::Vector3d>& half_planes) {
  Ring2 current = ring;
  Ring2 next;
  for (const Eigen::Vector3d& h : half_planes) {
    if (current.empty()) break;
    next.clear();
    const std::size_t n = current.size();
    for (std::size_t i = 0; i < n; ++i) {
      const Vec2& a = current[i];
      const Vec2& b = current[(i + 1) % n];
      const double va = h.x() * a.x() + h.y() * a.y() + h.z();
      const double vb = h.x() * b.x() + h.y() * b.y() + h.z();
      if (va >= 0.0) next.push_back(a);
      if ((va >= 0.0) != (vb >= 0.0)) {
        const double t = va / (va - vb);
        next.push_back(a + t * (b - a));
      }
    }
    std::swap(current, next);
  }
  if (current.size() < 3) current.clear();
  return current;
}

namespace {

bool in_triangle(const Vec2 (&c)[3], const Vec2& p) {
  for (int k = 0; k < 3; ++k) {
    const Vec2& a = c[k];
    const Vec2& b = c[(k + 1) % 3];
    if ((b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x()) < 0.0) return false;
  }
  return true;
}

void barycentric(const Vec2 (&c)[3], const Vec2& p, double (&out)[3]) {
  const double area = (c[1] - c[0]).x() * (c[2] - c[0]).y() - (c[1] - c[0]).y() * (c[2] - c[0]).x();
  for (int k = 0; k < 3; ++k) {
    const Vec2& a = c[(k + 1) % 3];
    const Vec2& b = c[(k + 2) % 3];
    out[k] = ((b - a).x() * (p - a).y() - (b - a).y() * (p - a).x()) / area;
  }
}

// The index of the face's vertex of smallest coordinates, where its image starts, as cells on
// demand store their faces: the order of the edges decides where the clipped rings start, and
// so their far-field trees, whose approximations differed by 1e-7 between the whole arrangement
// and cells on demand otherwise.
std::size_t first_vertex(const Arrangement& arrangement, const ArrangementFace& face) {
  std::size_t start = 0;
  for (std::size_t k = 1; k < face.vertices.size(); ++k) {
    const Vec3& p = arrangement.vertex(face.vertices[k]);
    const Vec3& q = arrangement.vertex(face.vertices[start]);
    if (std::lexicographical_compare(p.data(), p.data() + 3, q.data(), q.data() + 3)) start = k;
  }
  return start;
}

// The face's vertices in its plane's (u, v) coordinates, from vertex `start`.
Ring2 face_polygon(const Arrangement& arrangement, const ArrangementFace& face, std::size_t start,
                   const PlaneFrame& frame) {
  const std::size_t n = face.vertices.size();
  Ring2 polygon;
  polygon.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 d = arrangement.vertex(face.vertices[(start + i) % n]) - frame.origin;
    polygon.emplace_back(d.dot(frame.u), d.dot(frame.v));
  }
  return polygon;
}

// The face as half-planes a*x + b*y + c >= 0 in the slice's (u, v) coordinates, one per distinct
// edge plane. The side is decided by CGAL's exact predicate on a face vertex off the edge plane,
// so thin faces never get a flipped half-plane.
std::vector<Eigen::Vector3d> face_half_planes(const Arrangement& arrangement,
                                              const ArrangementFace& face, std::size_t start,
                                              const PlaneFrame& frame) {
  const std::size_t n = face.vertices.size();
  std::vector<Eigen::Vector3d> half_planes;
  std::vector<int> seen;
  for (std::size_t i = 0; i < n; ++i) {
    const int edge_plane_id = face.edge_planes[(start + i) % n];
    if (std::find(seen.begin(), seen.end(), edge_plane_id) != seen.end()) continue;
    seen.push_back(edge_plane_id);
    // Ask the exact predicate about the vertex farthest from the edge plane: its interval
    // filter decides at once, where vertices on the plane would need exact arithmetic.
    const ArrangementPlane& e = arrangement.plane(edge_plane_id);
    std::size_t farthest = 0;
    double farthest_distance = -1.0;
    for (std::size_t k = 0; k < n; ++k) {
      const double distance =
          std::abs(e.normal.dot(arrangement.vertex(face.vertices[k])) + e.offset);
      if (distance > farthest_distance) {
        farthest_distance = distance;
        farthest = k;
      }
    }
    int side = arrangement.side(edge_plane_id, face.vertices[farthest]);
    for (std::size_t k = 0; k < n && side == 0; ++k)
      side = arrangement.side(edge_plane_id, face.vertices[k]);
    if (side == 0) continue;  // cannot happen for a face of positive area
    Eigen::Vector3d h(e.normal.dot(frame.u), e.normal.dot(frame.v),
                      e.normal.dot(frame.origin) + e.offset);
    half_planes.push_back(side * h);
  }
  return half_planes;
}

// Clips a slice's rings to one face (its polygon and half-planes) and appends the parts' points
// to `points`.
class FaceClipper {
 public:
  FaceClipper(const Ring2& polygon, std::vector<Eigen::Vector3d> half_planes,
              std::vector<Vec2>& points)
      : polygon_(polygon), half_planes_(std::move(half_planes)), points_(points) {
    lo_ = hi_ = polygon[0];
    for (const Vec2& p : polygon) {
      lo_ = lo_.cwiseMin(p);
      hi_ = hi_.cwiseMax(p);
    }
    margin_ = 1e-9 * (hi_ - lo_).norm();
    centre_ = Vec2::Zero();
    for (const Vec2& q : polygon) centre_ += q;
    centre_ /= static_cast<double>(polygon.size());
  }

  // Whether the box [lo, hi] meets the face's box (with its margin).
  bool box_meets(const Vec2& lo, const Vec2& hi) const {
    return !((lo.array() > hi_.array() + margin_).any() ||
             (hi.array() < lo_.array() - margin_).any());
  }

  // The part of one ring inside the face. Most faces lie wholly inside or outside a ring: when
  // no ring edge comes near the face's box, the part is the face itself (in the ring's
  // orientation) or nothing, which spares clipping the whole ring (most of the face-image time
  // at 100 slices). `bands` (null: none) limits both tests to the edges of the bands the face's
  // box meets.
  void add_part(const Ring2& ring, const RingBands* bands, int material,
                std::vector<FaceImage::Part>& parts) const {
    if (!edge_near(ring, bands)) {
      const int winding = bands != nullptr ? winding_number_in_bands(ring, *bands, centre_)
                                           : winding_number(ring.data(), ring.size(), centre_);
      if (winding == 0) return;
      parts.push_back({material, static_cast<std::uint32_t>(points_.size()),
                       static_cast<std::uint32_t>(polygon_.size()), 0, 0, winding < 0 ? -1 : 1});
      if (winding < 0)
        points_.insert(points_.end(), polygon_.rbegin(), polygon_.rend());  // a hole
      else
        points_.insert(points_.end(), polygon_.begin(), polygon_.end());
      return;
    }
    const Ring2 clipped = clip_ring_to_convex(ring, half_planes_);
    if (clipped.empty()) return;
    parts.push_back({material, static_cast<std::uint32_t>(points_.size()),
                     static_cast<std::uint32_t>(clipped.size())});
    points_.insert(points_.end(), clipped.begin(), clipped.end());
  }

 private:
  // Whether an edge of `ring` comes near the face's box.
  bool edge_near(const Ring2& ring, const RingBands* bands) const {
    const auto near = [&](std::size_t i) {
      const Vec2& a = ring[i];
      const Vec2& b = ring[i + 1 < ring.size() ? i + 1 : 0];
      return std::max(a.x(), b.x()) >= lo_.x() - margin_ &&
             std::min(a.x(), b.x()) <= hi_.x() + margin_ &&
             std::max(a.y(), b.y()) >= lo_.y() - margin_ &&
             std::min(a.y(), b.y()) <= hi_.y() + margin_;
    };
    if (bands != nullptr) {
      const std::uint32_t first = bands->offsets[bands->band(lo_.y() - margin_)];
      const std::uint32_t last = bands->offsets[bands->band(hi_.y() + margin_) + 1];
      for (std::uint32_t k = first; k < last; ++k)
        if (near(bands->edges[k])) return true;
      return false;
    }
    for (std::size_t i = 0; i < ring.size(); ++i)
      if (near(i)) return true;
    return false;
  }

  const Ring2& polygon_;
  std::vector<Eigen::Vector3d> half_planes_;
  std::vector<Vec2>& points_;
  Vec2 lo_, hi_, centre_;
  double margin_ = 0.0;
};

}  // namespace

CellField::CellField(const Arrangement& arrangement, int material_count)
    : arrangement_(arrangement), material_count_(material_count) {
  on_face_height_ = 1e-12 * arrangement.box().diagonal();
}

CellField::CellField(const Arrangement& arrangement, const std::vector<PreparedSlice>& slices,
                     int material_count)
    : CellField(arrangement, material_count) {
  slices_ = slices;
  refresh({});  // every face is new
}

void CellField::add_slice(PreparedSlice slice) { slices_.push_back(std::move(slice)); }

void CellField::update_frames() {
  for (std::size_t p = frames_.size(); p < arrangement_.plane_count(); ++p) {
    const ArrangementPlane& plane = arrangement_.plane(static_cast<int>(p));
    PlaneFrame frame;
    if (plane.slice >= 0) {
      const PreparedSlice& s = slices_.at(static_cast<std::size_t>(plane.slice));
      frame = {s.origin, s.u, s.v, s.unit_normal};
    } else {
      // Box faces: plane 2k has normal +e_k, 2k+1 has -e_k; (u, v) turn about the normal.
      const int axis = static_cast<int>(p) / 2;
      const bool upper = p % 2 == 1;
      Vec3 e1 = Vec3::Unit((axis + 1) % 3), e2 = Vec3::Unit((axis + 2) % 3);
      if (upper) std::swap(e1, e2);
      frame.origin = upper ? arrangement_.box().max : arrangement_.box().min;
      frame.u = e1;
      frame.v = e2;
      frame.unit_normal = e1.cross(e2);
    }
    frames_.push_back(frame);
  }
}

std::vector<int> CellField::refresh(const std::vector<int>& split_faces) {
  // Unique across fields: a field made where an old one was never repeats its version.
  static std::atomic<std::uint64_t> versions{0};
  version_ = ++versions;
  update_frames();
  const std::size_t old_face_count = images_.size();
  grow(images_, arrangement_.face_count());  // on demand, every octree batch adds faces
  std::vector<char> rebuilt(images_.size(), 0);
  for (std::size_t f = old_face_count; f < images_.size(); ++f) rebuilt[f] = 1;
  for (const int f : split_faces) rebuilt[static_cast<std::size_t>(f)] = 1;
  grow(image_generations_, images_.size(), std::uint64_t{0});
  std::vector<int> to_build;
  for (std::size_t f = 0; f < images_.size(); ++f)
    if (rebuilt[f]) to_build.push_back(static_cast<int>(f));
  build_images(to_build);
  for (const int f : to_build)
    image_generations_[static_cast<std::size_t>(f)] = ++last_image_generation_;

  std::vector<int> completion_changed;
  bool any_unknown = false;
  for (const PreparedSlice& s : slices_) any_unknown |= !s.unknown.empty();
  // A slice's completion reads the faces with unknown parts and the known faces of their cells
  // and of those cells' neighbours across such faces: cells that all have a face with an
  // unknown part. On demand, every octree batch adds faces; when none of them is on such a cell
  // (nor was an image split or released), no completion can change and the bookkeeping below,
  // over all the faces, is skipped.
  bool completion_inputs_changed = images_released_ || !split_faces.empty();
  images_released_ = false;
  if (any_unknown && !completion_inputs_changed) {
    const auto touches_unknown = [&](int cell) {
      if (cell < 0) return false;
      for (const int g : arrangement_.cell(cell).faces)
        if (!images_[static_cast<std::size_t>(g)].unknown_parts.empty()) return true;
      return false;
    };
    completion_inputs_changed = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(old_face_count, images_.size(), 1024), false,
        [&](const tbb::blocked_range<std::size_t>& r, bool any) {
          for (std::size_t f = r.begin(); f < r.end() && !any; ++f) {
            const ArrangementFace& face = arrangement_.face(static_cast<int>(f));
            any = touches_unknown(face.cell_positive) || touches_unknown(face.cell_negative);
          }
          return any;
        },
        std::logical_or<>());
    if (!completion_inputs_changed) {
      face_completion_hashes_.resize(images_.size(), 0);
      completion_seconds_ = 0.0;
      recompleted_slices_ = 0;
    }
  }
  if (any_unknown && completion_inputs_changed) {
    // Slices whose inputs changed are completed again (build_unknown_images); the cells on both
    // sides of a face whose completed triangles changed must be evaluated again (an unchanged
    // face of a split cell counts too: its other cell is not in the arrangement's zone).
    std::vector<std::uint64_t> old_hashes = std::move(face_completion_hashes_);
    old_hashes.resize(images_.size(), 0);
    triangles_.clear();
    corner_values_.clear();
    for (FaceImage& image : images_) {
      image.triangle_begin = image.triangle_count = 0;
      image.triangle_tree = nullptr;
      image.triangle_tree_moments = nullptr;
    }
    build_unknown_images();
    for (std::size_t f = 0; f < old_face_count; ++f) {
      if (old_hashes[f] == face_completion_hashes_[f]) continue;
      const ArrangementFace& face = arrangement_.face(static_cast<int>(f));
      if (face.cell_positive >= 0) completion_changed.push_back(face.cell_positive);
      if (face.cell_negative >= 0) completion_changed.push_back(face.cell_negative);
    }
    std::sort(completion_changed.begin(), completion_changed.end());
    completion_changed.erase(std::unique(completion_changed.begin(), completion_changed.end()),
                             completion_changed.end());
  }
  compact_points();
  return completion_changed;
}

void CellField::release_images(const std::vector<int>& faces) {
  images_released_ |= !faces.empty();
  for (const int f : faces)
    if (static_cast<std::size_t>(f) < images_.size())
      images_[static_cast<std::size_t>(f)] = FaceImage{};
}

void CellField::compact_points() {
  // Counting the live points reads every image: on demand, with hundreds of thousands of faces
  // and two refreshes per online update, that was a tenth of an update (perf). They are counted
  // again once the points grew by a quarter since the last count.
  if (points_.size() < next_compaction_check_) return;
  next_compaction_check_ = points_.size() + points_.size() / 4 + 4096;
  const std::size_t live = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, images_.size(), 4096), std::size_t{0},
      [&](const tbb::blocked_range<std::size_t>& r, std::size_t sum) {
        for (std::size_t f = r.begin(); f < r.end(); ++f) {
          const FaceImage& image = images_[f];
          sum += image.polygon_count;
          for (const FaceImage::Part& part : image.parts) sum += part.count;
          for (const FaceImage::Part& part : image.unknown_parts) sum += part.count;
          for (const FaceImage::Part& part : image.known_parts) sum += part.count;
        }
        return sum;
      },
      std::plus<>());
  // Rebuilt images leave their old points and trees behind; copy the live ones once they are
  // the minority.
  if (points_.size() < 2 * live + 4096) return;
  std::vector<Vec2> compacted;
  compacted.reserve(live);
  std::vector<ChainNode> compacted_trees;
  auto move_range = [&](std::uint32_t& begin, std::uint32_t count) {
    const std::uint32_t new_begin = static_cast<std::uint32_t>(compacted.size());
    compacted.insert(compacted.end(), points_.begin() + begin, points_.begin() + begin + count);
    begin = new_begin;
  };
  auto move_part = [&](FaceImage::Part& part) {
    move_range(part.begin, part.count);
    if (part.tree_count == 0) return;
    const std::int64_t shift = static_cast<std::int64_t>(compacted_trees.size()) - part.tree_root;
    for (std::uint32_t n = part.tree_root; n < part.tree_root + part.tree_count; ++n) {
      ChainNode node = tree_nodes_[n];
      if (node.left >= 0) node.left = static_cast<std::int32_t>(node.left + shift);
      if (node.right >= 0) node.right = static_cast<std::int32_t>(node.right + shift);
      compacted_trees.push_back(node);
    }
    part.tree_root = static_cast<std::uint32_t>(part.tree_root + shift);
  };
  for (FaceImage& image : images_) {
    move_range(image.polygon_begin, image.polygon_count);
    for (FaceImage::Part& part : image.parts) move_part(part);
    for (FaceImage::Part& part : image.unknown_parts) move_part(part);
    for (FaceImage::Part& part : image.known_parts) move_part(part);
  }
  points_ = std::move(compacted);
  ++compactions_;
  tree_nodes_ = std::move(compacted_trees);
  next_compaction_check_ = points_.size() + points_.size() / 4 + 4096;
}

void CellField::build_images(const std::vector<int>& faces) {
  // Fixed chunks of faces, each built into its own buffers on any thread, then appended in
  // order: points_ and tree_nodes_ are those of building one face after the other, whatever
  // the number of threads.
  constexpr std::size_t kChunk = 64;
  const std::size_t chunks = (faces.size() + kChunk - 1) / kChunk;
  struct Buffers {
    std::vector<Vec2> points;
    std::vector<ChainNode> trees;
  };
  std::vector<Buffers> buffers(chunks);
  auto chunk_faces = [&](std::size_t c) {
    return std::span<const int>(faces).subspan(c * kChunk,
                                               std::min(kChunk, faces.size() - c * kChunk));
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks, 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t c = r.begin(); c < r.end(); ++c)
                        for (const int f : chunk_faces(c)) {
                          images_[static_cast<std::size_t>(f)] = FaceImage{};
                          build_face_image(f, buffers[c].points, buffers[c].trees);
                        }
                    });
  // Appended in parallel too: each chunk's place follows from the sizes of those before it.
  std::vector<std::size_t> point_bases(chunks + 1, points_.size());
  std::vector<std::size_t> tree_bases(chunks + 1, tree_nodes_.size());
  for (std::size_t c = 0; c < chunks; ++c) {
    point_bases[c + 1] = point_bases[c] + buffers[c].points.size();
    tree_bases[c + 1] = tree_bases[c] + buffers[c].trees.size();
  }
  grow(points_, point_bases[chunks]);
  grow(tree_nodes_, tree_bases[chunks]);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks, 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t c = r.begin(); c < r.end(); ++c) {
                        const auto point_base = static_cast<std::uint32_t>(point_bases[c]);
                        const auto tree_base = static_cast<std::int32_t>(tree_bases[c]);
                        std::copy(buffers[c].points.begin(), buffers[c].points.end(),
                                  points_.begin() + static_cast<std::ptrdiff_t>(point_base));
                        auto tree = tree_nodes_.begin() + tree_base;
                        for (ChainNode node : buffers[c].trees) {
                          if (node.left >= 0) node.left += tree_base;
                          if (node.right >= 0) node.right += tree_base;
                          *tree++ = node;
                        }
                        buffers[c] = Buffers{};
                        auto shift = [&](FaceImage::Part& part) {
                          part.begin += point_base;
                          if (part.tree_count != 0)
                            part.tree_root += static_cast<std::uint32_t>(tree_base);
                        };
                        for (const int f : chunk_faces(c)) {
                          FaceImage& image = images_[static_cast<std::size_t>(f)];
                          image.polygon_begin += point_base;
                          for (FaceImage::Part& part : image.parts) shift(part);
                          for (FaceImage::Part& part : image.unknown_parts) shift(part);
                          for (FaceImage::Part& part : image.known_parts) shift(part);
                        }
                      }
                    });
}

void CellField::add_tree(FaceImage::Part& part, const std::vector<Vec2>& points,
                         std::vector<ChainNode>& trees) {
  if (part.count < kChainTreeMinEdges) return;
  const std::size_t before = trees.size();
  part.tree_root = build_chain_tree(points.data() + part.begin, part.count, trees);
  part.tree_count = static_cast<std::uint32_t>(trees.size() - before);
}

void CellField::build_face_image(int face_id, std::vector<Vec2>& points,
                                 std::vector<ChainNode>& trees) {
  const ArrangementFace& face = arrangement_.face(face_id);
  const ArrangementPlane& plane = arrangement_.plane(face.plane);
  FaceImage& image = images_[static_cast<std::size_t>(face_id)];
  image.frame = face.plane;
  const PlaneFrame& frame = frames_[static_cast<std::size_t>(face.plane)];
  const std::size_t start = first_vertex(arrangement_, face);
  const Ring2 polygon = face_polygon(arrangement_, face, start, frame);
  image.polygon_begin = static_cast<std::uint32_t>(points.size());
  image.polygon_count = static_cast<std::uint32_t>(polygon.size());
  points.insert(points.end(), polygon.begin(), polygon.end());
  if (plane.slice < 0) return;  // box faces are outside

  const FaceClipper clipper(polygon, face_half_planes(arrangement_, face, start, frame), points);
  const PreparedSlice& slice = slices_[static_cast<std::size_t>(plane.slice)];
  for (std::size_t m = 1; m < slice.rings_by_material.size(); ++m) {
    for (std::size_t r = 0; r < slice.rings_by_material[m].size(); ++r) {
      if (!clipper.box_meets(slice.ring_bounds[m][r].first, slice.ring_bounds[m][r].second))
        continue;
      const bool banded = m < slice.ring_bands.size() && r < slice.ring_bands[m].size();
      clipper.add_part(slice.rings_by_material[m][r], banded ? &slice.ring_bands[m][r] : nullptr,
                       static_cast<int>(m), image.parts);
    }
  }
  // The unknown set as clipped rings too: the completion needs only its integral (a few edges)
  // where the triangles would cost many.
  for (const UnknownComponent& component : slice.unknown)
    for (const Ring2& ring : component.rings)
      clipper.add_part(ring, nullptr, 0, image.unknown_parts);
  // And the known set: the completion reads the known part of faces crossed by the unknown
  // boundary, which as the face minus its unknown part would cost both their edges (the edges
  // along the face's boundary cancel).
  if (!slice.unknown.empty()) {
    image.known_clipped = true;
    for (const Ring2& ring : slice.known) clipper.add_part(ring, nullptr, 0, image.known_parts);
  }
  for (FaceImage::Part& part : image.parts) add_tree(part, points, trees);
  for (FaceImage::Part& part : image.unknown_parts) add_tree(part, points, trees);
  for (FaceImage::Part& part : image.known_parts) add_tree(part, points, trees);
  double unknown_area = 0.0;
  for (const FaceImage::Part& part : image.unknown_parts)
    unknown_area +=
        signed_area(Ring2(points.begin() + part.begin, points.begin() + part.begin + part.count));
  image.fully_unknown = unknown_area >= (1.0 - 1e-9) * std::abs(signed_area(polygon));
}

bool CellField::outside_box(const Vec3& p, double* out) const {
  const Box3& box = arrangement_.box();
  if ((p.array() > box.min.array()).all() && (p.array() < box.max.array()).all()) return false;
  out[0] = 1.0;
  for (int l = 1; l < function_count(); ++l) out[l] = -1.0;
  return true;
}

int CellField::evaluate(const Vec3& p, double* out) const {
  if (outside_box(p, out)) return -1;
  // Evaluations come in runs of nearby points: the last cell this thread found is the first guess.
  thread_local int last_cell = -1;
  last_cell = arrangement_.locate(p, last_cell);
  return evaluate_in(last_cell, p, out);
}

int CellField::evaluate_in(int cell, const Vec3& p, double* out) const {
  if (outside_box(p, out)) return -1;
  const int n = function_count();
  // w[l] accumulates the mean-value weight of label l: its known parts of the faces plus its
  // share of the completed unknown triangles; w[0] only the completed share of the outside.
  constexpr int kMaxStack = 16;
  double stack_weights[2 * kMaxStack];
  std::vector<double> heap_weights;
  double* w = stack_weights;
  if (n > kMaxStack) {
    heap_weights.resize(2 * static_cast<std::size_t>(n));
    w = heap_weights.data();
  }
  double* face_w = w + n;  // one face's triangle sums
  std::fill(w, w + n, 0.0);
  double total = 0.0, known_materials = 0.0, unknown_total = 0.0;
  for (const int f : arrangement_.cell(cell).faces) {
    const FaceImage& image = images_[static_cast<std::size_t>(f)];
    const PlaneFrame& frame = frames_[static_cast<std::size_t>(image.frame)];
    const Vec3 d = p - frame.origin;
    const double height = std::abs(d.dot(frame.unit_normal));
    const Vec2 foot(d.dot(frame.u), d.dot(frame.v));
    if (height <= on_face_height_) {
      value_on_face(image, foot, out);
      return cell;
    }
    const double inv_height = 1.0 / height;
    total += projected_angle_plain(points_.data() + image.polygon_begin, image.polygon_count, foot,
                                   height) *
             inv_height;  // see part_angle
    for (const FaceImage::Part& part : image.parts) {
      const double weight = part_angle(part, foot, height) * inv_height;
      w[part.material] += weight;
      known_materials += weight;
    }
    unknown_total += add_unknown_shares(image, foot, height, face_w, w);
  }
  for (int l = 1; l < n; ++l) out[l] = 2.0 * w[l] / total - 1.0;
  out[0] = 2.0 * (total - known_materials - unknown_total + w[0]) / total - 1.0;
  for (int l = 0; l < n; ++l)
    if (!std::isfinite(out[l]))
      throw GeometryError("field: non-finite value in cell " + std::to_string(cell) +
                          " (a degenerate face or triangle); please report the input");
  return cell;
}

void CellField::value_on_face(const FaceImage& image, const Vec2& foot, double* out) const {
  // On the face itself the field is the face's own data: the completed values inside an unknown
  // triangle, else the slice's label. The slice's whole rings decide, not the face's clipped
  // parts: a foot on the line between two faces then gets the same label from both, whatever
  // the rounding of the clip.
  const int n = function_count();
  for (std::uint32_t t = image.triangle_begin; t < image.triangle_begin + image.triangle_count;
       ++t) {
    const UnknownTriangle& tri = triangles_[t];
    if (!in_triangle(tri.corners, foot)) continue;
    double bary[3];
    barycentric(tri.corners, foot, bary);
    for (int l = 0; l < n; ++l)
      out[l] = bary[0] * corner_value(t, 0, l) + bary[1] * corner_value(t, 1, l) +
               bary[2] * corner_value(t, 2, l);
    return;
  }
  int label = 0;
  const int slice = arrangement_.plane(image.frame).slice;
  if (slice >= 0) {
    const PreparedSlice& s = slices_[static_cast<std::size_t>(slice)];
    for (std::size_t m = 1; m < s.rings_by_material.size(); ++m) {
      int winding = 0;
      for (const Ring2& ring : s.rings_by_material[m])
        winding += winding_number(ring.data(), ring.size(), foot);
      if (winding > 0) label = static_cast<int>(m);
    }
  }
  for (int l = 0; l < n; ++l) out[l] = l == label ? 1.0 : -1.0;
}

double CellField::add_unknown_shares(const FaceImage& image, const Vec2& foot, double height,
                                     double* face_w, double* w) const {
  if (image.triangle_count == 0) return 0.0;
  const int n = function_count();
  const UnknownTriangle* triangles = triangles_.data() + image.triangle_begin;
  const double* values =
      corner_values_.data() + image.triangle_begin * 3 * static_cast<std::size_t>(n);
  std::fill(face_w, face_w + n, 0.0);
  if (image.triangle_tree != nullptr) {
    add_triangle_weights_tree(triangles, values, n, image.triangle_tree,
                              image.triangle_tree_moments, 0, foot, height, face_w);
  } else {
    add_triangle_weights(triangles, values, image.triangle_count, n, foot, height, face_w);
  }
  // The shares' own total (the completed values are a partition of unity, so it equals the
  // triangles' weight to rounding), the same way whether the tree summed them or not.
  double face_unknown = 0.0;
  for (int l = 0; l < n; ++l) face_unknown += face_w[l];
  if (!(face_unknown > 0.0)) return 0.0;
  // The unknown part's weight comes from its boundary, exactly like the face's total; the
  // triangles only split it among the functions. The far-field error of the tree then enters
  // through these shares alone, and a completion that is one label everywhere stays exactly that
  // label.
  const double inv_height = 1.0 / height;
  double exact_unknown = 0.0;
  for (const FaceImage::Part& part : image.unknown_parts)
    exact_unknown += part_angle(part, foot, height) * inv_height;
  const double scale = exact_unknown / face_unknown;
  for (int l = 0; l < n; ++l) w[l] += scale * face_w[l];
  return exact_unknown;
}

}  // namespace sonoshape::recon
