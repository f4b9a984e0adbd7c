// Completion of unknown regions (Bermano et al. 2011, Section 5): triangulation of the unknown
// part of every face, cell groups, and the values at the triangle corners.
#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>
#include <map>
#include <numeric>
#include <set>
#include <span>
#include <unordered_map>
#include <unordered_set>

#include "cell_field.hpp"
#include "mean_value.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::recon {
namespace {

// The triangulation's kernel: exact predicates on double coordinates.
using CdtKernel = CGAL::Exact_predicates_inexact_constructions_kernel;
// Each point knows its slots in the completion's corner cache (-1: none yet), so that the
// corners of new triangles find their parts without hashing their coordinates.
struct VertexInfo {
  std::int64_t slot_3d = -1;
  int component = -1;  // of slot_2d (a point where two unknown components touch has two)
  std::int64_t slot_2d = -1;
};
using Vb = CGAL::Triangulation_vertex_base_with_info_2<VertexInfo, CdtKernel>;
// Each triangle knows its entry among the completed triangles (-1: not completed yet).
struct FaceInfo {
  int entry = -1;
};
using Fb = CGAL::Constrained_triangulation_face_base_2<
    CdtKernel, CGAL::Triangulation_face_base_with_info_2<FaceInfo, CdtKernel>>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Exact_predicates_tag: constraints that cross (unknown boundaries and face edges) are split at
// their intersection points.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<CdtKernel, Tds, CGAL::Exact_predicates_tag>;

// Spacing of the first triangulation of the unknown set: the completed values live at the
// corners and are interpolated linearly, so corners must spread across the region, not only
// along its boundary: an eighth of the side of the slice's unknown area, between these fractions
// of the box diagonal. Where the completed labels change the triangles are refined further.
constexpr double kUnknownTriangleFraction = 0.125;
constexpr double kUnknownTriangleMin = 0.03, kUnknownTriangleMax = 0.12;
// Lattice points closer than this many triangle sizes to the unknown boundary are left out.
constexpr double kLatticeClearance = 0.5;
// Triangles whose corners complete to different labels are split (at the midpoint of their
// longest edge) down to this longest edge (fraction of the box diagonal: about 2 of the octree's
// finest cells, which are at most 1/128 of it), in at most this many rounds.
constexpr double kRefinedTriangleMin = 0.015;
constexpr int kMaxRefinementRounds = 8;

// The completion reads the known faces of the cells within this many group-adjacency steps of the
// faces around a corner. With fields of view every slice has unknown parts and groups grow to the
// whole arrangement; the nearby faces carry the weight (it falls off with distance), and the bound
// keeps completion linear in the number of triangles.
constexpr int kGroupHops = 1;

// A corner within this distance of an unknown-boundary edge, relative to the edge's length, is on
// the boundary (constraint intersections and splits land there only to rounding).
constexpr double kOnBoundaryTolerance = 1e-9;

int find_root(std::vector<int>& parent, int x) {
  while (parent[static_cast<std::size_t>(x)] != x) {
    parent[static_cast<std::size_t>(x)] =
        parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(x)])];
    x = parent[static_cast<std::size_t>(x)];
  }
  return x;
}

// Order-independent hash of one face's completed triangles and their corner values: equal
// completions give equal hashes whatever the order of the triangles and of their corners.
std::uint64_t completion_hash(const std::vector<UnknownTriangle>& triangles,
                              const std::vector<double>& values, std::size_t function_count) {
  auto mix = [](std::uint64_t h, double x) {
    std::uint64_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    h ^= bits + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2);
    return h;
  };
  std::uint64_t sum = 0;
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    const UnknownTriangle& triangle = triangles[t];
    // Start at the lowest corner so that the hash does not depend on the corner rotation.
    int first = 0;
    for (int k = 1; k < 3; ++k)
      if (std::make_pair(triangle.corners[k].x(), triangle.corners[k].y()) <
          std::make_pair(triangle.corners[first].x(), triangle.corners[first].y()))
        first = k;
    std::uint64_t h = 1469598103934665603ULL;
    for (int n = 0; n < 3; ++n) {
      const std::size_t k = static_cast<std::size_t>((first + n) % 3);
      h = mix(mix(h, triangle.corners[k].x()), triangle.corners[k].y());
      for (std::size_t l = 0; l < function_count; ++l)
        h = mix(h, values[(t * 3 + k) * function_count + l]);
    }
    sum += h;
  }
  return sum + triangles.size();
}

// Hash of a few doubles (exact values: the caches below key points by their coordinates).
struct DoublesHash {
  template <std::size_t N>
  std::size_t operator()(const std::array<double, N>& values) const {
    std::uint64_t h = 0x9e3779b97f4a7c15ull;
    for (const double value : values) {
      std::uint64_t bits;
      const double normalised = value + 0.0;  // -0 and +0 compare equal
      std::memcpy(&bits, &normalised, sizeof bits);
      h ^= bits + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
    }
    // splitmix64 finaliser
    h = (h ^ (h >> 30)) * 0xbf58476d1ce4e5b9ull;
    h = (h ^ (h >> 27)) * 0x94d049bb133111ebull;
    return static_cast<std::size_t>(h ^ (h >> 31));
  }
};

// Per-thread marks over the faces, to drop repeats from lists of faces as they are collected
// (instead of sorting lists full of repeats). Each thread keeps its marks for the process rather
// than allocating a mark per face for every completion. Task bodies that use them must not wait
// on nested parallel work (the thread could start another body meanwhile).
class FaceMarks {
 public:
  // Starts a new list over `face_count` faces.
  static FaceMarks& start(std::size_t face_count) {
    thread_local FaceMarks marks;
    if (marks.mark_.size() < face_count) marks.mark_.resize(face_count, 0);
    if (++marks.current_ == 0) {  // wrapped: clear the old marks
      std::fill(marks.mark_.begin(), marks.mark_.end(), 0);
      marks.current_ = 1;
    }
    return marks;
  }
  // True the first time `face` is seen in this list.
  bool insert(int face) {
    std::uint32_t& mark = mark_[static_cast<std::size_t>(face)];
    if (mark == current_) return false;
    mark = current_;
    return true;
  }

 private:
  std::vector<std::uint32_t> mark_;
  std::uint32_t current_ = 0;
};

// Corners per chunk of the completion's 3D part (complete_round).
constexpr std::size_t kCornersPerChunk = 256;

// The faces a chunk of corners reads, in ascending order, each with the corners (positions in
// the chunk) that read it, once each, in the corners' order: a counting sort of (face, corner)
// pairs over per-thread dense arrays. Use: count every pair (a corner's pairs one after the
// other; a face a corner lists twice counts once), group(), add every pair in the same order,
// then read faces() and readers(i), and finish() (which clears the dense arrays for the next
// chunk). As with FaceMarks, task bodies that use it must not wait on nested parallel work.
class FaceReaders {
 public:
  static FaceReaders& start(std::size_t face_count) {
    thread_local FaceReaders readers;
    if (readers.position_.size() < face_count) readers.position_.resize(face_count, kUnseen);
    readers.faces_.clear();
    readers.counts_.clear();
    readers.last_counted_.clear();
    return readers;
  }
  void count(int face, std::uint32_t reader) {
    std::uint32_t& position = position_[static_cast<std::size_t>(face)];
    if (position == kUnseen) {
      position = static_cast<std::uint32_t>(faces_.size());
      faces_.push_back(face);
      counts_.push_back(0);
      last_counted_.push_back(kUnseen);
    }
    if (last_counted_[position] == reader) return;
    last_counted_[position] = reader;
    ++counts_[position];
  }
  void group() {
    // Faces in ascending order, each position pointing at its place in that order.
    std::sort(faces_.begin(), faces_.end());
    begins_.assign(faces_.size() + 1, 0);
    for (std::size_t i = 0; i < faces_.size(); ++i) {
      std::uint32_t& position = position_[static_cast<std::size_t>(faces_[i])];
      begins_[i + 1] = begins_[i] + counts_[position];
      position = static_cast<std::uint32_t>(i);
    }
    cursors_.assign(begins_.begin(), begins_.end() - 1);
    readers_.resize(begins_.back());
  }
  void add(int face, std::uint32_t reader) {
    const std::uint32_t position = position_[static_cast<std::size_t>(face)];
    std::uint32_t& cursor = cursors_[position];
    if (cursor > begins_[position] && readers_[cursor - 1] == reader) return;
    readers_[cursor++] = reader;
  }
  std::span<const int> faces() const { return faces_; }
  std::span<const std::uint32_t> readers(std::size_t i) const {
    return std::span<const std::uint32_t>(readers_).subspan(begins_[i],
                                                            begins_[i + 1] - begins_[i]);
  }
  void finish() {
    for (const int face : faces_) position_[static_cast<std::size_t>(face)] = kUnseen;
  }

