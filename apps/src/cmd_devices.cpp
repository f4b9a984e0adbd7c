// `sonoshape devices`: the acquisition devices attached to this machine, each usable mode as
// the option a user pastes into `sonoshape scan`. One section per kind of device: V4L2 frame
// grabbers (--source v4l2:...); trackers add their section after it.
#include <CLI/CLI.hpp>
#include <iostream>

#include "commands.hpp"

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

}  // namespace

CommandRunner add_devices_command(CLI::App&) {
  return [] {
    print_frame_grabbers(std::cout);
    return 0;
  };
}

}  // namespace sonoshape::apps
