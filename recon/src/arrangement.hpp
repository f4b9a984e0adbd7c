#pragma once
// The 3D arrangement of the slice planes inside the reconstruction box (Bermano et al. 2011,
// Section 4.1), built by splitting convex cells plane by plane, which is also how the online
// engine adds one more plane.
//
// Robustness: every vertex is the exact intersection of three input planes (a construction of
// depth one), and every side-of-plane decision is exact, so near-parallel planes, three planes
// through a line, four through a point and planes through existing vertices all give a
// consistent cell complex. A vertex keeps its three planes and the interval approximation of
// the point that CGAL's Epeck kernel would compute; side() is Epeck's filtered predicate: the
// interval test, and CGAL's exact predicate on the exact point, constructed from the planes,
// when the intervals touch the plane (a lazy Epeck point kept two DAG nodes, ~290 bytes, per
// vertex: a third of the peak memory at 200 random slices). Doubles are used only after the
// combinatorics is fixed (evaluation, face images).
//
// On demand (issue 24): the full arrangement of k planes has O(k^3) cells, of which the octree
// evaluates only those the surface passes through. An on-demand arrangement records the planes
// and builds a cell only when construct_cell() is asked for a point in it: a lazily refined BSP
// whose leaves are convex regions with the planes that may still cross them; a query splits its
// leaf by those planes in turn (the same exact predicates and depth-one vertex constructions),
// following the point's side, until no plane crosses the region. That region is the cell of the
// full arrangement containing the point; it shares the faces its built neighbours have (found
// by their planes and vertex keys in an open-addressing table). Regions do not share vertices
// (finding them again cost more than constructing them: the same three planes give the same
// exact point), so a cell's faces may name one point by two ids.
// Online, a plane inserted after cells were built reopens the built cells it crosses: each is a
// region again (its faces with one id per point, the planes from the new one on still to try),
// its faces the plane crosses are retired, the others are kept for whichever part is built next
// to them; regions not refined yet meet the new plane when a query reaches them.
// In parallel (construct_cells): the points of a batch are walked down the tree, grouped by the
// region they reach, and each region is refined for its points on one thread into a job of its
// own (its vertices, regions and nodes; the arrangement is only read). A batch that reaches few
// regions (the first one reaches the root) is refined in bounded breadth-first rounds until it
// reaches more. The jobs are then put into the tree with ids in job order, so that cells, faces,
// vertices and their ids are the same for any number of threads: the ids are counted first, the
// jobs' vertices, nodes and cells written in parallel, and their faces shared with the cells
// across them as one-after-the-other building would (link()). The serial steps left (counting,
// growing the arrays, the face table's inserts) and the per-region storage cost a third more
// than the serial construction on one thread at 200 random slices, and give 4.3x on 16 threads
// at 100 (docs/benchmarks.md, "Thread scaling on 16 cores").
// Unknown regions (construct_cells_meeting): the completion reads the faces around a slice's
// unknown set with both their cells, so every cell that may meet a rectangle around it is built
// up front: the rectangles are walked down the tree like the points, clipped in doubles by each
// node's plane with a margin (conservative; the cells are the exact ones), and every region a
// part reaches is refined in the same jobs. Online, the older rectangles are walked only within
// the cells a new plane reopened.
// Left: each split builds both halves of a region though most siblings are never asked for.
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Interval_nt.h>
#include <CGAL/Simple_cartesian.h>
#include <tbb/enumerable_thread_specific.h>

#include <array>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon {

using ExactKernel = CGAL::Exact_predicates_exact_constructions_kernel;
/// The kernel of ExactKernel's approximations (its filter): interval arithmetic, valid only
/// with the FPU rounding upward (CGAL::Protect_FPU_rounding).
using IntervalKernel = CGAL::Simple_cartesian<CGAL::Interval_nt<false>>;

/// A plane n.x + d = 0 with its origin: a slice (slice >= 0) or a face of the box (slice = -1,
/// normal pointing into the box).
struct ArrangementPlane {
  Vec3 normal;        ///< as given (not necessarily unit); exact input of the predicates
  double offset = 0;  ///< d
  int slice = -1;     ///< slice index, or -1 for a box face
  ExactKernel::Plane_3 exact;
  IntervalKernel::Plane_3 interval;  ///< the same plane (its coefficients are exact doubles)
  double signed_distance(const Vec3& p) const { return (normal.dot(p) + offset) / normal.norm(); }
};

