#include "sonoshape/recon/reconstruct.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <optional>

#include "arrangement.hpp"
#include "mean_value.hpp"
#include "cell_field.hpp"
#include "mesher.hpp"
#include "octree_field.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::recon {
namespace {

// Points of every region too thin for grid cells of `cell_size`: its interior point and a
// lattice of half the cell size over it (see snap_thin_regions).
std::vector<RegionSample> thin_region_samples(const std::vector<PreparedSlice>& slices, double cell_size) {
  std::vector<RegionSample> samples;
  for (const PreparedSlice& slice : slices) {
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
  return samples;
}

}  // namespace

MeshSet reconstruct(const SliceSet& set, const ReconstructionOptions& options,
                    ReconstructionStats* stats_out) {
  ReconstructionStats stats;
  Stopwatch total_clock;
  const std::vector<int> material_ids = set.material_ids();
  const int material_count = static_cast<int>(material_ids.size());
  const Box3 box = set.effective_bounds();

  Stopwatch clock;
  const std::vector<PreparedSlice> slices = prepare_slices(set, material_ids, box);
  Arrangement arrangement(box);
  {
    Progress progress("arrangement", slices.size());
    for (std::size_t s = 0; s < slices.size(); ++s) {
      const PreparedSlice& slice = slices[s];
      const Vec3 normal = slice.u.cross(slice.v);
      arrangement.insert_plane(normal, -normal.dot(slice.origin), static_cast<int>(s));
      progress.update(s + 1);
    }
  }
  stats.arrangement_s = clock.seconds();

  clock.reset();
  const CellField field(arrangement, slices, material_count);
  stats.face_images_s = clock.seconds();
  stats.completion_s = field.completion_seconds();
  stats.unknown_triangles = field.unknown_triangle_count();
  stats.cell_groups = field.group_count();

  // Contour vertices refine the octree; contour segments fix the smoothing next to them.
  std::vector<Vec3> contour_points;
  std::vector<std::pair<Vec3, Vec3>> contour_segments;
  for (const PreparedSlice& slice : slices)
    for (const auto& rings : slice.rings_by_material)
      for (const Ring2& ring : rings)
        for (std::size_t i = 0; i < ring.size(); ++i) {
          const Vec3 a = slice.origin + ring[i].x() * slice.u + ring[i].y() * slice.v;
          const Vec2& q = ring[(i + 1) % ring.size()];
          contour_points.push_back(a);
          contour_segments.emplace_back(a, slice.origin + q.x() * slice.u + q.y() * slice.v);
        }

  tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
  const int fc = field.function_count();
  const BatchEvaluator evaluate = [&](const std::vector<Vec3>& points, double* values) {
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 64),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t n = r.begin(); n < r.end(); ++n)
                            field.evaluate(points[n], values + n * static_cast<std::size_t>(fc));
                        });
    });
  };
  OctreeOptions octree;
  octree.max_depth = options.max_depth > 0 ? options.max_depth : default_depth(box);
  octree.smoothing_iterations = options.smoothing_iterations;
  const std::vector<RegionSample> samples =
      thin_region_samples(slices, make_grid(box, octree.max_depth).cell_size);
  clock.reset();
  const SampledField sampled =
      sample_field(box, fc, evaluate, contour_points, contour_segments, samples, octree);
  stats.smoothing_s = sampled.smoothing_seconds;
  stats.field_s = clock.seconds() - stats.smoothing_s;

  clock.reset();
  std::vector<TriangleMesh> meshes = extract_label_surfaces(sampled);
  MeshSet out;
  for (int m = 1; m <= material_count; ++m) {
    const int id = material_ids[static_cast<std::size_t>(m - 1)];
    out.meshes.push_back({id, set.label_name(id), std::move(meshes[static_cast<std::size_t>(m - 1)])});
    stats.triangles[id] = out.meshes.back().mesh.triangles.size();
  }
  stats.mesh_s = clock.seconds();

  stats.slices = set.slices.size();
  stats.cells = arrangement.cell_count();
  stats.faces = arrangement.face_count();
  stats.field_evaluations = sampled.evaluations;
  stats.snapped_vertices = sampled.snapped_vertices;
  stats.depth = octree.max_depth;
  stats.total_s = total_clock.seconds();
  if (stats_out) *stats_out = stats;
  return out;
}

}  // namespace sonoshape::recon
