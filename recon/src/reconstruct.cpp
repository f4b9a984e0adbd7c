#include "sonoshape/recon/reconstruct.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "arrangement.hpp"
#include "cell_field.hpp"
#include "mesher.hpp"
#include "octree_field.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::recon {

MeshSet reconstruct(const SliceSet& set, const ReconstructionOptions& options,
                    ReconstructionStats* stats_out) {
  ReconstructionStats stats;
  Stopwatch total_clock;
  const std::vector<int> material_ids = set.material_ids();
  const int material_count = static_cast<int>(material_ids.size());
  const Box3 box = set.effective_bounds();

  Stopwatch clock;
  const std::vector<PreparedSlice> slices = prepare_slices(set, material_ids);
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
  clock.reset();
  const SampledField sampled =
      sample_field(box, fc, evaluate, contour_points, contour_segments, octree);
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
  stats.depth = octree.max_depth;
  stats.total_s = total_clock.seconds();
  if (stats_out) *stats_out = stats;
  return out;
}

}  // namespace sonoshape::recon
