#pragma once
// Where the field of a batch of grid vertices is evaluated: the native CPU (CellField on TBB's
// threads) or an OpenCL device (kernels/), behind one interface the octree's BatchEvaluator
// calls. Both give the same values (the device's kernels repeat the CPU's rounding).
#include <memory>
#include <string>
#include <vector>

#include "cell_field.hpp"

namespace sonoshape::recon {

class FieldEvaluator {
 public:
  virtual ~FieldEvaluator() = default;
  /// f_l at `points` into `values` (function_count() doubles per point), each point's cell into
  /// `cells` (-1 outside the box). `cells_known`: `cells` already holds them (an on-demand
  /// arrangement's construct_cell, with the field refreshed since); otherwise they are located.
  /// Call from one thread; the work runs on the calling TBB arena or the device. Throws
  /// GeometryError as CellField::evaluate_in, sonoshape::Error on a device failure.
  virtual void evaluate(const CellField& field, const std::vector<Vec3>& points, int* cells,
                        bool cells_known, double* values) = 0;
  /// "cpu" or the device's name.
  virtual std::string name() const = 0;
};

/// The evaluator `device` names (kernels::parse_device_spec: cpu, opencl[:P:D], auto; auto
/// without an fp64 GPU is the CPU). Throws sonoshape::Error when the device cannot be used.
std::unique_ptr<FieldEvaluator> make_field_evaluator(const std::string& device);

}  // namespace sonoshape::recon