 private:
  static constexpr std::uint32_t kUnseen = ~std::uint32_t{0};
  std::vector<std::uint32_t> position_;  // per face: kUnseen, or its index in faces_
  std::vector<int> faces_;
  std::vector<std::uint32_t> counts_, last_counted_, begins_, cursors_, readers_;
};

bool in_convex_ccw(const Vec2* polygon, std::size_t count, const Vec2& p) {
  for (std::size_t i = 0; i < count; ++i) {
    const Vec2& a = polygon[i];
    const Vec2& b = polygon[(i + 1) % count];
    if ((b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x()) < 0.0) return false;
  }
  return true;
}

// The 2D mean-value interpolant of an unknown component in its slice (formula 7 (b)) at p, from
// the known labels across its boundary, added to n2 (function_count numerators, then the
// denominator). With stop_on_boundary, false (and n2 partly written) when p is on the boundary,
// where the edge weights are singular.
bool add_part_2d(const UnknownComponent& component, std::size_t function_count, const Vec2& p,
                 bool stop_on_boundary, double* n2) {
  for (std::size_t r = 0; r < component.rings.size(); ++r) {
    const Ring2& ring = component.rings[r];
    for (std::size_t i = 0; i < ring.size(); ++i) {
      const Vec2& a = ring[i];
      const Vec2& b = ring[(i + 1) % ring.size()];
      if (stop_on_boundary) {
        // On the edge (to rounding).
        const Vec2 ab = b - a, ap = p - a;
        const double length_sq = ab.squaredNorm();
        const double cross = ab.x() * ap.y() - ab.y() * ap.x();
        const double along = ab.dot(ap);
        if (std::abs(cross) <= kOnBoundaryTolerance * length_sq &&
            along >= -kOnBoundaryTolerance * length_sq &&
            along <= (1.0 + kOnBoundaryTolerance) * length_sq)
          return false;
      }
      const double w = edge_weight_2d(a, b, p);
      n2[static_cast<std::size_t>(component.edge_labels[r][i])] += w;
      n2[function_count] += w;
    }
  }
  return true;
}

// Cell groups: cells joined through faces that hold unknown regions.
struct UnknownAdjacency {
  std::vector<std::vector<int>> unknown_neighbours;  // per cell: cells across its unknown faces
  std::vector<char> next_to_unknown;                 // per cell: 1 with a face with unknown parts
  std::size_t group_count = 0;
};

UnknownAdjacency link_unknown_cells(const Arrangement& arrangement,
                                    const std::vector<FaceImage>& images) {
  UnknownAdjacency out;
  std::vector<int> parent(arrangement.cell_count());
  std::iota(parent.begin(), parent.end(), 0);
  out.unknown_neighbours.resize(arrangement.cell_count());
  out.next_to_unknown.assign(arrangement.cell_count(), 0);
  for (std::size_t f = 0; f < images.size(); ++f) {
    if (images[f].unknown_parts.empty()) continue;
    const ArrangementFace& face = arrangement.face(static_cast<int>(f));
    for (const int c : {face.cell_positive, face.cell_negative})
      if (c >= 0) out.next_to_unknown[static_cast<std::size_t>(c)] = 1;
    if (face.cell_positive < 0 || face.cell_negative < 0) continue;
    parent[static_cast<std::size_t>(find_root(parent, face.cell_positive))] =
        find_root(parent, face.cell_negative);
    out.unknown_neighbours[static_cast<std::size_t>(face.cell_positive)].push_back(
        face.cell_negative);
    out.unknown_neighbours[static_cast<std::size_t>(face.cell_negative)].push_back(
        face.cell_positive);
  }
  std::unordered_set<int> roots;
  for (std::size_t f = 0; f < images.size(); ++f)
    if (!images[f].unknown_parts.empty())
      roots.insert(find_root(parent, arrangement.face(static_cast<int>(f)).cell_positive));
  out.group_count = roots.size();
  return out;
}

// The known faces of the cells within kGroupHops steps of each cell next to an unknown part
// (sorted; `known_plane`: each face's plane, -1 for faces without known data). A face's local
// faces are then those of its two cells, merged: walking from each cell rather than from each
// face walks about a fifth as often (a cell has about ten faces).
std::vector<std::vector<int>> known_faces_near_cells(const Arrangement& arrangement,
                                                     const UnknownAdjacency& adjacency,
                                                     const std::vector<int>& known_plane) {
  std::vector<std::vector<int>> cell_known_faces(arrangement.cell_count());
  tbb::parallel_for(std::size_t{0}, cell_known_faces.size(), [&](std::size_t start) {
    if (!adjacency.next_to_unknown[start]) return;
    std::vector<int> cells{
        static_cast<int>(start)};  // a few dozen: a linear search is the fastest set
    std::size_t frontier_begin = 0;
    for (int hop = 0; hop < kGroupHops; ++hop) {
      const std::size_t frontier_end = cells.size();
      for (std::size_t i = frontier_begin; i < frontier_end; ++i)
        for (const int n : adjacency.unknown_neighbours[static_cast<std::size_t>(cells[i])])
          if (std::find(cells.begin(), cells.end(), n) == cells.end()) cells.push_back(n);
      frontier_begin = frontier_end;
    }
    std::vector<int>& faces = cell_known_faces[start];
    FaceMarks& collected = FaceMarks::start(known_plane.size());
    for (const int c : cells)
      for (const int g : arrangement.cell(c).faces)
        if (collected.insert(g) && known_plane[static_cast<std::size_t>(g)] >= 0)
          faces.push_back(g);
    std::sort(faces.begin(), faces.end());
  });
  return cell_known_faces;
}

// The sorted union of the sorted lists `a` and `b`, less the faces of `plane`, into `out`.
void merge_known_faces(const std::vector<int>& a, const std::vector<int>& b,
                       const std::vector<int>& known_plane, int plane, std::vector<int>& out) {
  out.reserve(a.size() + b.size());
  std::size_t i = 0, j = 0;
  while (i < a.size() || j < b.size()) {
    int g;
    if (j == b.size() || (i < a.size() && a[i] < b[j]))
      g = a[i++];
    else if (i == a.size() || b[j] < a[i])
      g = b[j++];
    else
      g = (++i, b[j++]);  // in both
    if (known_plane[static_cast<std::size_t>(g)] != plane) out.push_back(g);
  }
}

