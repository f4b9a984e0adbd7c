// OpenCL through the Khronos C++ bindings (opencl-clhpp-headers): the ICD loader finds the
// platforms (PoCL on CPUs, a GPU vendor's driver).
#define CL_HPP_ENABLE_EXCEPTIONS
#define CL_HPP_TARGET_OPENCL_VERSION 120
#define CL_HPP_MINIMUM_OPENCL_VERSION 120
#include "sonoshape/kernels/opencl.hpp"

#include <unistd.h>

#include <CL/opencl.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::kernels {

bool have_opencl() { return true; }

namespace {

std::string cl_error(const cl::Error& e) {
  return std::string(e.what()) + " (OpenCL error " + std::to_string(e.err()) + ")";
}

std::vector<cl::Platform> platforms_or_empty() {
  std::vector<cl::Platform> platforms;
  try {
    cl::Platform::get(&platforms);
  } catch (const cl::Error&) {
    platforms.clear();  // no ICD or no platform: CL_PLATFORM_NOT_FOUND_KHR
  }
  return platforms;
}

DeviceInfo describe(const cl::Platform& platform, const cl::Device& device, int p, int d) {
  DeviceInfo info;
  info.platform = p;
  info.device = d;
  info.platform_name = platform.getInfo<CL_PLATFORM_NAME>();
  info.device_name = device.getInfo<CL_DEVICE_NAME>();
  info.version = device.getInfo<CL_DEVICE_VERSION>();
  info.gpu = (device.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_GPU) != 0;
  info.fp64 = device.getInfo<CL_DEVICE_EXTENSIONS>().find("cl_khr_fp64") != std::string::npos;
  info.global_memory_bytes = static_cast<std::size_t>(device.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>());
  info.compute_units = device.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
  // Strings from drivers end in a NUL byte.
  for (std::string* s : {&info.platform_name, &info.device_name, &info.version})
    while (!s->empty() && s->back() == '\0') s->pop_back();
  return info;
}

std::filesystem::path cache_dir() {
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  if (xdg != nullptr && *xdg != '\0') return std::filesystem::path(xdg) / "sonoshape" / "opencl";
  const char* home = std::getenv("HOME");
  if (home != nullptr && *home != '\0')
    return std::filesystem::path(home) / ".cache" / "sonoshape" / "opencl";
  return {};
}

// No -cl-mad-enable or -cl-fast-relaxed-math: the kernels repeat the CPU's rounding (field.cl).
constexpr const char* kBuildOptions = "-cl-std=CL1.2";

}  // namespace

struct Device::Impl {
  DeviceInfo info;
  cl::Context context;
  cl::Device device;
  cl::CommandQueue queue;
  cl::Program program;
  cl::Kernel kernel;
  bool from_cache = false;
  std::size_t local_size = 1;  // work-group size of every launch
  // One buffer per field array, grown by half again when too small, so that an update that
  // appends to an array copies only what it appended.
  struct Slot {
    cl::Buffer buffer;
    std::size_t capacity_bytes = 0;
  };
  std::vector<Slot> slots;
  bool uploaded = false;
  std::uint64_t uploaded_generation = 0;
  std::size_t uploaded_bytes = 0;
  double upload_s = 0, kernel_s = 0;

  // Brings slot `k` to `data`, whose first `clean` elements the buffer already holds.
  template <typename T>
  void sync(std::size_t k, const std::vector<T>& data, std::size_t clean) {
    Slot& slot = slots[k];
    const std::size_t bytes = std::max<std::size_t>(1, data.size()) * sizeof(T);
    if (slot.capacity_bytes < bytes) {
      slot.capacity_bytes = std::max<std::size_t>(4096, bytes + bytes / 2);
      slot.buffer = cl::Buffer(context, CL_MEM_READ_ONLY, slot.capacity_bytes);
      clean = 0;
    }
    if (data.size() <= clean) return;
    const std::size_t offset = clean * sizeof(T), size = data.size() * sizeof(T) - offset;
    queue.enqueueWriteBuffer(slot.buffer, CL_FALSE, offset, size,
                             reinterpret_cast<const char*>(data.data()) + offset);
    uploaded_bytes += size;
  }
};

