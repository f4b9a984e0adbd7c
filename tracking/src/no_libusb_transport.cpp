// The trakSTAR backend in a build without libusb (SONOSHAPE_WITH_LIBUSB off or libusb-1.0 not
// found): the source builds and its protocol is tested, but opening a tracker says why not.
#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::tracking {
namespace {

constexpr const char* kNoLibusb =
    "this sonoshape was built without libusb; install libusb-1.0-0-dev (scripts/install-deps) "
    "and configure with -DSONOSHAPE_WITH_LIBUSB=ON";

}  // namespace

bool have_libusb() { return false; }

BirdTransportOpener libusb_trakstar_opener(const TrakstarOptions&) {
  return [](std::string& error) -> std::unique_ptr<BirdTransport> {
    error = kNoLibusb;
    return nullptr;
  };
}

Result<std::vector<FoundTracker>> find_trakstars() { return Status::error(kNoLibusb); }

}  // namespace sonoshape::tracking