// The known faces around each face with unknown parts: those of the cells within kGroupHops
// group steps (a corner reads those of all the faces around it), sorted, less the faces of the
// face's own plane. In parallel: with fields of view every face has unknown parts, and this walk
// over the cells around each of them was a serial tenth of the completion.
std::vector<std::vector<int>> local_known_faces(const Arrangement& arrangement,
                                                const std::vector<FaceImage>& images,
                                                const UnknownAdjacency& adjacency) {
  // Each face's plane, or -1 for faces without known data (they add nothing to the 3D part): the
  // walk reads it for a hundred faces per face, from this compact array rather than from the
  // images' and the arrangement's large records.
  std::vector<int> known_plane(images.size());
  tbb::parallel_for(std::size_t{0}, images.size(), [&](std::size_t g) {
    known_plane[g] = images[g].fully_unknown ? -1 : arrangement.face(static_cast<int>(g)).plane;
  });
  const std::vector<std::vector<int>> cell_known_faces =
      known_faces_near_cells(arrangement, adjacency, known_plane);
  std::vector<std::vector<int>> local_faces(images.size());
  tbb::parallel_for(std::size_t{0}, images.size(), [&](std::size_t f) {
    if (images[f].unknown_parts.empty()) return;
    const ArrangementFace& face = arrangement.face(static_cast<int>(f));
    static const std::vector<int> kNone;
    const auto known_faces_of = [&](int c) -> const std::vector<int>& {
      return c >= 0 ? cell_known_faces[static_cast<std::size_t>(c)] : kNone;
    };
    // Sorted: the order of the corners' sums (the same for every thread), and corners on several
    // faces merge these lists.
    merge_known_faces(known_faces_of(face.cell_positive), known_faces_of(face.cell_negative),
                      known_plane, face.plane, local_faces[f]);
  });
  return local_faces;
}

// The faces with unknown parts of each slice.
std::vector<std::vector<int>> unknown_faces_by_slice(const Arrangement& arrangement,
                                                     const std::vector<FaceImage>& images,
                                                     std::size_t slice_count) {
  std::vector<std::vector<int>> slice_faces(slice_count);
  for (std::size_t f = 0; f < images.size(); ++f)
    if (!images[f].unknown_parts.empty())
      slice_faces[static_cast<std::size_t>(arrangement.plane(images[f].frame).slice)].push_back(
          static_cast<int>(f));
  return slice_faces;
}

}  // namespace

// The parts of formula 7 at the corners of one slice's triangles. A corner keeps its parts across
// the refinement rounds and between the triangles around it. Each round first lists the parts
// its new triangles need (serially: the points' slots decide which are new), then computes them
// in parallel.
struct CellField::CornerCache {
  // Slots: function_count + 1 doubles at slot * (function_count + 1) in `values`, the numerators
  // of every function, then the denominator. Formula 7 (a) has one slot per point of the slice,
  // read from the known faces around all the faces its triangles lie in; (b) one per point and
  // unknown component. The triangulation's points hold their slots (VertexInfo); on_boundary
  // marks corners on the unknown set's boundary, which take the limit from each triangle's side
  // instead (Section 5.1).
  using Key = std::array<double, 3>;
  explicit CornerCache(std::size_t function_count) : stride(function_count + 1) {}
  // The (b) slots of points that two unknown components share, by (component, x, y): their
  // points hold the first component's.
  std::unordered_map<Key, std::size_t, DoublesHash> part_2d;
  std::size_t stride;
  std::vector<double> values;
  std::vector<std::uint8_t> on_boundary;  // per slot
  // The parts listed this round: (component or -1, corner, slot).
  struct Job {
    int owner;
    Vec2 corner;
    std::size_t slot;
  };
  std::vector<Job> jobs_3d, jobs_2d;

  // A new slot for (owner, corner), listed as a job.
  std::size_t add(std::vector<Job>& jobs, int owner, const Vec2& corner) {
    const std::size_t next = on_boundary.size();
    on_boundary.push_back(0);
    jobs.push_back({owner, corner, next});
    return next;
  }
  // The slot of (owner, corner) in `parts`, listing a job when it is new.
  std::size_t slot(std::unordered_map<Key, std::size_t, DoublesHash>& parts, std::vector<Job>& jobs,
                   int owner, const Vec2& corner) {
    auto [it, inserted] =
        parts.try_emplace({static_cast<double>(owner), corner.x(), corner.y()}, on_boundary.size());
    if (inserted) add(jobs, owner, corner);
    return it->second;
  }
  double* at(std::size_t slot) { return values.data() + slot * stride; }
};

// The triangulation of one slice's unknown set and the completed values at its corners
// (CellField::triangulate_unknown), step by step: the working state of the steps is its members.
//
// Why not CGAL::Delaunay_mesher_2: its refinement is only guaranteed to end for input angles of
// 60 degrees and more, and with inexact constructions it crashed (Refine_edges_with_clusters) on
// the real PLUS sweep, whose segmented outlines have near-touching vertices and hairline spikes.
// The completion needs corners spread over the region, dense where the completed labels change,
// not well-shaped triangles: the boundary edges are split to triangle_size, a triangular lattice
// of that spacing fills the inside, and triangles whose corners complete to different labels
// are split at the midpoints of their longest edges (refine). Plain constrained Delaunay
// insertions with exact predicates always end.
class CellField::UnknownTriangulator {
 public:
  UnknownTriangulator(const CellField& field, int slice,
                      const std::vector<std::vector<int>>& local_faces)
      : field_(field),
        s_(field.slices_[static_cast<std::size_t>(slice)]),
        fc_(static_cast<std::size_t>(field.function_count())),
        diagonal_(field.arrangement_.box().diagonal()),
        local_faces_(local_faces),
        cache_(fc_) {}

  void run(const std::vector<int>& slice_faces, SliceCompletion& out) {
    if (!insert_boundary()) return;
    insert_lattice();
    insert_faces(slice_faces);
    index_faces();
    refine();
    write(out);
  }

 private:
  struct SliceFace {
    int id;
    Vec2 lo, hi;
  };
  // A triangle of the triangulation with its completed corners, refined where they disagree.
  struct Completed {
    Cdt::Vertex_handle vertices[3];  // the triangle's (a face that a flip reused has others)
    bool skipped = false;            // a sliver, or outside the unknown set or the faces
    UnknownTriangle triangle;
    int face_index = -1;                   // in `faces_`
    std::size_t slots_3d[3], slots_2d[3];  // its corners' parts in the cache
  };

  // Constraints are inserted through their end vertices, each new one located from the last
  // vertex (a ring's or a face's next edge starts where the last ended) rather than walked to
  // from an arbitrary face, as Cdt::insert_constraint(point, point) does; a point met again (most
  // are the ends of several edges) takes its vertex from a map, since locating a point that is a
  // vertex already runs into degenerate orientation tests that the exact predicates answer
  // slowly. The triangulation is the same: the points go in, in the same order.
  Cdt::Vertex_handle vertex(const Vec2& p, const Cdt::Vertex_handle& near) {
    auto [it, is_new] = vertex_at_.try_emplace({p.x(), p.y()});
    if (is_new)
      it->second = near == Cdt::Vertex_handle()
                       ? cdt_.insert(CdtKernel::Point_2(p.x(), p.y()))
                       : cdt_.insert(CdtKernel::Point_2(p.x(), p.y()), near->face());
    return it->second;
  }
  void insert_constraint(const Vec2& a, const Vec2& b) {
    const Cdt::Vertex_handle va = vertex(a, last_vertex_);
    const Cdt::Vertex_handle vb = vertex(b, va);
    cdt_.insert_constraint(va, vb);
    last_vertex_ = vb;
  }