/// A convex polygon on one plane. Vertices are counter-clockwise seen from the side the plane's
/// normal points to; edge i (vertex i -> i+1) also lies on plane `edge_planes[i]`.
struct ArrangementFace {
  int plane = -1;
  std::vector<int> vertices;
  std::vector<int> edge_planes;
  int cell_positive = -1;  ///< the cell on the side the normal points to (-1: outside the box)
  int cell_negative = -1;
};

/// A convex cell: the faces bounding it.
struct ArrangementCell {
  std::vector<int> faces;
};

class Arrangement {
 public:
  /// The box as one cell with six faces. Throws GeometryError for an empty box.
  explicit Arrangement(const Box3& box);
  /// The box as one region whose cells are built on demand (construct_cell) when `on_demand`.
  Arrangement(const Box3& box, bool on_demand);

  /// True when cells are built on demand: insert_plane then records the plane and reopens the
  /// built cells it crosses (see insert_plane), cells and faces exist only once
  /// construct_cell() built them, and locate() must not be used.
  bool on_demand() const { return on_demand_; }
  /// On demand: the cell of the full arrangement containing p (p inside the box), built with its
  /// faces on first use, found in O(depth) afterwards. Points on a plane may go to either side,
  /// as locate(). Not thread-safe (nor is construct_cells): call it from one thread, then read
  /// cells concurrently.
  int construct_cell(const Vec3& p);
  /// construct_cell for every point with wanted[n] != 0 (the others get -1). The regions the
  /// points reach are refined in parallel on the calling task arena's threads, each with its
  /// points on one thread; the results are then put into the tree in the order of the batch, so
  /// cells, faces, vertices and their ids do not depend on the number of threads. The regions
  /// are refined and linked in passes of at most `jobs_per_pass` (which bounds the memory they
  /// hold and changes no id). Without on-demand cells, the points are located.
  static constexpr std::size_t kJobsPerPass = 2048;
  std::vector<int> construct_cells(const std::vector<Vec3>& points, const std::vector<char>& wanted,
                                   std::size_t jobs_per_pass = kJobsPerPass);
  /// On demand: builds every cell that may meet one of `polygons` (each convex and planar, its
  /// corners in order; a slice's unknown set, whose faces the completion reads with both their
  /// cells, completion.cpp). Conservative: a cell is built unless the polygon, clipped in doubles
  /// by the planes that bound the cell with a margin of 1e-9 of the box's extent, is empty; the
  /// cells themselves are the exact ones construct_cell builds. Cells built before are kept. The
  /// regions the polygons reach are refined in parallel and put into the tree as in
  /// construct_cells: the same ids for any number of threads.
  void construct_cells_meeting(const std::vector<std::vector<Vec3>>& polygons,
                               std::size_t jobs_per_pass = kJobsPerPass);
  /// On demand: construct_cells_meeting within the cells insert_plane reopened since the last
  /// call only (the online engine: the cells meeting `polygons` were all built before the new
  /// planes, and only the reopened ones are missing). Each reopened region takes the parts of
  /// the polygons inside it (clipped by its faces' planes with the margin); the list of
  /// reopened regions is cleared.
  void construct_reopened_cells_meeting(const std::vector<std::vector<Vec3>>& polygons,
                                        std::size_t jobs_per_pass = kJobsPerPass);
  /// On demand: seconds spent since the last call in the serial steps of building cells
  /// (grouping, numbering, linking: see ReconstructionStats::arrangement_serial_s).
  double take_serial_seconds() { return std::exchange(serial_seconds_, 0.0); }
  /// On demand: the leaves of the lazy BSP (built cells and regions not yet refined).
  std::size_t region_count() const {
    return regions_.size() - free_regions_.size() + built_cell_count();
  }
  /// On demand: the cells built and not reopened since (cell_count() also counts the ids of
  /// reopened cells, which stay unused).
  std::size_t built_cell_count() const { return cells_.size() - reopened_cells_; }
  /// On demand: whether cell id `cell` was reopened by a later plane (its faces are gone).
  bool reopened(int cell) const { return cells_[static_cast<std::size_t>(cell)].faces.empty(); }
  /// On demand: the faces retired since the last call (crossed by a plane inserted after they
  /// were built; no cell uses them again), cleared by the call.
  std::vector<int> take_retired_faces() { return std::exchange(retired_faces_, {}); }

