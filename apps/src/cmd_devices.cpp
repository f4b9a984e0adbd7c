// `sonoshape devices`: the acquisition devices attached to this machine, each usable mode as
// the option a user pastes into `sonoshape scan`. One section per kind of device: V4L2 frame
// grabbers (--source v4l2:...), then USB trackers (--tracker usb:...).
#include <CLI/CLI.hpp>
#include <iostream>

#include "commands.hpp"
#include "sonoshape/tracking/trakstar_source.hpp"

#ifdef SONOSHAPE_WITH_V4L2
#include "sonoshape/acquisition/v4l2_devices.hpp"
#endif

namespace sonoshape::apps {
namespace {

void print_frame_grabbers(std::ostream& out) {
#ifdef SONOSHAPE_WITH_V4L2
  std::vector<std::string> unreadable;
  const auto devices =
      acq::list_v4l2_devices(*acq::system_v4l2_device(), "/sys/class/video4linux", &unreadable);
  out << acq::v4l2_devices_report(devices, unreadable);
#else
  out << "Frame grabbers (V4L2): not built (configure with -DSONOSHAPE_WITH_V4L2=ON on Linux)\n";
#endif
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

}  // namespace

CommandRunner add_devices_command(CLI::App&) {
  return [] {
    print_frame_grabbers(std::cout);
    print_trackers(std::cout);
    return 0;
  };
}

}  // namespace sonoshape::apps