  // The unknown set's boundary edges, split to the first triangle size; false when it has none.
  bool insert_boundary() {
    double unknown_area = 0.0;
    for (const UnknownComponent& component : s_.unknown)
      for (const Ring2& ring : component.rings) unknown_area += signed_area(ring);
    triangle_size_ = std::clamp(kUnknownTriangleFraction * std::sqrt(std::max(unknown_area, 0.0)),
                                kUnknownTriangleMin * diagonal_, kUnknownTriangleMax * diagonal_);
    lo_ = Vec2::Constant(std::numeric_limits<double>::infinity());
    hi_ = -lo_;
    for (const UnknownComponent& component : s_.unknown)
      for (const Ring2& ring : component.rings)
        for (std::size_t i = 0; i < ring.size(); ++i) {
          const Vec2& a = ring[i];
          const Vec2& b = ring[(i + 1) % ring.size()];
          lo_ = lo_.cwiseMin(a);
          hi_ = hi_.cwiseMax(a);
          if (a == b) continue;
          const int pieces =
              std::max(1, static_cast<int>(std::ceil((b - a).norm() / triangle_size_)));
          Vec2 previous = a;
          for (int k = 1; k <= pieces; ++k) {
            const Vec2 next =
                k == pieces ? b : Vec2(a + (b - a) * (static_cast<double>(k) / pieces));
            insert_constraint(previous, next);
            boundary_.emplace_back(previous, next);
            previous = next;
          }
        }
    return !boundary_.empty();
  }

  // The unknown component holding p (-1: none).
  int component_of(const Vec2& p) const {
    for (std::size_t c = 0; c < s_.unknown.size(); ++c) {
      int winding = 0;
      for (const Ring2& ring : s_.unknown[c].rings)
        winding += winding_number(ring.data(), ring.size(), p);
      if (winding > 0) return static_cast<int>(c);
    }
    return -1;
  }

  // Lattice points inside the unknown set, at least kLatticeClearance * triangle_size from its
  // boundary (closer ones would only make slivers along it). Boundary edges are bucketed by
  // lattice row so each point tests the few edges near it.
  void insert_lattice() {
    const double row_step = triangle_size_ * std::sqrt(3.0) / 2.0;
    const double clearance = kLatticeClearance * triangle_size_;
    const int rows = static_cast<int>(std::floor((hi_.y() - lo_.y()) / row_step)) + 1;
    std::vector<std::vector<std::size_t>> edges_near_row(static_cast<std::size_t>(rows));
    for (std::size_t e = 0; e < boundary_.size(); ++e) {
      const double y0 = std::min(boundary_[e].first.y(), boundary_[e].second.y()) - clearance;
      const double y1 = std::max(boundary_[e].first.y(), boundary_[e].second.y()) + clearance;
      const int r0 = std::max(0, static_cast<int>(std::ceil((y0 - lo_.y()) / row_step)));
      const int r1 = std::min(rows - 1, static_cast<int>(std::floor((y1 - lo_.y()) / row_step)));
      for (int r = r0; r <= r1; ++r) edges_near_row[static_cast<std::size_t>(r)].push_back(e);
    }
    const auto clear_of_boundary = [&](const Vec2& p, const std::vector<std::size_t>& edges) {
      for (const std::size_t e : edges) {
        const Vec2& a = boundary_[e].first;
        const Vec2 ab = boundary_[e].second - a;
        const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
        if ((a + t * ab - p).squaredNorm() < clearance * clearance) return false;
      }
      return true;
    };
    std::vector<CdtKernel::Point_2> lattice;
    for (int r = 0; r < rows; ++r) {
      const double y = lo_.y() + r * row_step;
      const double x_offset = (r % 2) * 0.5 * triangle_size_;
      for (double x = lo_.x() + x_offset; x <= hi_.x(); x += triangle_size_) {
        const Vec2 p(x, y);
        if (component_of(p) >= 0 &&
            clear_of_boundary(p, edges_near_row[static_cast<std::size_t>(r)]))
          lattice.emplace_back(x, y);
      }
    }
    cdt_.insert(lattice.begin(), lattice.end());
  }

  // The faces of this slice that reach the unknown set, as constraints too, so that every
  // triangle lies in one face. In an order of their own, not by id: the whole arrangement and
  // cells on demand number the same faces differently, and the insertions' order decides the
  // refinement (which triangles CGAL lists first). By each face's vertex mean, then from its
  // least vertex, both on a grid of 1e-9 of the box's diagonal: the two arrangements may round a
  // vertex differently in its last bits (its three planes in another order).
  void insert_faces(const std::vector<int>& slice_faces) {
    const std::vector<Vec2>& points = field_.points_;
    // Neighbouring faces share most edges: each is inserted once (a second insertion of the same
    // constraint changes nothing but costs its walk through the triangulation).
    std::unordered_set<std::array<double, 4>, DoublesHash> face_edges;
    for (const auto& [mean, f, first] : ordered_faces(slice_faces)) {
      const FaceImage& image = field_.images_[static_cast<std::size_t>(f)];
      SliceFace face{f, points[image.polygon_begin], points[image.polygon_begin]};
      for (std::uint32_t k = 0; k < image.polygon_count; ++k) {
        face.lo = face.lo.cwiseMin(points[image.polygon_begin + k]);
        face.hi = face.hi.cwiseMax(points[image.polygon_begin + k]);
      }
      if ((face.lo.array() > hi_.array()).any() || (face.hi.array() < lo_.array()).any()) continue;
      faces_.push_back(face);
      for (std::uint32_t i = 0; i < image.polygon_count; ++i) {
        const std::uint32_t k = (first + i) % image.polygon_count;
        const Vec2& a = points[image.polygon_begin + k];
        const Vec2& b = points[image.polygon_begin + (k + 1) % image.polygon_count];
        if (a == b) continue;
        const bool forward = a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
        const std::array<double, 4> key = forward
                                              ? std::array<double, 4>{a.x(), a.y(), b.x(), b.y()}
                                              : std::array<double, 4>{b.x(), b.y(), a.x(), a.y()};
        if (face_edges.insert(key).second) insert_constraint(a, b);
      }
    }
  }

  struct OrderedFace {
    std::array<std::int64_t, 2> mean;
    int id;
    std::uint32_t first;  // the polygon's least vertex
  };
  std::vector<OrderedFace> ordered_faces(const std::vector<int>& slice_faces) const {
    const std::vector<Vec2>& points = field_.points_;
    const double quantum = 1e-9 * diagonal_;
    const auto grid_point = [&](const Vec2& p) {
      return std::array<std::int64_t, 2>{std::llround(p.x() / quantum),
                                         std::llround(p.y() / quantum)};
    };
    std::vector<OrderedFace> ordered;
    for (const int f : slice_faces) {
      const FaceImage& image = field_.images_[static_cast<std::size_t>(f)];
      if (image.polygon_count == 0) continue;
      Vec2 sum = Vec2::Zero();
      std::uint32_t first = 0;
      for (std::uint32_t k = 0; k < image.polygon_count; ++k) {
        sum += points[image.polygon_begin + k];
        if (grid_point(points[image.polygon_begin + k]) <
            grid_point(points[image.polygon_begin + first]))
          first = k;
      }
      ordered.push_back({grid_point(sum / image.polygon_count), f, first});
    }
    std::sort(ordered.begin(), ordered.end(), [](const OrderedFace& a, const OrderedFace& b) {
      return a.mean != b.mean ? a.mean < b.mean : a.id < b.id;
    });
    return ordered;
  }

