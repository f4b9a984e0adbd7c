// `sonoshape devices`: the acquisition devices attached to this machine, each usable mode as
// the option a user pastes into `sonoshape scan`. One section per kind of device: V4L2 frame
// grabbers (--source v4l2:...), USB trackers (--tracker usb:...), then the OpenCL devices the
// field can be evaluated on (--device opencl:P:D).
#include <CLI/CLI.hpp>
#include <iomanip>
#include <iostream>

#include "commands.hpp"
#include "sonoshape/apps/scan_sources.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/kernels/opencl.hpp"
#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::apps {
namespace {

// Each kind of frame source that has devices (V4L2 grabbers), from the source registry.
void print_frame_grabbers(std::ostream& out) {
  // A named registry: the loop reads its kinds, which a temporary would not outlive.
  const scan::SourceRegistry registry = scan_sources();
  for (const scan::SourceKind& kind : registry.kinds())
    if (kind.list_devices) kind.list_devices(out);
}

// Listed from the USB descriptors, without opening the units (a scan may be using one).
void print_trackers(std::ostream& out) {
  out << "Trackers (USB):\n";
  if (!tracking::have_libusb()) {
    out << "  not built (install libusb-1.0-0-dev and configure with -DSONOSHAPE_WITH_LIBUSB=ON)\n";
    return;
  }
  const auto found = tracking::find_trakstars();
  if (!found) {
    out << "  cannot list USB devices: " << found.message() << "\n";
    return;
  }
  if (found->empty())
    out << "  no trakSTAR / driveBAY found (USB vendor 0x21e2): check the cable and the power\n";
  for (const tracking::FoundTracker& tracker : *found)
    out << "  " << tracker.description << ":  --tracker " << tracker.spec << "\n";
}

// Every platform's devices, those without double precision marked unusable.
void print_opencl(std::ostream& out) {
  out << "Field evaluation (OpenCL):\n";
  std::string error;
  const auto devices = kernels::list_devices(&error);
  if (!error.empty()) out << "  " << error << "\n";
  for (const kernels::DeviceInfo& d : devices) {
    out << "  " << d.platform_name << " / " << d.device_name << " (" << (d.gpu ? "GPU" : "CPU")
        << ", " << d.compute_units << " compute units, " << std::fixed << std::setprecision(1)
        << static_cast<double>(d.global_memory_bytes) / (1024.0 * 1024.0 * 1024.0) << " GiB, "
        << d.version << "): ";
    if (d.fp64)
      out << "fp64, --device opencl:" << d.platform << ":" << d.device << "\n";
    else
      out << "no fp64 (cl_khr_fp64): cannot run the field kernels\n";
  }
  out << "  --device cpu: the native CPU path (the default)\n";
}

}  // namespace

const char* const kFieldHelp =
    "Interpolant between the slices: mean-value (the paper's mean-value blend of each label's "
    "indicator per arrangement cell) or thin-plate (a biharmonic fill of each label's in-plane "
    "signed distance on a grid; keeps thin structures crossed by far-apart slices whole; see "
    "docs/engine.md)";
const char* const kDefaultField = "thin-plate";

const char* const kSmoothingHelp =
    "Bi-Laplacian smoothing iterations of the octree's samples, 0 to 1000 (0: off). Default: 8 "
    "with the mean-value field, 0 with thin-plate (that field already minimises the "
    "bi-Laplacian energy)";

const char* const kDeviceHelp =
    "Where the mean-value field is evaluated (the thin-plate field solves on the CPU): cpu "
    "(native, the default), opencl (the first OpenCL device with "
    "fp64, a GPU if any), opencl:PLATFORM:DEVICE (`sonoshape devices` lists them) or auto (an fp64 "
    "GPU if present, else cpu). Default: $SONOSHAPE_DEVICE, else cpu";

std::string resolve_device(const std::string& option, const std::string& field) {
  const kernels::DeviceSpec spec = kernels::device_spec_from(option);
  if (spec.kind == kernels::DeviceSpec::Kind::cpu) return "cpu";
  if (field == "thin-plate") {
    if (!option.empty())
      throw Error("--device " + option +
                  ": only the mean-value field runs on an OpenCL device (the thin-plate field, "
                  "the default, solves on the CPU); add --field mean-value, or leave --device out");
    log_info("SONOSHAPE_DEVICE=" + spec.text() +
             " applies to --field mean-value; the thin-plate field solves on the CPU");
    return "cpu";
  }
  const auto device = kernels::open_device(spec);
  if (!device) {
    log_info("--device auto: no OpenCL GPU with fp64, the field runs on the CPU");
    return "cpu";
  }
  return "opencl:" + std::to_string(device->info().platform) + ":" +
         std::to_string(device->info().device);
}

CommandRunner add_devices_command(CLI::App&) {
  return [] {
    print_frame_grabbers(std::cout);
    print_trackers(std::cout);
    print_opencl(std::cout);
    return 0;
  };
}

}  // namespace sonoshape::apps