  /// Adds the plane n.x + d = 0 (exact doubles) carrying `slice`, splitting every cell it crosses.
  /// Returns the ids of the cells created or changed (both halves of every split cell). A plane
  /// that misses the interior of the box changes nothing. Throws GeometryError if the plane
  /// coincides with a plane already inserted.
  /// On demand (online engine): every built cell the plane crosses is reopened, i.e. becomes a
  /// region of the lazy BSP again that the next query reaching it splits (by this plane and any
  /// later one), and its id is returned (it is never used again); cells it does not cross and
  /// their faces are kept. Regions not refined yet meet the plane when first touched.
  std::vector<int> insert_plane(const Vec3& normal, double offset, int slice);
  /// The faces the last insert_plane split, by their old ids (each keeps its negative part
  /// under that id; the positive parts are new faces). Every other face kept its polygon.
  std::vector<int> faces_split_by_last_plane() const;

  /// The cell containing p (p inside the box; points on a plane may go to either side).
  int locate(const Vec3& p) const;
  /// locate(p) from a guess (a cell index of this or any arrangement, or -1): the guess when p
  /// lies inside that cell clear of its faces' planes, where the walk down the tree would end in
  /// the same cell, and the walk's answer otherwise. Planes inserted in sweep order make the tree
  /// as deep as the number of planes; most evaluations are in the cell of the one before.
  int locate(const Vec3& p, int guess) const;

  const Box3& box() const { return box_; }
  std::size_t cell_count() const { return cells_.size(); }
  std::size_t face_count() const { return faces_.size(); }
  std::size_t vertex_count() const { return vertex_planes_.size(); }
  std::size_t plane_count() const { return planes_.size(); }
  const ArrangementCell& cell(int id) const { return cells_[static_cast<std::size_t>(id)]; }
  /// Double bounds of a cell's vertices (a reopened cell keeps its last ones).
  const Box3& cell_bounds(int id) const { return cell_bounds_[static_cast<std::size_t>(id)]; }
  const ArrangementFace& face(int id) const { return faces_[static_cast<std::size_t>(id)]; }
  const ArrangementPlane& plane(int id) const { return planes_[static_cast<std::size_t>(id)]; }
  /// Double approximation of a vertex (rounded from the exact point).
  const Vec3& vertex(int id) const { return vertex_approx_[static_cast<std::size_t>(id)]; }
  /// The exact point of a vertex, constructed again on each call (vertices keep an interval
  /// approximation and the three planes they lie on, not the point).
  ExactKernel::Point_3 exact_vertex(int id) const;
  /// Exact side of a vertex w.r.t. a plane: -1, 0 or +1.
  int side(int plane_id, int vertex_id) const;