  // A slice holds hundreds of faces: a uniform grid over the unknown set's box lists the faces
  // whose boxes reach each cell (in the order of `faces_`, so the first face containing a point
  // is the same as by a scan).
  void index_faces() {
    grid_side_ =
        std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(faces_.size())))));
    grid_cell_ = ((hi_ - lo_) / grid_side_).cwiseMax(Vec2::Constant(1e-300));
    faces_in_cell_.assign(static_cast<std::size_t>(grid_side_ * grid_side_), {});
    for (std::size_t i = 0; i < faces_.size(); ++i)
      for (int gy = grid_index(faces_[i].lo, 1); gy <= grid_index(faces_[i].hi, 1); ++gy)
        for (int gx = grid_index(faces_[i].lo, 0); gx <= grid_index(faces_[i].hi, 0); ++gx)
          faces_in_cell_[static_cast<std::size_t>(gy * grid_side_ + gx)].push_back(
              static_cast<int>(i));
  }
  int grid_index(const Vec2& p, int axis) const {
    return std::clamp(static_cast<int>(std::floor((p[axis] - lo_[axis]) / grid_cell_[axis])), 0,
                      grid_side_ - 1);
  }
  // The index in `faces_` of the face holding p (-1: none).
  int face_of(const Vec2& p) const {
    for (const int i : faces_in_cell_[static_cast<std::size_t>(grid_index(p, 1) * grid_side_ +
                                                               grid_index(p, 0))]) {
      const SliceFace& face = faces_[static_cast<std::size_t>(i)];
      if ((p.array() < face.lo.array()).any() || (p.array() > face.hi.array()).any()) continue;
      const FaceImage& image = field_.images_[static_cast<std::size_t>(face.id)];
      if (in_convex_ccw(field_.points_.data() + image.polygon_begin, image.polygon_count, p))
        return i;
    }
    return -1;
  }

  double* values_of(std::size_t entry) { return entry_values_.data() + entry * 3 * fc_; }

  // Completed values of the corners of every unknown triangle, refined where they disagree: in
  // rounds, the new triangles are listed, their new corners completed, and the longest edges of
  // those whose corners complete to different labels split.
  void refine() {
    // Room for the refinement rounds too: moving the entries as the vector grows, into fresh
    // pages, was a tenth of the completion.
    entries_.reserve(2 * cdt_.number_of_faces());
    for (int round = 0;; ++round) {
      fresh_faces_.clear();
      job_vertices_.clear();
      cache_.jobs_3d.clear();
      cache_.jobs_2d.clear();
      list_new_triangles(round);
      complete_new_corners();
      const auto splits = edges_to_split();
      if (splits.empty() || round == kMaxRefinementRounds) break;
      split(splits);
    }
  }

  // The triangles new in this round (a flip may also have reused a face for new corners); each
  // holds its entry until the splits change the triangulation. The points the last round
  // inserted: every triangle an insertion makes has the new point as a corner, so the triangles
  // new in a round are among those around these points (walking every triangle of the slice in
  // every round was a twentieth of the completion on the homer 80 mm sector set).
  void list_new_triangles(int round) {
    if (round == 0) {
      for (auto it = cdt_.finite_faces_begin(); it != cdt_.finite_faces_end(); ++it)
        list_if_new(it);
      return;
    }
    for (const Cdt::Vertex_handle& v : inserted_) {
      Cdt::Face_circulator around = cdt_.incident_faces(v), done = around;
      do {
        if (!cdt_.is_infinite(around)) list_if_new(around);
      } while (++around != done);
    }
    // In the triangulation's own order, which the splits are inserted in (the order the walk
    // over every triangle had): the same triangulation.
    const auto& container = cdt_.tds().faces();
    std::vector<std::pair<std::size_t, Cdt::Face_handle>> ordered;
    ordered.reserve(fresh_faces_.size());
    for (const Cdt::Face_handle& f : fresh_faces_) ordered.emplace_back(container.index(f), f);
    std::sort(ordered.begin(), ordered.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    for (std::size_t i = 0; i < ordered.size(); ++i) fresh_faces_[i] = ordered[i].second;
  }

  void list_if_new(const Cdt::Face_handle& it) {
    int& index = it->info().entry;
    if (index >= 0) {
      const Completed& known = entries_[static_cast<std::size_t>(index)];
      for (const Cdt::Vertex_handle& v : known.vertices)
        if (v != it->vertex(0) && v != it->vertex(1) && v != it->vertex(2)) index = -1;
    }
    if (index >= 0) return;
    index = static_cast<int>(entries_.size());
    Completed& entry = entries_.emplace_back();
    for (int k = 0; k < 3; ++k) entry.vertices[k] = it->vertex(k);
    if (!place(entry)) return;
    list_corner_parts(entry);
    fresh_faces_.push_back(it);
  }

  // The triangle's corners (counter-clockwise), component and face; false (skipped) for a
  // sliver or a triangle outside the unknown set or the faces.
  bool place(Completed& entry) const {
    UnknownTriangle& triangle = entry.triangle;
    for (int k = 0; k < 3; ++k)
      triangle.corners[k] = Vec2(entry.vertices[k]->point().x(), entry.vertices[k]->point().y());
    const double area =
        signed_area(Ring2{triangle.corners[0], triangle.corners[1], triangle.corners[2]});
    // Slivers from constraint intersections rounded onto each other cover nothing.
    const double longest_sq = std::max({(triangle.corners[1] - triangle.corners[0]).squaredNorm(),
                                        (triangle.corners[2] - triangle.corners[1]).squaredNorm(),
                                        (triangle.corners[0] - triangle.corners[2]).squaredNorm()});
    entry.skipped =
        !(std::abs(area) > 1e-12 * longest_sq) || std::abs(area) < 1e-14 * diagonal_ * diagonal_;
    if (area < 0.0) {  // counter-clockwise
      std::swap(triangle.corners[1], triangle.corners[2]);
      std::swap(entry.vertices[1], entry.vertices[2]);
    }
    const Vec2 centroid = (triangle.corners[0] + triangle.corners[1] + triangle.corners[2]) / 3.0;
    if (!entry.skipped) triangle.component = component_of(centroid);
    entry.skipped = entry.skipped || triangle.component < 0;
    if (!entry.skipped) entry.face_index = face_of(centroid);
    entry.skipped = entry.skipped || entry.face_index < 0;
    return !entry.skipped;
  }

  // The cache slots of the triangle's corners, listing the parts its new corners need.
  void list_corner_parts(Completed& entry) {
    const UnknownTriangle& triangle = entry.triangle;
    for (int k = 0; k < 3; ++k) {
      VertexInfo& point = entry.vertices[k]->info();
      if (point.slot_3d < 0) {
        point.slot_3d =
            static_cast<std::int64_t>(cache_.add(cache_.jobs_3d, -1, triangle.corners[k]));
        job_vertices_.push_back(entry.vertices[k]);
      }
      entry.slots_3d[k] = static_cast<std::size_t>(point.slot_3d);
      if (point.component < 0) {
        point.component = triangle.component;
        point.slot_2d = static_cast<std::int64_t>(
            cache_.add(cache_.jobs_2d, triangle.component, triangle.corners[k]));
      }
      entry.slots_2d[k] = point.component == triangle.component
                              ? static_cast<std::size_t>(point.slot_2d)
                              : cache_.slot(cache_.part_2d, cache_.jobs_2d, triangle.component,
                                            triangle.corners[k]);
    }
  }

  // The parts this round listed, then formula 7 at the new triangles' corners.
  void complete_new_corners() {
    // The known faces each new corner reads: those of the faces of all unknown triangles around
    // it (a corner shared by several faces of the slice gets one 3D part, from the cells of all
    // of them: they are all in one group). complete_round reads the union of these lists (most
    // corners lie inside one face; those on face edges read the lists of all the faces around).
    std::vector<std::vector<std::span<const int>>> corner_faces(job_vertices_.size());
    tbb::parallel_for(std::size_t{0}, job_vertices_.size(), [&](std::size_t j) {
      std::vector<int> faces_around;  // indices in `faces_`
      Cdt::Face_circulator around = cdt_.incident_faces(job_vertices_[j]), done = around;
      do {
        if (cdt_.is_infinite(around)) continue;
        const Completed& e = entries_[static_cast<std::size_t>(around->info().entry)];
        if (!e.skipped &&
            std::find(faces_around.begin(), faces_around.end(), e.face_index) == faces_around.end())
          faces_around.push_back(e.face_index);
      } while (++around != done);
      // Each face's local faces (sorted): most corners lie inside one face and read these.
      for (const int face_index : faces_around)
        corner_faces[j].push_back(local_faces_[static_cast<std::size_t>(
            faces_[static_cast<std::size_t>(face_index)].id)]);
    });
    field_.complete_round(s_, corner_faces, cache_);
    entry_values_.resize(entries_.size() * 3 * fc_);
    tbb::parallel_for(std::size_t{0}, fresh_faces_.size(), [&](std::size_t i) {
      blend_corner_values(static_cast<std::size_t>(fresh_faces_[i]->info().entry));
    });
  }

  // Formula 7 at a triangle's corners: the normalised blend of both parts.
  void blend_corner_values(std::size_t entry_index) {
    const Completed& entry = entries_[entry_index];
    double* const entry_corner_values = values_of(entry_index);
    const Vec2* corners = entry.triangle.corners;
    const Vec2 centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
    std::vector<double> inside;
    for (int k = 0; k < 3; ++k) {
      const double* n3w = cache_.at(entry.slots_3d[k]);
      const double* n2 = cache_.at(entry.slots_2d[k]);
      if (cache_.on_boundary[entry.slots_2d[k]] != 0) {
        // On the boundary (b) is read just inside the triangle's corner, so that the corner
        // takes the limit from its own side (Section 5.1).
        inside.assign(fc_ + 1, 0.0);
        add_part_2d(s_.unknown[static_cast<std::size_t>(entry.triangle.component)], fc_,
                    corners[k] + 1e-4 * (centroid - corners[k]), false, inside.data());
        n2 = inside.data();
      }
      const double denominator = n3w[fc_] + n2[fc_];
      double* value = entry_corner_values + static_cast<std::size_t>(k) * fc_;
      for (std::size_t l = 0; l < fc_; ++l)
        value[l] =
            denominator > 0.0 ? 2.0 * (n3w[l] + n2[l]) / denominator - 1.0 : (l == 0 ? 1.0 : -1.0);
    }
  }

  using Edge = std::pair<Cdt::Vertex_handle, Cdt::Vertex_handle>;
  // Longest edges of the triangles to split, by their end vertices. Only new triangles can need
  // a split: a triangle whose corners disagreed had its longest edge split last round, which
  // removed it. A triangle whose corners complete to different labels holds part of the
  // surface: split it until it is as fine as the octree that will sample the field. At the
  // midpoint of its longest edge, not at its centroid: that edge is often a face edge (a
  // constraint), which centroid splits never shorten, so they went on adding points beside it
  // for every round (twice the triangles on the 80 mm sector sets, for no better IoU).
  std::vector<Edge> edges_to_split() {
    const double refined_min = kRefinedTriangleMin * diagonal_;
    std::vector<Edge> splits;
    for (const Cdt::Face_handle& it : fresh_faces_) {
      const std::size_t entry_index = static_cast<std::size_t>(it->info().entry);
      const Completed& c = entries_[entry_index];
      if (c.skipped) continue;
      const UnknownTriangle& triangle = c.triangle;
      const double longest_sq =
          std::max({(triangle.corners[1] - triangle.corners[0]).squaredNorm(),
                    (triangle.corners[2] - triangle.corners[1]).squaredNorm(),
                    (triangle.corners[0] - triangle.corners[2]).squaredNorm()});
      if (longest_sq <= refined_min * refined_min || !corners_disagree(entry_index)) continue;
      int longest = 0;
      double longest_edge_sq = -1.0;
      for (int k = 0; k < 3; ++k) {
        const double length_sq = CGAL::squared_distance(it->vertex(Cdt::cw(k))->point(),
                                                        it->vertex(Cdt::ccw(k))->point());
        if (length_sq > longest_edge_sq) {
          longest_edge_sq = length_sq;
          longest = k;
        }
      }
      splits.emplace_back(it->vertex(Cdt::cw(longest)), it->vertex(Cdt::ccw(longest)));
    }
    return splits;
  }

  // Whether the triangle's corners complete to different labels (argmax of their values).
  bool corners_disagree(std::size_t entry_index) {
    int first_label = -1;
    for (int k = 0; k < 3; ++k) {
      const double* v = values_of(entry_index) + static_cast<std::size_t>(k) * fc_;
      const int label = static_cast<int>(std::max_element(v, v + fc_) - v);
      if (first_label < 0) first_label = label;
      if (label != first_label) return true;
    }
    return false;
  }

  // Inserts the midpoints of the edges (once each: both triangles along an edge may ask).
  void split(const std::vector<Edge>& splits) {
    std::set<std::array<double, 4>> split_edges;
    inserted_.clear();
    for (const auto& [a, b] : splits) {
      const CdtKernel::Point_2& pa = a->point();
      const CdtKernel::Point_2& pb = b->point();
      std::array<double, 4> key{pa.x(), pa.y(), pb.x(), pb.y()};
      if (std::make_pair(pb.x(), pb.y()) < std::make_pair(pa.x(), pa.y()))
        key = {pb.x(), pb.y(), pa.x(), pa.y()};
      if (!split_edges.insert(key).second) continue;
      const CdtKernel::Point_2 middle(0.5 * (pa.x() + pb.x()), 0.5 * (pa.y() + pb.y()));
      Cdt::Face_handle face;
      int index = 0;
      // On the edge itself (a constraint is split there), even where rounding puts the midpoint
      // a hair off its line.
      if (cdt_.is_edge(a, b, face, index))
        inserted_.push_back(cdt_.insert(middle, Cdt::EDGE, face, index));
      else
        inserted_.push_back(cdt_.insert(middle));
    }
  }

  // The final triangles, per face, in the order of their corner coordinates (not the
  // triangulation's).
  void write(SliceCompletion& out) {
    using TriangleKey = std::array<double, 6>;
    std::vector<std::pair<TriangleKey, std::size_t>> ordered;  // (corners, entry)
    for (auto it = cdt_.finite_faces_begin(); it != cdt_.finite_faces_end(); ++it) {
      const std::size_t entry_index = static_cast<std::size_t>(it->info().entry);
      const Completed& entry = entries_[entry_index];
      if (entry.skipped) continue;
      const Vec2* corners = entry.triangle.corners;
      ordered.emplace_back(TriangleKey{corners[0].x(), corners[0].y(), corners[1].x(),
                                       corners[1].y(), corners[2].x(), corners[2].y()},
                           entry_index);
    }
    std::sort(ordered.begin(), ordered.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::map<int, std::size_t> entry_of_face;  // face index -> position in out
    for (const auto& [key, entry_index] : ordered) {
      const Completed& entry = entries_[entry_index];
      auto [it, inserted] = entry_of_face.try_emplace(entry.face_index, out.faces.size());
      if (inserted) {
        out.faces.push_back(faces_[static_cast<std::size_t>(entry.face_index)].id);
        out.triangles.emplace_back();
        out.values.emplace_back();
      }
      out.triangles[it->second].push_back(entry.triangle);
      const double* corner_values = values_of(entry_index);
      out.values[it->second].insert(out.values[it->second].end(), corner_values,
                                    corner_values + 3 * fc_);
    }
  }

  const CellField& field_;
  const PreparedSlice& s_;
  const std::size_t fc_;
  const double diagonal_;
  const std::vector<std::vector<int>>& local_faces_;  // of each face of the arrangement
  double triangle_size_ = 0.0;
  Cdt cdt_;
  Cdt::Vertex_handle last_vertex_;
  std::unordered_map<std::array<double, 2>, Cdt::Vertex_handle, DoublesHash> vertex_at_;
  Vec2 lo_, hi_;                                 // the unknown set's box
  std::vector<std::pair<Vec2, Vec2>> boundary_;  // the split boundary edges
  std::vector<SliceFace> faces_;
  int grid_side_ = 1;
  Vec2 grid_cell_;
  std::vector<std::vector<int>> faces_in_cell_;
  CornerCache cache_;
  std::vector<Completed> entries_;
  // The corner values of entry i (3 corners x fc) at i * 3 * fc: one array rather than one
  // allocation per triangle.
  std::vector<double> entry_values_;
  std::vector<Cdt::Face_handle> fresh_faces_;     // this round's new triangles
  std::vector<Cdt::Vertex_handle> job_vertices_;  // of each 3D part listed this round
  std::vector<Cdt::Vertex_handle> inserted_;      // the points the last round inserted
};

void CellField::triangulate_unknown(int slice, const std::vector<int>& slice_faces,
                                    const std::vector<std::vector<int>>& local_faces,
                                    SliceCompletion& out) const {
  UnknownTriangulator(*this, slice, local_faces).run(slice_faces, out);
}

void CellField::complete_round(const PreparedSlice& s,
                               const std::vector<std::vector<std::span<const int>>>& corner_faces,
                               CornerCache& cache) const {
  const std::size_t fc = static_cast<std::size_t>(function_count());
  cache.values.resize(cache.on_boundary.size() * cache.stride, 0.0);
  // (a) the 3D mean-value interpolant of the known faces around, at the corner itself. Face by
  // face within chunks of corners: the corners of a chunk lie close together and read mostly the
  // same faces, so each face is read for up to four of them at once, one per AVX2 lane
  // (known_weights4), where one corner at a time left most lanes padding on rings of a handful
  // of edges. Every corner still adds its faces in ascending order (its list's) with the same
  // edge sums, so its sums are the same as corner by corner.
  const std::size_t job_count = cache.jobs_3d.size();
  const std::size_t chunk_count = (job_count + kCornersPerChunk - 1) / kCornersPerChunk;
  tbb::parallel_for(std::size_t{0}, chunk_count, [&](std::size_t chunk) {
    const std::size_t first = chunk * kCornersPerChunk;
    const std::size_t last = std::min(job_count, first + kCornersPerChunk);
    FaceReaders& readers = FaceReaders::start(images_.size());
    for (std::size_t j = first; j < last; ++j)
      for (const std::span<const int> list : corner_faces[j])
        for (const int g : list) readers.count(g, static_cast<std::uint32_t>(j - first));
    readers.group();
    for (std::size_t j = first; j < last; ++j)
      for (const std::span<const int> list : corner_faces[j])
        for (const int g : list) readers.add(g, static_cast<std::uint32_t>(j - first));
    Vec3 points[kCornersPerChunk];
    for (std::size_t j = first; j < last; ++j) {
      const Vec2& corner = cache.jobs_3d[j].corner;
      points[j - first] = s.origin + corner.x() * s.u + corner.y() * s.v;
    }
    std::vector<double> materials(4 * fc);  // of one face, per lane
    const std::span<const int> faces = readers.faces();
    for (std::size_t i = 0; i < faces.size(); ++i) {
      const int g = faces[i];
      prefetch_known_reads(faces, i);
      const std::span<const std::uint32_t> face_readers = readers.readers(i);
      for (std::size_t r = 0; r < face_readers.size(); r += 4) {
        const std::size_t lanes = std::min<std::size_t>(4, face_readers.size() - r);
        Vec3 lane_points[4];
        for (std::size_t k = 0; k < lanes; ++k) lane_points[k] = points[face_readers[r + k]];
        double known[4];
        bool ok[4];
        std::fill(materials.begin(), materials.end(), 0.0);
        known_weights4(g, lane_points, lanes, known, materials.data(), ok);
        for (std::size_t k = 0; k < lanes; ++k) {
          if (!ok[k]) continue;
          const double* lane_materials = materials.data() + k * fc;
          double* n3w = cache.at(cache.jobs_3d[first + face_readers[r + k]].slot);
          double material_sum = 0.0;
          for (std::size_t l = 1; l < fc; ++l) {
            n3w[l] += 0.5 * lane_materials[l];
            material_sum += lane_materials[l];
          }
          n3w[0] += 0.5 * (known[k] - material_sum);  // the known outside
          n3w[fc] += 0.5 * known[k];
        }
      }
    }
    readers.finish();
  });
  // (b) at the corner itself when it lies inside the unknown set (the interpolant is smooth
  // there, and the triangles around the corner share it).
  tbb::parallel_for(std::size_t{0}, cache.jobs_2d.size(), [&](std::size_t j) {
    const CornerCache::Job& job = cache.jobs_2d[j];
    double* n2 = cache.at(job.slot);
    if (!add_part_2d(s.unknown[static_cast<std::size_t>(job.owner)], fc, job.corner, true, n2)) {
      std::fill(n2, n2 + cache.stride, 0.0);
      cache.on_boundary[job.slot] = 1;
    }
  });
}

void CellField::prefetch_known_reads(std::span<const int> faces, std::size_t i) const {
  // Reaching a face's records, not the arithmetic, is most of the time of a read: they are
  // scattered over the arrays of all faces, one record leading to the next (image, frame, parts,
  // points). So the image of the face read four steps ahead is fetched, then two steps ahead what
  // it points to, then one step ahead its parts' points (-10 % of the completion on the homer
  // 80 mm sector set: bench/compare_runs.sh, twelve pairs of runs without and with).
  if (i + 4 < faces.size()) __builtin_prefetch(&images_[static_cast<std::size_t>(faces[i + 4])]);
  if (i + 2 < faces.size()) {
    const FaceImage& ahead = images_[static_cast<std::size_t>(faces[i + 2])];
    __builtin_prefetch(&frames_[static_cast<std::size_t>(ahead.frame)]);
    __builtin_prefetch(points_.data() + ahead.polygon_begin);
    if (!ahead.parts.empty()) __builtin_prefetch(ahead.parts.data());
    if (!ahead.known_parts.empty()) __builtin_prefetch(ahead.known_parts.data());
  }
  if (i + 1 < faces.size()) {
    const FaceImage& next = images_[static_cast<std::size_t>(faces[i + 1])];
    for (const FaceImage::Part& part : next.parts) __builtin_prefetch(points_.data() + part.begin);
    if (next.known_clipped)
      for (const FaceImage::Part& part : next.known_parts)
        __builtin_prefetch(points_.data() + part.begin);
  }
}

void CellField::known_weights4(int face, const Vec3 (&points)[4], std::size_t count,
                               double (&known)[4], double* materials, bool (&ok)[4]) const {
  const FaceImage& image = images_[static_cast<std::size_t>(face)];
  const PlaneFrame& frame = frames_[static_cast<std::size_t>(image.frame)];
  double foot_x[4], foot_y[4], height[4], inv_height[4];
  int first_ok = -1;
  for (std::size_t k = 0; k < 4; ++k) {
    const Vec3 d = points[std::min(k, count - 1)] - frame.origin;
    height[k] = std::abs(d.dot(frame.unit_normal));
    ok[k] = k < count && height[k] > on_face_height_;
    foot_x[k] = d.dot(frame.u);
    foot_y[k] = d.dot(frame.v);
    inv_height[k] = 1.0 / height[k];
    if (ok[k] && first_ok < 0) first_ok = static_cast<int>(k);
  }
  if (first_ok < 0) return;
  for (std::size_t k = 0; k < 4; ++k)
    if (!ok[k]) {  // a point on the face's plane, or no point: a copy of a lane that is used
      const std::size_t copy = static_cast<std::size_t>(first_ok);
      foot_x[k] = foot_x[copy];
      foot_y[k] = foot_y[copy];
      height[k] = height[copy];
      inv_height[k] = inv_height[copy];
    }
  // The plain edge sums: the completion adds these weights into sums of order 1 / distance, so
  // the absolute accuracy of the plain sum suffices; the split form that keeps small angles'
  // relative accuracy (feet outside a face, most of the faces read here) would cost three times
  // as many atan2.
  // Parts that are the face polygon itself (a face wholly inside a ring: most faces) take the
  // polygon's sum, computed once.
  double polygon[4];
  bool polygon_done = false;
  const auto polygon_angle = [&]() -> const double(&)[4] {
    if (!polygon_done)
      projected_angle_plain4(points_.data() + image.polygon_begin, image.polygon_count, foot_x,
                             foot_y, height, polygon);
    polygon_done = true;
    return polygon;
  };
  double angle[4];
  const auto copy_or_angle = [&](const FaceImage::Part& part) {
    if (part.polygon_copy != 0) {
      const double(&whole)[4] = polygon_angle();
      for (std::size_t k = 0; k < 4; ++k) angle[k] = part.polygon_copy * whole[k];
    } else {
      part_angle4(part, foot_x, foot_y, height, angle);
    }
  };
  if (image.known_clipped) {
    std::fill(known, known + 4, 0.0);
    for (const FaceImage::Part& part : image.known_parts) {
      copy_or_angle(part);
      for (std::size_t k = 0; k < 4; ++k) known[k] += angle[k];
    }
  } else {
    std::copy_n(polygon_angle(), 4, known);
  }
  for (std::size_t k = 0; k < 4; ++k) known[k] *= inv_height[k];
  const std::size_t fc = static_cast<std::size_t>(function_count());
  for (const FaceImage::Part& part : image.parts) {
    copy_or_angle(part);
    for (std::size_t k = 0; k < 4; ++k)
      materials[k * fc + static_cast<std::size_t>(part.material)] += angle[k] * inv_height[k];
  }
}

void CellField::build_unknown_images() {
  std::vector<int> slices_with_unknown;
  for (std::size_t s = 0; s < slices_.size(); ++s)
    if (!slices_[s].unknown.empty()) slices_with_unknown.push_back(static_cast<int>(s));
  face_completion_hashes_.assign(images_.size(), 0);
  if (slices_with_unknown.empty()) return;
  Stopwatch clock;
  const UnknownAdjacency adjacency = link_unknown_cells(arrangement_, images_);
  group_count_ = adjacency.group_count;
  const std::vector<std::vector<int>> local_faces =
      local_known_faces(arrangement_, images_, adjacency);
  const std::vector<std::vector<int>> slice_faces =
      unknown_faces_by_slice(arrangement_, images_, slices_.size());
  slice_completions_.resize(slices_.size());
  std::vector<std::vector<std::pair<int, std::uint64_t>>> inputs(slices_.size());
  const std::vector<int> stale =
      stale_slices(slices_with_unknown, slice_faces, local_faces, inputs);
  // Slices triangulate and complete independently (each writes only its own entry).
  tbb::parallel_for(std::size_t{0}, stale.size(), [&](std::size_t index) {
    const std::size_t slice = static_cast<std::size_t>(stale[index]);
    complete_slice(static_cast<int>(slice), slice_faces[slice], local_faces,
                   std::move(inputs[slice]));
  });
  install_completions(slices_with_unknown);
  completion_seconds_ = clock.seconds();
  recompleted_slices_ = stale.size();
}

std::vector<int> CellField::stale_slices(
    const std::vector<int>& slices_with_unknown, const std::vector<std::vector<int>>& slice_faces,
    const std::vector<std::vector<int>>& local_faces,
    std::vector<std::vector<std::pair<int, std::uint64_t>>>& inputs) const {
  // A slice's triangles and values depend only on the images of its faces with unknown parts
  // and of their local faces: slices none of whose inputs were rebuilt keep their completion
  // (the online engine's zone rarely reaches most slices).
  std::vector<char> is_stale(slices_.size(), 0);
  tbb::parallel_for(std::size_t{0}, slices_with_unknown.size(), [&](std::size_t index) {
    const std::size_t slice = static_cast<std::size_t>(slices_with_unknown[index]);
    std::vector<std::pair<int, std::uint64_t>>& read = inputs[slice];
    FaceMarks& collected = FaceMarks::start(images_.size());
    const auto add = [&](int g) {
      if (!collected.insert(g)) return;
      read.emplace_back(g, image_generations_[static_cast<std::size_t>(g)]);
    };
    for (const int f : slice_faces[slice]) {
      add(f);
      for (const int g : local_faces[static_cast<std::size_t>(f)]) add(g);
    }
    std::sort(read.begin(), read.end());
    is_stale[slice] = read != slice_completions_[slice].inputs || read.empty();
  });
  std::vector<int> stale;
  for (const int slice : slices_with_unknown)
    if (is_stale[static_cast<std::size_t>(slice)]) stale.push_back(slice);
  return stale;
}

void CellField::complete_slice(int slice, const std::vector<int>& slice_faces,
                               const std::vector<std::vector<int>>& local_faces,
                               std::vector<std::pair<int, std::uint64_t>> inputs) {
  SliceCompletion& completion = slice_completions_[static_cast<std::size_t>(slice)];
  completion = SliceCompletion{};
  completion.inputs = std::move(inputs);
  triangulate_unknown(slice, slice_faces, local_faces, completion);
  // Far-field trees (they reorder the triangles) and hashes, kept with the completion: a slice
  // that is not completed again keeps them too.
  const std::size_t face_count = completion.faces.size();
  completion.tree_nodes.resize(face_count);
  completion.tree_moments.resize(face_count);
  for (std::size_t i = 0; i < face_count; ++i) {
    if (completion.triangles[i].size() >= kTriangleTreeMinTriangles)
      build_triangle_tree(completion.triangles[i].data(), completion.values[i].data(),
                          completion.triangles[i].size(), function_count(),
                          completion.tree_nodes[i], completion.tree_moments[i]);
    completion.hashes.push_back(completion_hash(completion.triangles[i], completion.values[i],
                                                static_cast<std::size_t>(function_count())));
  }
}

void CellField::install_completions(const std::vector<int>& slices_with_unknown) {
  for (const int slice : slices_with_unknown) {
    const SliceCompletion& completion = slice_completions_[static_cast<std::size_t>(slice)];
    for (std::size_t i = 0; i < completion.faces.size(); ++i) {
      FaceImage& image = images_[static_cast<std::size_t>(completion.faces[i])];
      image.triangle_begin = static_cast<std::uint32_t>(triangles_.size());
      image.triangle_count = static_cast<std::uint32_t>(completion.triangles[i].size());
      triangles_.insert(triangles_.end(), completion.triangles[i].begin(),
                        completion.triangles[i].end());
      corner_values_.insert(corner_values_.end(), completion.values[i].begin(),
                            completion.values[i].end());
      if (!completion.tree_nodes[i].empty()) {
        image.triangle_tree = completion.tree_nodes[i].data();
        image.triangle_tree_moments = completion.tree_moments[i].data();
      }
      face_completion_hashes_[static_cast<std::size_t>(completion.faces[i])] = completion.hashes[i];
    }
  }
}

}  // namespace sonoshape::recon
