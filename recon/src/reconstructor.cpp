#include "sonoshape/recon/reconstructor.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <set>
#include <stdexcept>
#include <unordered_map>

#include "arrangement.hpp"
#include "cell_field.hpp"
#include "field_evaluator.hpp"
#include "mean_value.hpp"
#include "mesher.hpp"
#include "octree_field.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_compare.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "thin_plate.hpp"
#include "zero_set_refinement.hpp"

namespace sonoshape::recon {
namespace {

// Two slice planes closer than this (relative, as the slice-set validation) are the same plane.
constexpr double kCoincidentTolerance = 1e-9;

// Appends the points of every region of `slice` too thin for grid cells of `cell_size`: its
// interior point and a lattice of half the cell size over it (see snap_thin_regions).
void add_thin_region_samples(const PreparedSlice& slice, double cell_size,
                             std::vector<RegionSample>& samples) {
  for (std::size_t m = 1; m < slice.rings_by_material.size(); ++m) {
    const std::vector<Ring2>& rings = slice.rings_by_material[m];
    auto inside = [&](const Vec2& p) {
      int winding = 0;
      for (const Ring2& r : rings) winding += winding_number(r.data(), r.size(), p);
      return winding > 0;
    };
    auto add = [&](const Vec2& p) {
      samples.push_back({slice.origin + p.x() * slice.u + p.y() * slice.v, static_cast<int>(m)});
    };
    for (const Ring2& ring : rings) {
      const double area = signed_area(ring);
      if (area <= 0.0) continue;  // holes
      double perimeter = 0.0;
      Vec2 lo = ring[0], hi = ring[0];
      for (std::size_t i = 0; i < ring.size(); ++i) {
        perimeter += (ring[(i + 1) % ring.size()] - ring[i]).norm();
        lo = lo.cwiseMin(ring[i]);
        hi = hi.cwiseMax(ring[i]);
      }
      if (2.0 * area / perimeter >= 2.0 * cell_size) continue;  // wide enough for the grid
      if (const auto p = interior_point(ring); p && inside(*p)) add(*p);
      const double step = 0.5 * cell_size;
      for (double x = lo.x() + 0.5 * step; x < hi.x(); x += step)
        for (double y = lo.y() + 0.5 * step; y < hi.y(); y += step)
          if (inside(Vec2(x, y))) add(Vec2(x, y));
    }
  }
}

// The contour segments of a slice (world mm), ring by ring.
std::vector<std::pair<Vec3, Vec3>> contour_segments(const PreparedSlice& slice) {
  std::vector<std::pair<Vec3, Vec3>> segments;
  for (const auto& rings : slice.rings_by_material)
    for (const Ring2& ring : rings)
      for (std::size_t i = 0; i < ring.size(); ++i) {
        const Vec2& p = ring[i];
        const Vec2& q = ring[(i + 1) % ring.size()];
        segments.emplace_back(slice.origin + p.x() * slice.u + p.y() * slice.v,
                              slice.origin + q.x() * slice.u + q.y() * slice.v);
      }
  return segments;
}

bool same_plane(const LabeledSlice& a, const LabeledSlice& b, double scale) {
  const Vec3 na = a.normal().normalized(), nb = b.normal().normalized();
  return std::abs(na.dot(nb)) >= 1.0 - kCoincidentTolerance &&
         std::abs(na.dot(b.origin_mm - a.origin_mm)) <= kCoincidentTolerance * scale;
}

// A value's tag in the sampled field (BatchEvaluator): the arrangement cell it was evaluated in
// (-1: outside the box, where the value is constant) and the update (generation). The value stays
// current while that cell is unchanged: the field inside a cell depends only on that cell's faces
// and their images. Kept per row of the field, so that telling which of the kept field's rows are
// current is one pass over the rows (before, every row's key was looked up in a 9 MiB table of its
// own: about 1 ms per update of spot's sweep by per-pass timers, 0.1 ms now).
std::uint64_t evaluation_tag(int cell, std::uint32_t generation) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(cell)) << 32) | generation;
}
bool tag_current(std::uint64_t tag, const std::vector<std::uint32_t>& cell_generation) {
  const auto cell = static_cast<std::int32_t>(static_cast<std::uint32_t>(tag >> 32));
  const auto generation = static_cast<std::uint32_t>(tag);
  return cell < 0 || generation >= cell_generation[static_cast<std::size_t>(cell)];
}

}  // namespace

struct Reconstructor::State {
  struct Entry {
    int id = -1;
    LabeledSlice slice;
    bool duplicate = false;  // identical to an earlier slice: not inserted
  };

  ReconstructorOptions options;
  int next_id = 0;
  std::vector<Entry> entries;        // in the reconstruction, insertion order
  std::vector<Entry> pending_adds;   // queued for the next update
  std::vector<int> pending_removes;  // ids of entries to drop at the next update