Device::Device(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Device::~Device() = default;
const DeviceInfo& Device::info() const { return impl_->info; }
bool Device::program_from_cache() const { return impl_->from_cache; }
double Device::upload_seconds() const { return impl_->upload_s; }
double Device::kernel_seconds() const { return impl_->kernel_s; }
std::size_t Device::uploaded_bytes() const { return impl_->uploaded_bytes; }

std::vector<DeviceInfo> list_devices(std::string* error) {
  std::vector<DeviceInfo> out;
  const std::vector<cl::Platform> platforms = platforms_or_empty();
  if (platforms.empty() && error != nullptr)
    *error =
        "no OpenCL platform (install an ICD: Debian pocl-opencl-icd for the CPU, or the GPU's "
        "driver)";
  for (std::size_t p = 0; p < platforms.size(); ++p) {
    std::vector<cl::Device> devices;
    try {
      platforms[p].getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error&) {
      continue;  // a platform with no device
    }
    for (std::size_t d = 0; d < devices.size(); ++d)
      out.push_back(describe(platforms[p], devices[d], static_cast<int>(p), static_cast<int>(d)));
  }
  return out;
}

namespace {

// The device `spec` names; null for automatic without an fp64 GPU.
std::unique_ptr<Device::Impl> choose(const DeviceSpec& spec) {
  const std::vector<cl::Platform> platforms = platforms_or_empty();
  if (platforms.empty()) {
    if (spec.kind == DeviceSpec::Kind::automatic) return nullptr;
    throw Error(
        "--device " + spec.text() +
        ": no OpenCL platform (install an ICD: Debian pocl-opencl-icd, or the GPU's driver), "
        "or use --device cpu");
  }
  std::vector<DeviceInfo> infos = list_devices();
  const DeviceInfo* chosen = nullptr;
  if (spec.platform >= 0) {
    for (const DeviceInfo& info : infos)
      if (info.platform == spec.platform && info.device == spec.device) chosen = &info;
    if (chosen == nullptr)
      throw Error("--device " + spec.text() +
                  ": no such OpenCL device; `sonoshape devices` lists them");
    if (!chosen->fp64)
      throw Error("--device " + spec.text() + ": " + chosen->device_name +
                  " has no double precision (cl_khr_fp64), which the field kernels need; choose "
                  "another device (`sonoshape devices`) or --device cpu");
  } else {
    for (const DeviceInfo& info : infos)  // a GPU first, then any
      if (info.fp64 && info.gpu && chosen == nullptr) chosen = &info;
    if (chosen == nullptr && spec.kind == DeviceSpec::Kind::automatic) return nullptr;
    for (const DeviceInfo& info : infos)
      if (info.fp64 && chosen == nullptr) chosen = &info;
    if (chosen == nullptr)
      throw Error("--device " + spec.text() +
                  ": no OpenCL device with double precision (cl_khr_fp64); use --device cpu");
  }
  auto impl = std::make_unique<Device::Impl>();
  impl->info = *chosen;
  std::vector<cl::Device> devices;
  platforms[static_cast<std::size_t>(chosen->platform)].getDevices(CL_DEVICE_TYPE_ALL, &devices);
  impl->device = devices[static_cast<std::size_t>(chosen->device)];
  return impl;
}

// The program from the cache when a binary for this device, driver and source is there; else
// built from source and its binary stored (a failure to store only costs the next start).
void build_program(Device::Impl& impl) {
  const std::string source = field_kernel_source();
  const std::string driver = impl.device.getInfo<CL_DRIVER_VERSION>();
  const std::size_t key =
      std::hash<std::string>{}(impl.info.platform_name + "\n" + impl.info.device_name + "\n" +
                               driver + "\n" + kBuildOptions + "\n" + source);
  std::ostringstream name;
  name << std::hex << key << ".bin";
  const std::filesystem::path dir = cache_dir();
  const std::filesystem::path file = dir.empty() ? std::filesystem::path() : dir / name.str();
  if (!file.empty()) {
    std::ifstream in(file, std::ios::binary);
    if (in) {
      std::vector<unsigned char> binary((std::istreambuf_iterator<char>(in)),
                                        std::istreambuf_iterator<char>());
      try {
        impl.program = cl::Program(impl.context, {impl.device}, cl::Program::Binaries{binary});
        impl.program.build({impl.device}, kBuildOptions);
        impl.from_cache = true;
        return;
      } catch (const cl::Error&) {
        // A stale or foreign binary: build from source below.
      }
    }
  }
  impl.program = cl::Program(impl.context, source);
  try {
    impl.program.build({impl.device}, kBuildOptions);
  } catch (const cl::Error& e) {
    throw Error("OpenCL: the field kernels do not build on " + impl.info.device_name + ": " +
                cl_error(e) + "\n" + impl.program.getBuildInfo<CL_PROGRAM_BUILD_LOG>(impl.device) +
                "\nplease report this with `sonoshape devices`; --device cpu works meanwhile");
  }
  if (file.empty()) return;
  try {
    const auto binaries = impl.program.getInfo<CL_PROGRAM_BINARIES>();
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    const std::filesystem::path tmp = file.string() + ".tmp" + std::to_string(::getpid());
    {
      std::ofstream out(tmp, std::ios::binary);
      out.write(reinterpret_cast<const char*>(binaries.at(0).data()),
                static_cast<std::streamsize>(binaries.at(0).size()));
    }
    std::filesystem::rename(tmp, file, ec);
  } catch (const std::exception& e) {
    log_warning(std::string("OpenCL: could not cache the program binary: ") + e.what());
  }
}

template <typename T>
cl::Buffer upload(const cl::Context& context, const std::vector<T>& data,
                  cl_mem_flags flags = CL_MEM_READ_ONLY) {
  // OpenCL has no empty buffers: one element stands in.
  static const T zero{};
  const void* host = data.empty() ? &zero : data.data();
  const std::size_t bytes = std::max<std::size_t>(1, data.size()) * sizeof(T);
  return cl::Buffer(context, flags | CL_MEM_COPY_HOST_PTR, bytes, const_cast<void*>(host));
}

}  // namespace

std::unique_ptr<Device> open_device(const DeviceSpec& spec) {
  if (spec.kind == DeviceSpec::Kind::cpu) return nullptr;
  std::unique_ptr<Device::Impl> impl = choose(spec);
  if (!impl) return nullptr;
  try {
    impl->context = cl::Context(impl->device);
    impl->queue = cl::CommandQueue(impl->context, impl->device);
    build_program(*impl);
    impl->kernel = cl::Kernel(impl->program, "evaluate_field");
    // 64 work-items (two warps on NVIDIA, vector lanes on PoCL) where the kernel allows it.
    const std::size_t most = impl->kernel.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(impl->device);
    impl->local_size = std::max<std::size_t>(1, std::min<std::size_t>(64, most));
  } catch (const cl::Error& e) {
    throw Error("OpenCL: cannot open " + impl->info.device_name + ": " + cl_error(e));
  }
  return std::unique_ptr<Device>(new Device(std::move(impl)));
}

void Device::evaluate_field(const FieldData& field, const FieldBatch& batch, double* values,
                            int* status) {
  Impl& d = *impl_;
  const std::size_t n = batch.size();
  if (n == 0) return;
  if (field.function_count > kMaxFunctions)
    throw Error("OpenCL field: " + std::to_string(field.function_count) +
                " functions, the kernels take at most " + std::to_string(kMaxFunctions) +
                "; use --device cpu");
  using Clock = std::chrono::steady_clock;
  try {
    auto start = Clock::now();
    if (!d.uploaded || d.uploaded_generation != field.generation) {
      // Appended arrays keep their clean prefix when this generation extends the uploaded one.
      const bool extend =
          d.uploaded && field.extends_previous && field.generation == d.uploaded_generation + 1;
      const std::size_t points_clean = extend ? field.points_clean : 0;
      const std::size_t chain_clean = extend ? field.chain_clean : 0;
      const std::size_t parts_clean = extend ? field.parts_clean : 0;
      d.slots.resize(15);
      d.sync(0, field.frames, 0);
      d.sync(1, field.faces, 0);
      d.sync(2, field.parts, parts_clean);
      d.sync(3, field.points, points_clean);
      d.sync(4, field.chain_d, chain_clean * 18);
      d.sync(5, field.chain_i, chain_clean * 4);
      d.sync(6, field.triangle_faces, 0);
      d.sync(7, field.triangles, 0);
      d.sync(8, field.corner_values, 0);
      d.sync(9, field.tnode_d, 0);
      d.sync(10, field.tnode_i, 0);
      d.sync(11, field.moments, 0);
      d.sync(12, field.pairs, d.uploaded ? field.pairs.size() : 0);  // constants: once
      d.sync(13, field.kernel_table, d.uploaded ? field.kernel_table.size() : 0);
      d.sync(14, field.truncation, d.uploaded ? field.truncation.size() : 0);
      d.uploaded = true;
      d.uploaded_generation = field.generation;
    }
    const cl::Buffer positions = upload(d.context, batch.positions);
    const cl::Buffer point_faces = upload(d.context, batch.point_faces);
    const cl::Buffer face_list = upload(d.context, batch.face_list);
    cl::Buffer out(d.context, CL_MEM_WRITE_ONLY,
                   n * static_cast<std::size_t>(field.function_count) * sizeof(double));
    cl::Buffer out_status(d.context, CL_MEM_WRITE_ONLY, n * sizeof(int));
    auto middle = Clock::now();
    d.upload_s += std::chrono::duration<double>(middle - start).count();
    cl::Kernel& k = d.kernel;
    cl_uint arg = 0;
    k.setArg(arg++, static_cast<cl_uint>(n));
    k.setArg(arg++, static_cast<cl_int>(field.function_count));
    k.setArg(arg++, field.on_face_height);
    k.setArg(arg++, positions);
    k.setArg(arg++, point_faces);
    k.setArg(arg++, face_list);
    for (const Impl::Slot& slot : d.slots) k.setArg(arg++, slot.buffer);
    k.setArg(arg++, out);
    k.setArg(arg++, out_status);
    // One work-group size for every batch: PoCL compiles the kernel again for each local size,
    // and left to choose, it chose one per global size (an online scan spent minutes compiling).
    const std::size_t local = d.local_size;
    d.queue.enqueueNDRangeKernel(k, cl::NullRange, cl::NDRange((n + local - 1) / local * local),
                                 cl::NDRange(local));
    d.queue.enqueueReadBuffer(out, CL_FALSE, 0,
                              n * static_cast<std::size_t>(field.function_count) * sizeof(double),
                              values);
    d.queue.enqueueReadBuffer(out_status, CL_FALSE, 0, n * sizeof(int), status);
    d.queue.finish();
    d.kernel_s += std::chrono::duration<double>(Clock::now() - middle).count();
  } catch (const cl::Error& e) {
    throw Error("OpenCL field on " + d.info.device_name + ": " + cl_error(e));
  }
}

}  // namespace sonoshape::kernels
