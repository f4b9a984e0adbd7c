// FieldEvaluator on the CPU and on an OpenCL device (kernels/cl/field.cl): the CellField is
// packed into flat arrays once per refresh and each batch of points goes to the device with its
// cells' face lists. Points the kernel leaves to the CPU (on a face; a non-finite value, which
// evaluate_in reports) and points outside the box are evaluated here.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "field_evaluator.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/kernels/opencl.hpp"

namespace sonoshape::recon {
namespace {

// Each point's cell, located in parallel (a thread's last cell is its next guess).
void locate_cells(const CellField& field, const std::vector<Vec3>& points, int* cells) {
  const CellField::Internals in = field.internals();
  const Box3& box = in.arrangement.box();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      int guess = -1;
                      for (std::size_t n = r.begin(); n < r.end(); ++n) {
                        const Vec3& p = points[n];
                        const bool inside = (p.array() > box.min.array()).all() &&
                                            (p.array() < box.max.array()).all();
                        cells[n] = inside ? guess = in.arrangement.locate(p, guess) : -1;
                      }
                    });
}

class CpuEvaluator final : public FieldEvaluator {
 public:
  void evaluate(const CellField& field, const std::vector<Vec3>& points, int* cells,
                bool cells_known, double* values) override {
    const std::size_t fc = static_cast<std::size_t>(field.function_count());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 64),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t n = r.begin(); n < r.end(); ++n)
                          cells[n] = cells_known
                                         ? field.evaluate_in(cells[n], points[n], values + n * fc)
                                         : field.evaluate(points[n], values + n * fc);
                      });
  }
  std::string name() const override { return "cpu"; }
};

// The CellField as kernels::FieldData (record layouts: kernels/cl/field.cl), kept across
// refreshes: the points and chain-tree nodes the field appended and the parts of the images it
// rebuilt are appended to the arrays (the device copies only those), the face records and the
// completed triangles are written again. A new field or a compaction packs everything anew.
class FieldPacker {
 public:
  // Brings `out` to `field`; returns true when it changed (a new generation).
  bool pack(const CellField& field, kernels::FieldData& out) {
    const CellField::Internals in = field.internals();
    if (&field == field_ && in.version == version_) return false;
    const bool extend = &field == field_ && in.compactions == compactions_;
    if (!extend) {
      out = kernels::FieldData{};
      face_generations_.clear();
      triangle_tree_tables(out.pairs, out.kernel_table, out.truncation);
    }
    out.extends_previous = extend;
    out.generation = ++generation_;
    out.function_count = field.function_count();
    out.on_face_height = in.on_face_height;
    out.points_clean = out.points.size();
    out.chain_clean = out.chain_i.size() / 4;
    out.parts_clean = out.parts.size();
    pack_frames(in, out);
    pack_points(in, out);
    pack_faces(in, out);
    pack_triangles(in, field.function_count(), out);
    field_ = &field;
    version_ = in.version;
    compactions_ = in.compactions;
    return true;
  }