  // Engine state for `entries`.
  bool built = false;
  Box3 box;
  int depth = 0;
  std::vector<int> material_ids;
  std::unique_ptr<Arrangement> arrangement;    // mean-value field
  std::unique_ptr<CellField> field;            // mean-value field
  std::unique_ptr<ThinPlateField> thin_plate;  // thin-plate field
  std::vector<Box3>
      thin_plate_boxes;  // per material, the box of its contours in the field's slices
  // The entry ids of the thin-plate field's slices, and the materials and box they were
  // prepared with (a rebuild copies them instead of preparing them again).
  std::vector<int> thin_plate_ids;
  std::vector<int> thin_plate_materials;
  Box3 thin_plate_box;
  std::unique_ptr<FieldEvaluator> evaluator;   // made at the first update (opens the device)
  std::vector<std::uint32_t> cell_generation;  // update count at which each cell last changed
  std::uint32_t generation = 0;
  // What the slices alone decide on the grid, for field->slices()[0, contour_slices): merged
  // per update for the new slices only.
  OctreeOptions octree;
  ContourKeys contours;
  std::vector<RegionSample> region_samples;
  std::size_t contour_slices = 0;
  SampledField sampled;
  bool sampled_tags_current =
      false;  // `sampled`'s row tags name this arrangement's cells (false after a rebuild), or
              // for the thin-plate field the solves of this field's sampled solution
  Box3 sampled_box;                  // the box `sampled` was sampled over
  OctreeWorkspace octree_workspace;  // kept across updates (see OctreeWorkspace)
  MeshSet mesh;
  ReconstructionStats totals;

  SliceSet slice_set_of(const std::vector<Entry>& list) const {
    SliceSet set;
    set.labels = options.labels;
    set.bounds = options.bounds;
    for (const Entry& e : list) set.slices.push_back(e.slice);
    return set;
  }

  std::vector<int> materials_of(const std::vector<Entry>& list) const {
    std::set<int> ids;
    for (const LabelInfo& l : options.labels) ids.insert(l.id);
    for (const Entry& e : list)
      for (const Region& r : e.slice.regions)
        if (r.label != kUnknownLabel) ids.insert(r.label);
    return {ids.begin(), ids.end()};
  }

  // Per material index (material_ids' order): whether its label casts a shadow.
  std::vector<bool> shadow_casters() const {
    std::vector<bool> casters;
    for (const int id : material_ids)
      casters.push_back(
          std::any_of(options.labels.begin(), options.labels.end(),
                      [&](const LabelInfo& l) { return l.id == id && l.casts_shadow; }));
    return casters;
  }

  std::string label_name(int id) const {
    for (const LabelInfo& l : options.labels)
      if (l.id == id && !l.name.empty()) return l.name;
    return "label_" + std::to_string(id);
  }

  // Inserts one slice's plane (prepared against the current box and materials, as the field's
  // next slice); returns the cells it created or split and adds the older faces it split to
  // `split_faces`.
  std::vector<int> insert(PreparedSlice prepared, std::vector<int>& split_faces) {
    const std::size_t index = field->slices().size();
    const Vec3 normal = prepared.u.cross(prepared.v);
    const double offset = -normal.dot(prepared.origin);
    field->add_slice(std::move(prepared));
    std::vector<int> cells = arrangement->insert_plane(normal, offset, static_cast<int>(index));
    const std::vector<int> split = arrangement->faces_split_by_last_plane();
    split_faces.insert(split_faces.end(), split.begin(), split.end());
    return cells;
  }

  // On demand: the cells around the slices' unknown sets, built before the face images. The
  // completion reads every face with an unknown part, with the faces of its two cells and of
  // their neighbours across other such faces (build_unknown_images); all those cells meet an
  // unknown set. One rectangle per unknown component: its bounds in the slice's plane, widened
  // by a millionth of the box's diagonal. The rectangles of the slices new to the field are
  // walked down the lazy BSP from its root; the older ones only within the cells the new planes
  // reopened (the cells meeting them were all built before, and only reopened ones are missing
  // now): walking them all from the root every update took the arrangement of a 597-slice
  // sector sweep (growth_table.py --sweep-online 600 --sweep-online-fov) to 135 ms per update
  // by its end, against 5-14 ms this way.
  std::vector<std::vector<Vec3>> unknown_rectangles;  // of field->slices()[0, rectangle_slices)
  std::size_t rectangle_slices = 0;

