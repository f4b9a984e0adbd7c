// A build without OpenCL (SONOSHAPE_WITH_OPENCL=OFF): every OpenCL device request fails with
// how to get one; the native CPU path is all there is.
#include "sonoshape/core/errors.hpp"
#include "sonoshape/kernels/opencl.hpp"

namespace sonoshape::kernels {

bool have_opencl() { return false; }

std::vector<DeviceInfo> list_devices(std::string* error) {
  if (error != nullptr)
    *error =
        "not built (install ocl-icd-opencl-dev and opencl-clhpp-headers and configure with "
        "-DSONOSHAPE_WITH_OPENCL=ON)";
  return {};
}

struct Device::Impl {};
Device::Device(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Device::~Device() = default;

std::unique_ptr<Device> open_device(const DeviceSpec& spec) {
  if (spec.kind != DeviceSpec::Kind::opencl) return nullptr;  // cpu, or auto without a GPU
  throw Error(
      "--device " + spec.text() +
      ": this build has no OpenCL (configure with -DSONOSHAPE_WITH_OPENCL=ON); use --device cpu");
}

const DeviceInfo& Device::info() const { throw Error("no OpenCL in this build"); }
bool Device::program_from_cache() const { return false; }
double Device::upload_seconds() const { return 0; }
double Device::kernel_seconds() const { return 0; }
std::size_t Device::uploaded_bytes() const { return 0; }
void Device::evaluate_field(const FieldData&, const FieldBatch&, double*, int*) {
  throw Error("no OpenCL in this build");
}

}  // namespace sonoshape::kernels