 private:
  struct FaceSplit {
    int positive = -1;  // face id of the part on the positive side
    int negative = -1;  // face id of the part on the negative side (reuses the old id)
    int chord_from = -1, chord_to = -1;  // the chord on the new plane, in the stored order
  };
  struct BspNode {
    int plane = -1;  // -1: leaf
    int negative = -1, positive = -1;
    int cell = -1;
    int region = -1;  // on demand: a leaf not refined yet (cell -1)
  };
  // On demand: a convex region of the lazy BSP; the planes from index `next` on may cross it.
  // Its faces are records in one array (one allocation per region: a split makes two regions,
  // and hundreds of thousands of splits made allocation a fifth of the time): plane, sigma
  // (+1 / -1: the region's side of the plane), n, then n pairs (vertex, edge plane), the
  // vertices counter-clockwise about the plane's normal as in ArrangementFace.
  struct Region {
    std::vector<int> faces;
    Box3 bounds;
    std::size_t next = 0;
  };
  struct DirectedEdge {
    int from, to, plane;
  };
  // On demand: a vertex a refinement job made (construct_cells): its region faces name it
  // kJobVertex + its index in the job until the job's vertices are numbered after the others.
  static constexpr int kJobVertex = 1 << 30;
  struct JobVertex {
    IntervalKernel::Point_3 interval;
    std::array<int, 3> planes;
    Vec3 approx;
  };
  // On demand: the refinement of one BSP leaf for the points of a batch that reach it, done on
  // one thread: it only reads the arrangement. nodes[0] is the leaf; a node is split by `plane`
  // (children `negative`, `positive`) or is a leaf: a cell, with the points
  // points[points_begin, points_end), or a region no point reached.
  struct RefineJob {
    struct Node {
      int plane = -1;
      int negative = -1, positive = -1;
      int region = -1;  // index in `regions`
      bool cell = false;
      std::size_t points_begin = 0, points_end = 0;
      int targets = -1;  // index in `targets`: the polygons that reach it (construct_cells_meeting)
    };
    int leaf = -1;  // the BSP node
    std::vector<int> points;
    // construct_cells_meeting: per node, the parts of the polygons that may meet its region.
    std::vector<std::vector<std::vector<Vec3>>> targets;
    std::vector<Node> nodes;
    std::vector<Region> regions;
    std::vector<JobVertex> vertices;
    std::vector<std::int8_t> vertex_signs;  // side-of-plane cache of `vertices`
    // Set by number(): the ids of its first vertex, BSP node (minus one: node 0 is `leaf`) and
    // cell in the arrangement.
    int vertex_base = 0, node_base = 0, cell_base = 0;
    // Set by place(): the faces of its cells in node order, each with its key, its vertices'
    // keys (sorted, in sorted_keys from keys_at), its polygon (the record at `at` in the faces
    // of regions[region]) and the corner it starts from; and where each cell's faces end.
    struct CellFace {
      std::uint64_t key = 0;
      int sigma = 0;
      int cell = -1;
      int other_cell = -1;  // link(): the cell across that shares it, when built in this batch
      int region = -1, at = 0, start = 0;
      std::size_t keys_at = 0;
    };
    std::vector<CellFace> cell_faces;
    std::vector<std::size_t> cell_faces_end;
    std::vector<std::uint64_t> sorted_keys;
  };
  // On demand: one thread's scratch: side-of-plane signs of the arrangement's vertices (reset
  // after each test) and a split's working lists.
  struct RefineScratch {
    std::vector<std::int8_t> signs;
    std::vector<int> touched;
    std::vector<std::pair<std::uint64_t, int>> split_vertices;  // per split: edge -> crossing
    std::vector<DirectedEdge> section;
    std::vector<Vec3> clipped;  // a target polygon's part on one side (refine)
  };
  // On demand: face ids by 64-bit key, several per key; open addressing with linear probing (a
  // std::unordered_multimap spent a tenth of the run at 200 random slices in its node chains).
  class FaceTable {
   public:
    // Calls visit(face) for the faces under `key` until it returns true.
    template <typename Visit>
    void find(std::uint64_t key, Visit&& visit) const {
      if (slots_.empty()) return;
      for (std::size_t i = slot_of(key);; i = (i + 1) & (slots_.size() - 1)) {
        const Slot& slot = slots_[i];
        if (slot.face == kEmpty) return;
        if (slot.key == key && slot.face >= 0 && visit(slot.face)) return;
      }
    }
    void insert(std::uint64_t key, int face);
    // Room for `more` insertions without growing.
    void reserve(std::size_t more);
    // Removes `face` from under `key`; false if it is not there.
    bool erase(std::uint64_t key, int face);