  void build_unknown_cells() {
    if (!arrangement->on_demand()) return;
    arrangement->construct_reopened_cells_meeting(unknown_rectangles);
    const double widen = 1e-6 * box.diagonal();
    const std::size_t old_count = unknown_rectangles.size();
    const std::vector<PreparedSlice>& slices = field->slices();
    for (std::size_t k = rectangle_slices; k < slices.size(); ++k) {
      const PreparedSlice& slice = slices[k];
      for (const UnknownComponent& component : slice.unknown) {
        Vec2 lo = Vec2::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
        for (const Ring2& ring : component.rings)
          for (const Vec2& p : ring) {
            lo = lo.cwiseMin(p);
            hi = hi.cwiseMax(p);
          }
        lo.array() -= widen;
        hi.array() += widen;
        const auto corner = [&](double x, double y) {
          return Vec3(slice.origin + x * slice.u + y * slice.v);
        };
        unknown_rectangles.push_back({corner(lo.x(), lo.y()), corner(hi.x(), lo.y()),
                                      corner(hi.x(), hi.y()), corner(lo.x(), hi.y())});
      }
    }
    rectangle_slices = slices.size();
    arrangement->construct_cells_meeting(
        {unknown_rectangles.begin() + static_cast<std::ptrdiff_t>(old_count),
         unknown_rectangles.end()});
  }

  bool thin_plate_field() const { return options.engine.field == FieldKind::thin_plate; }

  // The slices of list[first, end) that are not duplicates, prepared in parallel (each depends
  // on itself alone; the first error in slice order is thrown). `index` names the first in errors.
  std::vector<PreparedSlice> prepare(const std::vector<Entry>& list, std::size_t first,
                                     std::size_t index) const {
    std::vector<const Entry*> kept;
    for (std::size_t k = first; k < list.size(); ++k)
      if (!list[k].duplicate) kept.push_back(&list[k]);
    std::vector<PreparedSlice> prepared(kept.size());
    std::vector<std::exception_ptr> errors(kept.size());
    tbb::parallel_for(std::size_t{0}, kept.size(), [&](std::size_t k) {
      try {
        prepared[k] = prepare_slice(kept[k]->slice, index + k, material_ids, box);
      } catch (...) {
        errors[k] = std::current_exception();
      }
    });
    for (const std::exception_ptr& error : errors)
      if (error) std::rethrow_exception(error);
    return prepared;
  }

  // Rebuilds everything for `list` (first update, removals, a grown box, a new material).
  void rebuild(const std::vector<Entry>& list, ReconstructionStats& stats) {
    const SliceSet set = slice_set_of(list);
    box = set.effective_bounds();
    material_ids = materials_of(list);
    depth = options.engine.max_depth > 0 ? options.engine.max_depth : default_depth(box);
    octree = OctreeOptions{};
    octree.max_depth = depth;
    octree.smoothing_iterations = options.engine.smoothing_iterations >= 0
                                      ? options.engine.smoothing_iterations
                                  : thin_plate_field() ? 0
                                                       : kMeanValueSmoothing;
    contours = ContourKeys{};
    region_samples.clear();
    contour_slices = 0;
    sampled_tags_current = false;
    if (thin_plate_field())
      rebuild_thin_plate(list, stats);
    else
      rebuild_mean_value(list, stats);
    built = true;
  }

  // The slices of `list` that are not duplicates, prepared; those the thin-plate field holds
  // already, prepared with the same materials and box, are copied from it: only the truncations
  // change when an organ's extent outgrows them, which a live sweep does often.
  std::vector<PreparedSlice> prepare_for_rebuild(const std::vector<Entry>& list) const {
    std::unordered_map<int, const PreparedSlice*> held;
    if (thin_plate && thin_plate_ids.size() == thin_plate->slices().size() &&
        thin_plate_materials == material_ids && thin_plate_box.min == box.min &&
        thin_plate_box.max == box.max)
      for (std::size_t k = 0; k < thin_plate_ids.size(); ++k)
        held[thin_plate_ids[k]] = &thin_plate->slices()[k];
    std::vector<const Entry*> kept;
    for (const Entry& e : list)
      if (!e.duplicate) kept.push_back(&e);
    std::vector<PreparedSlice> prepared(kept.size());
    std::vector<std::exception_ptr> errors(kept.size());
    tbb::parallel_for(std::size_t{0}, kept.size(), [&](std::size_t k) {
      try {
        const auto found = held.find(kept[k]->id);
        prepared[k] = found != held.end() ? *found->second
                                          : prepare_slice(kept[k]->slice, k, material_ids, box);
      } catch (...) {
        errors[k] = std::current_exception();
      }
    });
    for (const std::exception_ptr& error : errors)
      if (error) std::rethrow_exception(error);
    return prepared;
  }

  // The ids of `list`'s entries that are not duplicates, in order.
  static std::vector<int> slice_ids(const std::vector<Entry>& list, std::size_t first) {
    std::vector<int> ids;
    for (std::size_t k = first; k < list.size(); ++k)
      if (!list[k].duplicate) ids.push_back(list[k].id);
    return ids;
  }