 private:
  static void pack_frames(const CellField::Internals& in, kernels::FieldData& out) {
    out.frames.clear();
    for (const PlaneFrame& f : in.frames)
      for (const Vec3* v : {&f.origin, &f.u, &f.v, &f.unit_normal})
        out.frames.insert(out.frames.end(), {v->x(), v->y(), v->z()});
  }
  // The points and chain-tree nodes past those already packed.
  static void pack_points(const CellField::Internals& in, kernels::FieldData& out) {
    for (std::size_t k = out.points.size() / 2; k < in.points.size(); ++k)
      out.points.insert(out.points.end(), {in.points[k].x(), in.points[k].y()});
    for (std::size_t k = out.chain_i.size() / 4; k < in.tree_nodes.size(); ++k) {
      const ChainNode& n = in.tree_nodes[k];
      out.chain_d.insert(out.chain_d.end(), {n.centre.x(), n.centre.y(), n.radius_sq, n.area, n.m1x,
                                             n.m1y, n.m2xx, n.m2xy, n.m2yy});
      out.chain_d.insert(out.chain_d.end(), n.m3, n.m3 + 4);
      out.chain_d.insert(out.chain_d.end(), n.m4, n.m4 + 5);
      out.chain_i.insert(out.chain_i.end(),
                         {static_cast<int>(n.first), static_cast<int>(n.last), n.left, n.right});
    }
  }
  // The records of the faces built or rebuilt since the last pack, their parts appended.
  void pack_faces(const CellField::Internals& in, kernels::FieldData& out) {
    out.faces.resize(in.images.size() * 8);
    face_generations_.resize(in.images.size(), 0);
    auto add_parts = [&](const std::vector<FaceImage::Part>& parts) {
      for (const FaceImage::Part& p : parts)
        out.parts.insert(out.parts.end(),
                         {p.material, static_cast<int>(p.begin), static_cast<int>(p.count),
                          static_cast<int>(p.tree_root), static_cast<int>(p.tree_count)});
    };
    for (std::size_t f = 0; f < in.images.size(); ++f) {
      if (face_generations_[f] != 0 && face_generations_[f] == in.image_generations[f]) continue;
      face_generations_[f] = in.image_generations[f];
      const FaceImage& image = in.images[f];
      const int parts_begin = static_cast<int>(out.parts.size() / 5);
      add_parts(image.parts);
      const int unknown_begin = static_cast<int>(out.parts.size() / 5);
      add_parts(image.unknown_parts);
      const int record[8] = {image.frame,
                             static_cast<int>(image.polygon_begin),
                             static_cast<int>(image.polygon_count),
                             parts_begin,
                             static_cast<int>(image.parts.size()),
                             unknown_begin,
                             static_cast<int>(image.unknown_parts.size()),
                             0};
      std::copy(record, record + 8, out.faces.begin() + static_cast<std::ptrdiff_t>(f * 8));
    }
  }
  // The completed triangles, their values and every face's tree (rebuilt by each refresh).
  static void pack_triangles(const CellField::Internals& in, int function_count,
                             kernels::FieldData& out) {
    out.triangle_faces.clear();
    out.tnode_d.clear();
    out.tnode_i.clear();
    out.moments.clear();
    out.triangles.clear();
    const std::size_t stride = triangle_moment_stride(function_count);
    for (const FaceImage& image : in.images) {
      int tree_root = -1;
      if (image.triangle_tree != nullptr) {
        tree_root = static_cast<int>(out.tnode_i.size() / 4);
        const std::size_t nodes = tree_size(image.triangle_tree);
        for (std::size_t k = 0; k < nodes; ++k) {
          const TriangleNode& node = image.triangle_tree[k];
          out.tnode_d.insert(out.tnode_d.end(), {node.centre.x(), node.centre.y(), node.radius_sq});
          out.tnode_i.insert(
              out.tnode_i.end(),
              {static_cast<int>(node.first), static_cast<int>(node.last), node.left, node.right});
        }
        out.moments.insert(out.moments.end(), image.triangle_tree_moments,
                           image.triangle_tree_moments + nodes * stride);
      }
      out.triangle_faces.insert(out.triangle_faces.end(),
                                {static_cast<int>(image.triangle_begin),
                                 static_cast<int>(image.triangle_count), tree_root, tree_root});
    }
    for (const UnknownTriangle& t : in.triangles)
      for (const Vec2& c : t.corners) out.triangles.insert(out.triangles.end(), {c.x(), c.y()});
    out.corner_values = in.corner_values;
  }
  // Nodes of a triangle tree: its nodes are 0 .. the largest child index.
  static std::size_t tree_size(const TriangleNode* nodes) {
    std::size_t count = 1;
    std::vector<std::int32_t> stack{0};
    while (!stack.empty()) {
      const TriangleNode& node = nodes[stack.back()];
      stack.pop_back();
      if (node.left < 0) continue;
      count = std::max(count, static_cast<std::size_t>(std::max(node.left, node.right)) + 1);
      stack.insert(stack.end(), {node.left, node.right});
    }
    return count;
  }

  const CellField* field_ = nullptr;
  std::uint64_t version_ = 0, compactions_ = 0, generation_ = 0;
  std::vector<std::uint64_t> face_generations_;  // image generation of each packed face
};