   private:
    static constexpr int kEmpty = -1, kErased = -2;
    struct Slot {
      std::uint64_t key = 0;
      int face = kEmpty;
    };
    std::size_t slot_of(std::uint64_t key) const {
      return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> shift_);
    }
    std::vector<Slot> slots_;  // a power of two, at most half used (erased slots count)
    std::size_t used_ = 0;
    int shift_ = 64;
  };
  // On demand: the record of a face starting at faces[at]: `count` corners from `corners`.
  struct RegionFace {
    int plane, sigma, count;
    const int* corners;  // vertex, edge plane, vertex, edge plane, ...
    int vertex(int i) const { return corners[2 * i]; }
    int edge_plane(int i) const { return corners[2 * i + 1]; }
    std::size_t size() const { return 3 + 2 * static_cast<std::size_t>(count); }
  };
  static RegionFace region_face(const std::vector<int>& faces, std::size_t at) {
    return {faces[at], faces[at + 1], faces[at + 2], faces.data() + at + 3};
  }
  // On demand: the jobs of construct_cells: the points with wanted[n] != 0 walked down the tree
  // (cells[n] set for those in built cells), the others grouped by the region they reach.
  std::vector<RefineJob> group_points(const std::vector<Vec3>& points,
                                      const std::vector<char>& wanted, std::vector<int>& cells);
  // On demand: the jobs of construct_cells_meeting: the polygons walked down the tree, clipped
  // by each node's plane (with a margin) and sent to the sides they may reach; a region reached
  // becomes a job with the parts that reach it, in the order of a depth-first walk.
  // `starts`: the nodes to walk from, each with the polygons' parts that may reach it.
  using PolygonParts = std::vector<std::vector<Vec3>>;
  std::vector<RefineJob> group_polygons(const std::vector<std::pair<int, PolygonParts>>& starts);
  // The largest |n.x + d| of `plane` over the box: 1e-9 of it bounds the rounding of a value.
  double value_scale(const ArrangementPlane& plane) const {
    return plane.normal.cwiseAbs().dot(box_.max.cwiseAbs().cwiseMax(box_.min.cwiseAbs())) +
           std::abs(plane.offset);
  }
  // The parts of each of `parts` on the negative and positive side of `plane_id` (clip_to_side),
  // appended to `negative` and `positive`; `scratch` holds one part at a time.
  void split_parts(const PolygonParts& parts, int plane_id, PolygonParts& negative,
                   PolygonParts& positive, std::vector<Vec3>& scratch) const;
  // On demand: a job for region leaf `leaf` (its region moved into the job, its slot freed),
  // appended to `jobs`.
  RefineJob& start_job(std::vector<RefineJob>& jobs, int leaf);
  // The part of convex `polygon` on the `sigma` side of `plane_id` (+1: value >= -margin,
  // -1: value <= margin, margin 1e-9 of the box's extent), into `out`.
  void clip_to_side(const std::vector<Vec3>& polygon, int plane_id, int sigma,
                    std::vector<Vec3>& out) const;
  // On demand: construct_cells' passes over the jobs `group` returns (refine, number, place,
  // link), until a round leaves nothing to refine.
  template <typename Group>
  void refine_in_passes(Group&& group, const std::vector<Vec3>& points, std::vector<int>& cells,
                        std::size_t jobs_per_pass);
  // On demand: refines job.nodes[0] breadth first until each of its points, and each part of
  // its target polygons, is in a cell (a region no plane crosses) or `max_splits` splits are
  // made (the points left in regions keep no cell); const but for the job and the thread's
  // scratch.
  void refine(RefineJob& job, const std::vector<Vec3>& points, RefineScratch& scratch,
              std::size_t max_splits) const;
  // On demand: side(plane, v) for the arrangement's vertices and the job's, cached until
  // reset_signs(job, scratch).
  int job_side(int plane_id, int vertex_id, RefineJob& job, RefineScratch& scratch) const;
  static void reset_signs(RefineJob& job, RefineScratch& scratch);
  const Vec3& job_vertex(int vertex_id, const RefineJob& job) const {
    return vertex_id >= kJobVertex
               ? job.vertices[static_cast<std::size_t>(vertex_id - kJobVertex)].approx
               : vertex(vertex_id);
  }
  // On demand: whether `plane` has vertices of `region` strictly on both sides.
  bool region_crossed(const Region& region, int plane, RefineJob& job,
                      RefineScratch& scratch) const;
  // On demand: the parts (negative, positive) of `old` on each side of `plane`.
  std::pair<Region, Region> split_region(const Region& old, int plane, RefineJob& job,
                                         RefineScratch& scratch) const;
  // On demand: appends the parts of `face` on each side of `new_plane` to `pos` and `neg`;
  // returns the chord as an edge of the cross-section (counter-clockwise about the new plane).
  DirectedEdge split_region_face(const RegionFace& face, int new_plane, std::vector<int>& pos,
                                 std::vector<int>& neg, RefineJob& job,
                                 RefineScratch& scratch) const;
  // On demand: puts refined jobs into the tree in three steps. number(): ids in job order after
  // the arrangement's (vertices, BSP nodes, cells; node order within a job), the arrays grown
  // to hold them. place() (in parallel, one job per thread, writing only the job's ids): the
  // vertices, the nodes, the cells' bounds and faces, cells[n] for the job's points. link() (in
  // job order): the leaves no point reached become regions, and each cell's faces are shared
  // with the cell across when that one is built (by key), added otherwise.
  void number(std::vector<RefineJob>& jobs);
  void place(RefineJob& job, std::vector<int>& cells, std::vector<std::uint64_t>& sorted);
  void link(std::vector<RefineJob>& jobs);
  // The steps of link (arrangement.cpp): the leaves no point reached become regions again, and
  // the new cells' faces are shared or added.
  void relink_regions(std::vector<RefineJob>& jobs);
  class FaceLinker;
  // On demand: the cross-section's edges chained into the new face, appended to `out` with
  // side `sigma`.
  void close_section(const std::vector<DirectedEdge>& section, int new_plane, int sigma,
                     std::vector<int>& out) const;
  // On demand: the reopening of the built cells `plane` crosses (insert_plane).
  std::vector<int> reopen_crossed_cells(int plane);
  // On demand: turns built cell `cell` back into a region that the planes from `next` on may
  // cross; its faces lose the cell (those `plane` crosses are retired).
  void reopen_cell(int cell, int plane);
  // On demand: the key under which faces_by_key_ holds a face on `plane` with these vertex keys
  // (sorted in place).
  static std::uint64_t face_key(int plane, std::vector<std::uint64_t>& keys);
  // On demand: a new region slot.
  int allocate_region(Region region);
  int split_vertex(int a, int b, int face_plane, int edge_plane, int new_plane, RefineJob& job,
                   RefineScratch& scratch) const;
  // The interval approximation of the intersection of three planes (as ExactKernel computes
  // it) and its double point. Throws GeometryError when the planes do not meet in one point.
  std::pair<IntervalKernel::Point_3, Vec3> intersection_point(int a, int b, int c) const;
  // The exact side of the point with this approximation on these three planes.
  int point_side(int plane_id, const IntervalKernel::Point_3& interval,
                 const std::array<int, 3>& planes) const;
  // The exact intersection of three planes as a new vertex (on the last: sign 0 cached).
  int plane_vertex(int face_plane, int edge_plane, int new_plane);
  void reset_signs();
  // Whether p lies inside `cell` (any id) farther from its faces' planes than rounding reaches.
  bool clear_inside(const Vec3& p, int cell) const;
  // A vertex at the intersection of three planes; `approximation` encloses the exact point,
  // `approx` is its double point.
  int add_vertex(const IntervalKernel::Point_3& approximation, const std::array<int, 3>& planes,
                 const Vec3& approx);
  // side(), cached per vertex until reset_signs().
  int plane_side(int plane_id, int vertex_id);
  // Whether two vertices are the same exact point.
  bool same_point(int a, int b) const;
  int edge_vertex(int a, int b, int face_plane, int edge_plane, int new_plane);
  FaceSplit split_face(int face_id, int new_plane);
  void split_cell(int cell_id, int new_plane, std::vector<int>& changed);
  // The steps of split_cell: the new face's boundary chained from the section's edges, and the
  // two cells' boxes and leaves in the point-location tree.
  void chain_section(const std::vector<DirectedEdge>& section, int cell_id, int new_face);
  void locate_split_cells(int cell_neg, int cell_pos, int new_plane);

  Box3 box_;
  std::vector<ArrangementPlane> planes_;
  // Each vertex is the intersection of three planes (box corners: three box faces); it keeps
  // the interval approximation of that point, which decides nearly every side-of-plane test,
  // and the planes, from which the exact point is constructed when the interval cannot decide.
  // A lazy exact point (ExactKernel) kept two nodes of ~290 bytes per vertex: a third of the
  // peak memory at 200 random slices.
  std::vector<IntervalKernel::Point_3> vertex_intervals_;
  std::vector<std::array<int, 3>> vertex_planes_;
  std::vector<Vec3> vertex_approx_;
  std::vector<ArrangementFace> faces_;
  std::vector<ArrangementCell> cells_;
  std::vector<Box3> cell_bounds_;  // double bounds of each cell's vertices, for quick rejection
  std::vector<BspNode> bsp_;
  std::vector<int> leaf_of_cell_;

  bool on_demand_ = false;
  std::vector<Region> regions_;
  std::vector<int> free_regions_;
  // On demand: each vertex's three planes (sorted, 21 bits each), or bit 63 and its id for a
  // box corner: the same key is the same exact point.
  std::vector<std::uint64_t> vertex_keys_;
  // Built faces by a hash of their plane and sorted vertex keys: the two cells on a face share
  // it (and its image) when both are built.
  FaceTable faces_by_key_;
  tbb::enumerable_thread_specific<RefineScratch> refine_scratch_;
  std::vector<std::uint64_t> sorted_scratch_;
  std::size_t reopened_cells_ = 0;
  double serial_seconds_ = 0.0;       // take_serial_seconds()
  std::vector<int> reopened_leaves_;  // construct_reopened_cells_meeting()
  std::vector<int> retired_faces_;

  // Per-insertion scratch state.
  std::vector<std::int8_t> sign_cache_;  // 2: not computed
  std::vector<int> touched_vertices_;
  std::unordered_map<std::uint64_t, int> edge_vertex_cache_;
  std::unordered_map<int, FaceSplit> face_split_cache_;
};

}  // namespace sonoshape::recon