  void rebuild_thin_plate(const std::vector<Entry>& list, ReconstructionStats& stats) {
    arrangement.reset();
    field.reset();
    ThinPlateOptions tp;
    tp.shadow_casters = shadow_casters();
    tp.own_grids = options.engine.own_grids;
    Stopwatch clock;
    std::vector<PreparedSlice> prepared = prepare_for_rebuild(list);
    const int materials = static_cast<int>(material_ids.size());
    thin_plate_boxes = material_boxes(prepared, materials);
    auto rebuilt = std::make_unique<ThinPlateField>(box, make_grid(box, depth).cell_size, materials,
                                                    tp, thin_plate_boxes);
    // A rebuild on the same grid (a removal, a material's extent outgrown) starts its solve from
    // the last field: far fewer iterations than from the closing value. It keeps the last
    // field's sampled solution too, so that the octree's rows stay current where the solve does
    // not move it (ThinPlateOptions::resample_tolerance) if the octree's grid is the same.
    const bool started = thin_plate && rebuilt->start_from(*thin_plate);
    sampled_tags_current = started && sampled_box.min == box.min && sampled_box.max == box.max &&
                           sampled.grid.depth == depth;
    thin_plate = std::move(rebuilt);
    thin_plate_ids.clear();
    thin_plate->add_slices(std::move(prepared));
    thin_plate_ids = slice_ids(list, 0);
    thin_plate_materials = material_ids;
    thin_plate_box = box;
    stats.data_s += clock.seconds();
  }

  // Adds the data of list[first, end) to the thin-plate field. A material whose extent they
  // grow (truncation_extent of it) has its truncation grown first (ThinPlateField::
  // grow_boxes), so that every slice's data have the truncation a one-shot reconstruction
  // gives them; false, and the caller rebuilds, where that is not possible (or where an organ
  // outgrew the grid of its own).
  bool add_thin_plate_slices(const std::vector<Entry>& list, std::size_t first,
                             ReconstructionStats& stats) {
    Stopwatch clock;
    std::vector<PreparedSlice> added = prepare(list, first, thin_plate->slices().size());
    std::vector<Box3> boxes = material_boxes(added, static_cast<int>(material_ids.size()));
    for (std::size_t m = 0; m < boxes.size(); ++m) {
      boxes[m].min = boxes[m].min.cwiseMin(thin_plate_boxes[m].min);
      boxes[m].max = boxes[m].max.cwiseMax(thin_plate_boxes[m].max);
    }
    if (!thin_plate->grow_boxes(boxes)) return false;
    thin_plate_boxes = std::move(boxes);
    thin_plate->add_slices(std::move(added));
    const std::vector<int> ids = slice_ids(list, first);
    thin_plate_ids.insert(thin_plate_ids.end(), ids.begin(), ids.end());
    stats.data_s += clock.seconds();
    return true;
  }

  void rebuild_mean_value(const std::vector<Entry>& list, ReconstructionStats& stats) {
    Stopwatch clock;
    thin_plate.reset();
    arrangement = std::make_unique<Arrangement>(box, options.engine.cells_on_demand);
    field = std::make_unique<CellField>(*arrangement, static_cast<int>(material_ids.size()));
    {
      // The planes are inserted in order.
      std::vector<PreparedSlice> prepared = prepare(list, 0, 0);
      Progress progress("arrangement", prepared.size());
      std::size_t done = 0;
      std::vector<int> split_faces;  // all faces are new to the field below
      for (PreparedSlice& slice : prepared) {
        insert(std::move(slice), split_faces);
        progress.update(++done);
      }
    }
    unknown_rectangles.clear();
    rectangle_slices = 0;
    build_unknown_cells();
    stats.arrangement_s += clock.seconds();
    stats.arrangement_serial_s += arrangement->take_serial_seconds();
    clock.reset();
    field->refresh({});
    stats.face_images_s += clock.seconds();
    ++generation;
    cell_generation.assign(arrangement->cell_count(), generation);
  }

  // The steps of Reconstructor::update, in its order (docs/engine.md, "Online engine").
  UpdateStats unchanged_update() const;
  std::vector<Entry> next_entries(UpdateStats& out) const;
  void apply_changes(tbb::task_arena& arena, std::vector<Entry> next, bool use_thin_plate,
                     UpdateStats& out);
  void update_thin_plate(const std::vector<Entry>& next, bool full, UpdateStats& out);
  void update_zone(const std::vector<Entry>& next, UpdateStats& out);
  void add_new_contours(tbb::task_arena& arena, bool use_thin_plate);
  void evaluate_points(tbb::task_arena& arena, bool use_thin_plate, const std::vector<Vec3>& points,
                       double* values, std::uint64_t* tags, ReconstructionStats& stats);
  void sample(tbb::task_arena& arena, bool use_thin_plate, ReconstructionStats& stats);
  void extract_meshes(tbb::task_arena& arena, ReconstructionStats& stats);
  void finish_stats(UpdateStats& out, double total_s);

  // Whether row `n` of `field` (a thin-plate sample) still holds what the field evaluates at its
  // vertex: no solve since its evaluation (its tag) changed a node its interpolation reads.
  bool thin_plate_row_current(const SampledField& field, std::size_t n) const {
    int i = 0, j = 0, k = 0;
    grid_unkey(field.keys[n], i, j, k);
    return thin_plate->changed_at(field.grid.position(i, j, k)) <= field.row_tags[n];
  }

