#pragma once
// OpenCL devices for the field evaluation (kernels/cl/*.cl): listing platforms and devices,
// parsing `--device`, and a device with its built program. The kernel source is compiled into
// the binary; a device builds it at first use and caches the program binary under
// $XDG_CACHE_HOME/sonoshape/opencl (~/.cache when unset), keyed by device, driver and source.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace sonoshape::kernels {

/// Whether this build has OpenCL (SONOSHAPE_WITH_OPENCL).
bool have_opencl();

/// One OpenCL device as `sonoshape devices` lists it.
struct DeviceInfo {
  int platform = 0, device = 0;  ///< indices as in --device opencl:PLATFORM:DEVICE
  std::string platform_name, device_name, version;
  bool gpu = false;
  bool fp64 = false;  ///< cl_khr_fp64: required by the field kernels
  std::size_t global_memory_bytes = 0;
  unsigned compute_units = 0;
};

/// Every device of every platform (empty without an ICD or platform). `error` (optional) gets
/// why nothing could be listed, empty when the platforms were read.
std::vector<DeviceInfo> list_devices(std::string* error = nullptr);

/// Where the field is evaluated, as `--device` and SONOSHAPE_DEVICE spell it:
/// "cpu" (native, the default), "opencl" (first fp64 device: a GPU if any), "opencl:P:D" (that
/// platform and device), "auto" (an fp64 GPU if one is present, else cpu).
struct DeviceSpec {
  enum class Kind { cpu, opencl, automatic };
  Kind kind = Kind::cpu;
  int platform = -1, device = -1;  ///< -1: not named
  std::string text() const;
};

/// Parses a device spec; throws sonoshape::Error naming the spec and the accepted forms.
DeviceSpec parse_device_spec(const std::string& text);

/// The spec a command uses: `option` when given (non-empty), else SONOSHAPE_DEVICE, else "cpu".
DeviceSpec device_spec_from(const std::string& option);

/// The field of a CellField as flat arrays (recon/src/device_field.cpp packs them; the record
/// layouts are those of kernels/cl/field.cl). `generation` changes whenever any array does: a
/// device uploads the arrays again only then. With `extends_previous`, the first
/// `points_clean` doubles of `points`, `chain_clean` nodes of the chain trees and `parts_clean`
/// ints of `parts` are those of the previous generation, and only the rest is copied (an online
/// update appends the images it rebuilt); the other arrays are copied whole.
struct FieldData {
  std::uint64_t generation = 0;
  bool extends_previous = false;
  std::size_t points_clean = 0, chain_clean = 0, parts_clean = 0;
  int function_count = 2;  ///< at most kMaxFunctions
  double on_face_height = 0;
  std::vector<double> frames;         ///< 12 per arrangement plane: origin, u, v, unit normal
  std::vector<int> faces;             ///< 8 per face (field.cl FACE_INTS)
  std::vector<int> parts;             ///< 5 per part (PART_INTS)
  std::vector<double> points;         ///< 2 per point of the face images
  std::vector<double> chain_d;        ///< 18 per chain-tree node (CHAIN_DOUBLES)
  std::vector<int> chain_i;           ///< 4 per chain-tree node
  std::vector<int> triangle_faces;    ///< 4 per face (TFACE_INTS)
  std::vector<double> triangles;      ///< 6 per completed unknown triangle
  std::vector<double> corner_values;  ///< 3 x function_count per triangle
  std::vector<double> tnode_d;        ///< 3 per triangle-tree node
  std::vector<int> tnode_i;           ///< 4 per triangle-tree node
  std::vector<double> moments;        ///< triangle_moment_stride per triangle-tree node
  std::vector<int> pairs;             ///< (a, b) per moment pair
  std::vector<double> kernel_table;   ///< 7 per moment pair
  std::vector<double> truncation;     ///< per degree 0..12
};
constexpr int kMaxFunctions = 16;

/// A batch of points for the device: `positions` (3 per point, mm), each point's cell as the
/// (first, count) of its faces in `face_list`.
struct FieldBatch {
  std::vector<double> positions;
  std::vector<std::uint32_t> point_faces;
  std::vector<int> face_list;
  std::size_t size() const { return positions.size() / 3; }
};

/// A device chosen and opened, with the field program built. Thread-compatible: one thread
/// at a time enqueues work (the evaluator that owns it).
class Device {
 public:
  ~Device();
  Device(const Device&) = delete;
  Device& operator=(const Device&) = delete;
  const DeviceInfo& info() const;
  /// True when the program came from the cache (no compilation at this start).
  bool program_from_cache() const;
  /// Evaluates `batch` against `field` (uploaded again only when its generation changed):
  /// `values` gets function_count doubles per point, `status` one per point (0: done; 1: the
  /// point lies on a face, 2: a value is not finite; the caller evaluates those itself).
  /// Throws sonoshape::Error on an OpenCL failure.
  void evaluate_field(const FieldData& field, const FieldBatch& batch, double* values, int* status);
  /// Seconds spent uploading the field and running the kernel since the device was opened, and
  /// the bytes of field arrays copied to the device.
  double upload_seconds() const;
  std::size_t uploaded_bytes() const;
  double kernel_seconds() const;
  struct Impl;  ///< OpenCL objects (opencl.cpp)

 private:
  friend std::unique_ptr<Device> open_device(const DeviceSpec& spec);
  explicit Device(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Opens the device `spec` names (kind opencl or automatic) and builds the field program.
/// Returns null for automatic when no fp64 GPU is present (the native path then). Throws
/// sonoshape::Error when OpenCL is not built or has no platform, the named device does not
/// exist, lacks cl_khr_fp64, or the program does not build (with the build log).
std::unique_ptr<Device> open_device(const DeviceSpec& spec);

/// The embedded OpenCL C source of the field kernels (kernels/cl/field.cl).
const char* field_kernel_source();

}  // namespace sonoshape::kernels