class OpenClEvaluator final : public FieldEvaluator {
 public:
  explicit OpenClEvaluator(std::unique_ptr<kernels::Device> device) : device_(std::move(device)) {}
  ~OpenClEvaluator() override {
    log_debug("OpenCL field: pack " + std::to_string(pack_s_) + " s, batches " +
              std::to_string(batch_s_) + " s, upload " + std::to_string(device_->upload_seconds()) +
              " s (" + std::to_string(device_->uploaded_bytes() >> 20) + " MiB), kernel " +
              std::to_string(device_->kernel_seconds()) + " s, CPU fallback " +
              std::to_string(fallback_s_) + " s");
  }

  void evaluate(const CellField& field, const std::vector<Vec3>& points, int* cells,
                bool cells_known, double* values) override {
    if (field.function_count() > kernels::kMaxFunctions) {
      // The kernel keeps every function's weight in registers: more labels stay on the CPU.
      if (!warned_)
        log_warning("OpenCL field: " + std::to_string(field.function_count() - 1) +
                    " materials, the kernels take at most " +
                    std::to_string(kernels::kMaxFunctions - 1) + "; the field runs on the CPU");
      warned_ = true;
      return cpu_.evaluate(field, points, cells, cells_known, values);
    }
    if (!cells_known) locate_cells(field, points, cells);
    const CellField::Internals in = field.internals();
    Stopwatch clock;
    packer_.pack(field, data_);
    pack_s_ += clock.seconds();
    clock.reset();
    // The points inside the box go to the device, with their cells' face lists (the points come
    // in runs of one cell: a run shares its list).
    batch_.positions.clear();
    batch_.point_faces.clear();
    batch_.face_list.clear();
    device_points_.clear();
    int last_cell = -2;
    std::uint32_t first = 0, count = 0;
    for (std::size_t n = 0; n < points.size(); ++n) {
      if (cells[n] < 0) continue;
      if (cells[n] != last_cell) {
        const std::vector<int>& faces = in.arrangement.cell(cells[n]).faces;
        first = static_cast<std::uint32_t>(batch_.face_list.size());
        count = static_cast<std::uint32_t>(faces.size());
        batch_.face_list.insert(batch_.face_list.end(), faces.begin(), faces.end());
        last_cell = cells[n];
      }
      batch_.positions.insert(batch_.positions.end(),
                              {points[n].x(), points[n].y(), points[n].z()});
      batch_.point_faces.insert(batch_.point_faces.end(), {first, count});
      device_points_.push_back(n);
    }
    batch_s_ += clock.seconds();
    const std::size_t fc = static_cast<std::size_t>(field.function_count());
    device_values_.resize(device_points_.size() * fc);
    status_.assign(device_points_.size(), 0);
    device_->evaluate_field(data_, batch_, device_values_.data(), status_.data());
    for (std::size_t k = 0; k < device_points_.size(); ++k)
      std::copy_n(device_values_.data() + k * fc, fc, values + device_points_[k] * fc);
    clock.reset();
    // Outside the box, on a face, or a value to report: the CPU's evaluate_in.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 256),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t n = r.begin(); n < r.end(); ++n)
                          if (cells[n] < 0) field.evaluate_in(-1, points[n], values + n * fc);
                      });
    for (std::size_t k = 0; k < device_points_.size(); ++k)
      if (status_[k] != 0) {
        const std::size_t n = device_points_[k];
        field.evaluate_in(cells[n], points[n], values + n * fc);
      }
    fallback_s_ += clock.seconds();
  }
  std::string name() const override { return device_->info().device_name; }

 private:
  std::unique_ptr<kernels::Device> device_;
  FieldPacker packer_;
  kernels::FieldData data_;
  kernels::FieldBatch batch_;
  std::vector<std::size_t> device_points_;
  std::vector<double> device_values_;
  std::vector<int> status_;
  double pack_s_ = 0, batch_s_ = 0, fallback_s_ = 0;
  CpuEvaluator cpu_;
  bool warned_ = false;
};

}  // namespace

std::unique_ptr<FieldEvaluator> make_field_evaluator(const std::string& device) {
  const kernels::DeviceSpec spec = kernels::parse_device_spec(device);
  std::unique_ptr<kernels::Device> opened = kernels::open_device(spec);
  if (!opened) return std::make_unique<CpuEvaluator>();
  log_info("field on OpenCL device " + opened->info().device_name + " (" +
           opened->info().platform_name +
           (opened->program_from_cache() ? ", program from cache)" : ")"));
  return std::make_unique<OpenClEvaluator>(std::move(opened));
}

}  // namespace sonoshape::recon