  // Per update, for the stats: the points evaluated and their seconds, and the cells of the
  // last batch's points (kept to reuse the buffer).
  std::size_t evaluations = 0;
  double evaluation_seconds = 0.0;
  std::vector<int> point_cells;
};

Reconstructor::Reconstructor(ReconstructorOptions options) : state_(std::make_unique<State>()) {
  state_->options = std::move(options);
}
Reconstructor::~Reconstructor() = default;
Reconstructor::Reconstructor(Reconstructor&&) noexcept = default;
Reconstructor& Reconstructor::operator=(Reconstructor&&) noexcept = default;

int Reconstructor::add_slice(LabeledSlice slice) {
  State& s = *state_;
  SliceSet single;
  single.slices.push_back(slice);
  if (const Status valid = validate_slice_set(single, "added slice"); !valid)
    throw std::invalid_argument(valid.message());
  State::Entry entry{s.next_id, std::move(slice), false};
  const double scale = std::max(
      1.0, s.options.bounds ? s.options.bounds->diagonal() : single.effective_bounds().diagonal());
  auto check = [&](const State::Entry& other) {
    if (other.duplicate || !same_plane(other.slice, entry.slice, scale)) return;
    if (identical_slices(other.slice, entry.slice)) {
      entry.duplicate = true;
      return;
    }
    throw std::invalid_argument("added slice lies in the plane of slice " +
                                std::to_string(other.id) +
                                " but its content differs; remove that slice first or merge both "
                                "into one slice");
  };
  for (const State::Entry& e : s.entries)
    if (std::find(s.pending_removes.begin(), s.pending_removes.end(), e.id) ==
        s.pending_removes.end())
      check(e);
  for (const State::Entry& e : s.pending_adds) check(e);
  s.pending_adds.push_back(std::move(entry));
  return s.next_id++;
}

bool Reconstructor::remove_slice(int id) {
  State& s = *state_;
  const auto pending = std::find_if(s.pending_adds.begin(), s.pending_adds.end(),
                                    [&](const State::Entry& e) { return e.id == id; });
  if (pending != s.pending_adds.end()) {
    s.pending_adds.erase(pending);
    return true;
  }
  const bool present = std::any_of(s.entries.begin(), s.entries.end(),
                                   [&](const State::Entry& e) { return e.id == id; });
  if (!present ||
      std::find(s.pending_removes.begin(), s.pending_removes.end(), id) != s.pending_removes.end())
    return false;
  s.pending_removes.push_back(id);
  return true;
}

UpdateStats Reconstructor::update() {
  State& s = *state_;
  // The field's device first: a device that cannot be used leaves the engine as it was.
  const bool thin_plate = s.thin_plate_field();
  if (!s.evaluator && !thin_plate) s.evaluator = make_field_evaluator(s.options.engine.device);
  if (s.built && s.pending_adds.empty() && s.pending_removes.empty()) return s.unchanged_update();
  Stopwatch total_clock;
  UpdateStats out;
  std::vector<State::Entry> next = s.next_entries(out);
  // Every stage runs in one arena of engine.threads threads: the arrangement, the face images
  // and the completion as well as the evaluation, the octree and the mesher.
  tbb::task_arena arena(s.options.engine.threads > 0 ? s.options.engine.threads
                                                     : tbb::task_arena::automatic);
  s.apply_changes(arena, std::move(next), thin_plate, out);
  s.add_new_contours(arena, thin_plate);
  s.sample(arena, thin_plate, out.step);
  s.extract_meshes(arena, out.step);
  s.finish_stats(out, total_clock.seconds());
  return out;
}

// Nothing queued: the totals as they are, with no time spent.
UpdateStats Reconstructor::State::unchanged_update() const {
  UpdateStats out;
  out.step = totals;
  out.step.arrangement_s = out.step.face_images_s = out.step.field_s = out.step.smoothing_s =
      out.step.mesh_s = out.step.total_s = out.step.completion_s = out.step.evaluation_s =
          out.step.arrangement_serial_s = out.step.data_s = out.step.solve_s = 0.0;
  out.step.solve_iterations = 0;
  out.step.field_evaluations = 0;
  return out;
}

// The entries after this update: the kept ones in their order, then the queued additions.
std::vector<Reconstructor::State::Entry> Reconstructor::State::next_entries(
    UpdateStats& out) const {
  std::vector<Entry> next;
  for (const Entry& e : entries)
    if (std::find(pending_removes.begin(), pending_removes.end(), e.id) == pending_removes.end())
      next.push_back(e);
  out.slices_removed = entries.size() - next.size();
  out.slices_added = pending_adds.size();
  for (const Entry& e : pending_adds) next.push_back(e);
  // A removed slice may have hidden a duplicate: the first of identical slices is the one in.
  for (std::size_t i = 0; i < next.size(); ++i) {
    next[i].duplicate = false;
    for (std::size_t j = 0; j < i && !next[i].duplicate; ++j)
      next[i].duplicate = !next[j].duplicate && identical_slices(next[j].slice, next[i].slice);
  }
  return next;
}

// The arrangement and the field's data for `next`: the zone of the new planes, or everything
// when a slice went, a material came or the box grew. Should that fail, the engine is put back
// as it was before the update (the queued changes dropped) and the error passed on.
void Reconstructor::State::apply_changes(tbb::task_arena& arena, std::vector<Entry> next,
                                         bool use_thin_plate, UpdateStats& out) {
  ReconstructionStats& stats = out.step;
  const std::vector<Entry> previous = entries;
  try {
    arena.execute([&] {
      const Box3 next_box = slice_set_of(next).effective_bounds();
      const bool full = !built || out.slices_removed > 0 || materials_of(next) != material_ids ||
                        next_box.min != box.min || next_box.max != box.max;
      if (use_thin_plate) {
        update_thin_plate(next, full, out);
        return;
      }
      if (full) {
        rebuild(next, stats);
        out.full_rebuild = true;
        out.cells_changed = arrangement->cell_count();
      } else {
        update_zone(next, out);
      }
      stats.completion_s = field->completion_seconds();
      stats.unknown_triangles = field->unknown_triangle_count();
      stats.cell_groups = field->group_count();
      stats.completed_slices = field->recompleted_slice_count();
    });
    entries = std::move(next);
  } catch (...) {
    pending_adds.clear();
    pending_removes.clear();
    built = false;
    if (!previous.empty() || options.bounds) {
      ReconstructionStats ignored;
      arena.execute([&] { rebuild(previous, ignored); });
    }
    entries = previous;
    throw;
  }
  pending_adds.clear();
  pending_removes.clear();
}

// An added slice changes only its data; the solve starts from the last solution.
void Reconstructor::State::update_thin_plate(const std::vector<Entry>& next, bool full,
                                             UpdateStats& out) {
  ReconstructionStats& stats = out.step;
  if (full || !add_thin_plate_slices(next, entries.size(), stats)) {
    rebuild(next, stats);
    out.full_rebuild = true;
  }
  const ThinPlateSolveStats solved = thin_plate->solve();
  stats.solve_s = solved.solve_s;
  stats.solve_iterations = static_cast<std::size_t>(solved.iterations);
  stats.solve_nodes = solved.nodes;
}

// The zone of the new planes: the cells they split, the faces they cut and the completions
// those change are marked with a new generation; the rest keeps its sampled values.
void Reconstructor::State::update_zone(const std::vector<Entry>& next, UpdateStats& out) {
  ReconstructionStats& stats = out.step;
  Stopwatch clock;
  std::vector<int> changed, split_faces;
  for (std::size_t k = entries.size(); k < next.size(); ++k) {
    if (next[k].duplicate) continue;
    const std::vector<int> cells = insert(
        prepare_slice(next[k].slice, field->slices().size(), material_ids, box), split_faces);
    changed.insert(changed.end(), cells.begin(), cells.end());
  }
  build_unknown_cells();  // around the new unknown sets, and in the reopened cells
  std::sort(changed.begin(), changed.end());
  changed.erase(std::unique(changed.begin(), changed.end()), changed.end());
  stats.arrangement_s = clock.seconds();
  stats.arrangement_serial_s = arrangement->take_serial_seconds();
  clock.reset();
  std::sort(split_faces.begin(), split_faces.end());
  split_faces.erase(std::unique(split_faces.begin(), split_faces.end()), split_faces.end());
  // On demand: no face was split (crossed cells were reopened, their crossed faces
  // retired); the images of new faces are built when their cells are.
  if (arrangement->on_demand()) field->release_images(arrangement->take_retired_faces());
  const std::vector<int> completion_changed = field->refresh(split_faces);
  stats.face_images_s = clock.seconds();
  ++generation;
  cell_generation.resize(arrangement->cell_count(), generation);
  std::vector<char> marked(arrangement->cell_count(), 0);
  for (const std::vector<int>* list :
       std::initializer_list<const std::vector<int>*>{&changed, &completion_changed})
    for (const int c : *list)
      if (!marked[static_cast<std::size_t>(c)]) {
        marked[static_cast<std::size_t>(c)] = 1;
        cell_generation[static_cast<std::size_t>(c)] = generation;
        ++out.cells_changed;
      }
}

// Contour vertices refine the octree; contour segments fix the smoothing next to them. The new
// slices' keys and samples in parallel (each depends on its slice alone), then merged: the keys
// pairwise in a tree (a union of sorted sets: the same whatever the order), the samples in
// slice order. In the arena too: contour_keys sorts in parallel, and --threads bounds every
// stage.
void Reconstructor::State::add_new_contours(tbb::task_arena& arena, bool use_thin_plate) {
  const std::vector<PreparedSlice>& slices =
      use_thin_plate ? thin_plate->slices() : field->slices();
  const Grid grid = make_grid(box, octree.max_depth);
  arena.execute([&] {
    const std::size_t first = contour_slices, count = slices.size() - first;
    std::vector<ContourKeys> keys(count);
    std::vector<std::vector<RegionSample>> samples(count);
    tbb::parallel_for(std::size_t{0}, count, [&](std::size_t k) {
      keys[k] = contour_keys(grid, octree, contour_segments(slices[first + k]));
      add_thin_region_samples(slices[first + k], grid.cell_size, samples[k]);
    });
    for (std::size_t width = 1; width < count; width *= 2)
      tbb::parallel_for(std::size_t{0}, (count + 2 * width - 1) / (2 * width), [&](std::size_t i) {
        const std::size_t a = 2 * width * i;
        if (a + width < count) merge_contour_keys(keys[a], keys[a + width]);
      });
    if (count > 0) merge_contour_keys(contours, keys[0]);
    for (const std::vector<RegionSample>& more : samples)
      region_samples.insert(region_samples.end(), more.begin(), more.end());
    contour_slices = slices.size();
  });
}

// The octree asks only for vertices the kept field has no valid value for: all are evaluated
// (in parallel) and tagged with their cell and this update.
void Reconstructor::State::evaluate_points(tbb::task_arena& arena, bool use_thin_plate,
                                           const std::vector<Vec3>& points, double* values,
                                           std::uint64_t* tags, ReconstructionStats& stats) {
  if (use_thin_plate) {
    const Stopwatch evaluation_clock;
    arena.execute([&] { thin_plate->evaluate(points, values); });
    std::fill(tags, tags + points.size(), std::uint64_t{thin_plate->generation()});
    evaluations += points.size();
    evaluation_seconds += evaluation_clock.seconds();
    return;
  }
  if (arrangement->on_demand()) {
    // The cells of the points are built first (their regions refined in parallel, the cells
    // made in a fixed order), then evaluated in parallel like those of the whole arrangement.
    Stopwatch clock;
    std::vector<char> inside(points.size());
    for (std::size_t n = 0; n < points.size(); ++n)
      inside[n] = (points[n].array() > box.min.array()).all() &&
                  (points[n].array() < box.max.array()).all();
    arena.execute([&] { point_cells = arrangement->construct_cells(points, inside); });
    // Values are tagged with the cells built now and this update (their generation).
    cell_generation.resize(arrangement->cell_count(), generation);
    stats.arrangement_s += clock.seconds();
    stats.arrangement_serial_s += arrangement->take_serial_seconds();
    clock.reset();
    arena.execute([&] { field->refresh({}); });  // the images of the new cells' faces
    stats.face_images_s += clock.seconds();
  } else {
    point_cells.resize(points.size());
  }
  // The native CPU or an OpenCL device (options.engine.device; field_evaluator.hpp).
  const Stopwatch evaluation_clock;
  arena.execute([&] {
    evaluator->evaluate(*field, points, point_cells.data(), arrangement->on_demand(), values);
  });
  for (std::size_t n = 0; n < points.size(); ++n)
    tags[n] = evaluation_tag(point_cells[n], generation);
  evaluations += points.size();
  evaluation_seconds += evaluation_clock.seconds();
}

// The octree's samples of the field, smoothed. The last field is kept: its rows whose cells did
// not change still hold their values. A thin-plate row is current while no solve since its
// evaluation changed the sampled solution it interpolates (ThinPlateField::changed_at). In the
// arena: the octree's parallel loops use the same threads as the evaluation.
void Reconstructor::State::sample(tbb::task_arena& arena, bool use_thin_plate,
                                  ReconstructionStats& stats) {
  evaluations = 0;
  evaluation_seconds = 0.0;
  const BatchEvaluator evaluate = [&](const std::vector<Vec3>& points, double* values,
                                      std::uint64_t* tags) {
    evaluate_points(arena, use_thin_plate, points, values, tags, stats);
  };
  Stopwatch clock;
  octree_workspace.previous_valid.clear();
  if (sampled_tags_current) {
    std::vector<char>& valid = octree_workspace.previous_valid;
    valid.assign(sampled.keys.size(), 0);
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, valid.size(), 4096),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t n = r.begin(); n < r.end(); ++n)
                            valid[n] = use_thin_plate
                                           ? thin_plate_row_current(sampled, n)
                                           : tag_current(sampled.row_tags[n], cell_generation);
                        });
    });
  }
  sampled_box = box;
  octree_workspace.previous = std::move(sampled);
  arena.execute([&] {
    const int function_count = static_cast<int>(material_ids.size()) + 1;
    sampled = sample_field(box, function_count, evaluate, contours, region_samples, octree,
                           octree_workspace);
  });
  sampled_tags_current = true;
  stats.smoothing_s = sampled.smoothing_seconds;
  stats.field_s = clock.seconds() - stats.smoothing_s;
  stats.field_evaluations = evaluations;
  stats.evaluation_s = evaluation_seconds;
}

// One mesh per material: the zero set of its function against the others (mesher.hpp).
void Reconstructor::State::extract_meshes(tbb::task_arena& arena, ReconstructionStats& stats) {
  Stopwatch clock;
  std::vector<TriangleMesh> meshes;
  arena.execute([&] {
    meshes = extract_label_surfaces(sampled);
    // The thin-plate field is cubic between the grid's vertices: its meshes' vertices are moved
    // onto its zero set, and their edges split where the surface bends (zero_set_refinement.hpp).
    if (!thin_plate_field() || !options.refine_meshes) return;
    const PointFieldEvaluator evaluate = [&](const std::vector<Vec3>& points, double* values) {
      thin_plate->evaluate(points, values);
    };
    for (std::size_t m = 1; m <= meshes.size(); ++m) {
      ZeroSetRefinement refinement;
      refinement.material = static_cast<int>(m);
      refinement.function_count = sampled.function_count;
      refinement.cell_size_mm = sampled.grid.cell_size;
      refine_on_zero_set(meshes[m - 1], refinement, evaluate);
    }
  });
  mesh = MeshSet{};
  for (std::size_t m = 1; m <= material_ids.size(); ++m) {
    const int id = material_ids[m - 1];
    mesh.meshes.push_back({id, label_name(id), std::move(meshes[m - 1])});
    stats.triangles[id] = mesh.meshes.back().mesh.triangles.size();
  }
  stats.mesh_s = clock.seconds();
}

// The update's counts, and the totals over every update.
void Reconstructor::State::finish_stats(UpdateStats& out, double total_s) {
  ReconstructionStats& stats = out.step;
  stats.slices = entries.size();
  if (arrangement) {
    stats.cells =
        arrangement->on_demand() ? arrangement->built_cell_count() : arrangement->cell_count();
    if (out.full_rebuild && arrangement->on_demand()) out.cells_changed = stats.cells;
    stats.faces = arrangement->face_count();
  }
  stats.snapped_vertices = sampled.snapped_vertices;
  stats.depth = depth;
  stats.total_s = total_s;

  totals.arrangement_s += stats.arrangement_s;
  totals.arrangement_serial_s += stats.arrangement_serial_s;
  totals.face_images_s += stats.face_images_s;
  totals.field_s += stats.field_s;
  totals.smoothing_s += stats.smoothing_s;
  totals.mesh_s += stats.mesh_s;
  totals.total_s += stats.total_s;
  totals.completion_s += stats.completion_s;
  totals.evaluation_s += stats.evaluation_s;
  totals.data_s += stats.data_s;
  totals.solve_s += stats.solve_s;
  totals.solve_iterations += stats.solve_iterations;
  totals.solve_nodes = stats.solve_nodes;
  totals.field_evaluations += stats.field_evaluations;
  totals.slices = stats.slices;
  totals.cells = stats.cells;
  totals.faces = stats.faces;
  totals.snapped_vertices = stats.snapped_vertices;
  totals.unknown_triangles = stats.unknown_triangles;
  totals.cell_groups = stats.cell_groups;
  totals.completed_slices += stats.completed_slices;
  totals.depth = stats.depth;
  totals.triangles = stats.triangles;
}

const MeshSet& Reconstructor::mesh() const { return state_->mesh; }

std::vector<int> Reconstructor::slice_ids() const {
  std::vector<int> ids;
  for (const State::Entry& e : state_->entries) ids.push_back(e.id);
  return ids;
}

SliceSet Reconstructor::slice_set() const {
  SliceSet set = state_->slice_set_of(state_->entries);
  if (state_->built) set.bounds = state_->box;
  return set;
}

std::size_t Reconstructor::slice_count() const { return state_->entries.size(); }

const ReconstructionStats& Reconstructor::totals() const { return state_->totals; }

std::vector<std::pair<Vec3, std::vector<double>>> Reconstructor::sampled_field() const {
  const SampledField& f = state_->sampled;
  const std::size_t fc = static_cast<std::size_t>(f.function_count);
  std::vector<std::size_t> rows;  // those the last update read (the field keeps older ones)
  for (std::size_t r = 0; r < f.keys.size(); ++r)
    if (f.row_pass[r] == f.pass) rows.push_back(r);
  std::sort(rows.begin(), rows.end(),
            [&](std::size_t a, std::size_t b) { return f.keys[a] < f.keys[b]; });
  std::vector<std::pair<Vec3, std::vector<double>>> out;
  out.reserve(rows.size());
  for (const std::size_t r : rows) {
    int i, j, k;
    grid_unkey(f.keys[r], i, j, k);
    out.emplace_back(
        f.grid.position(i, j, k),
        std::vector<double>(f.values.begin() + static_cast<std::ptrdiff_t>(r * fc),
                            f.values.begin() + static_cast<std::ptrdiff_t>((r + 1) * fc)));
  }
  return out;
}

}  // namespace sonoshape::recon
