#pragma once
// A scan's status in the form the publishers send (the mesh stream's and OpenIGTLink's STATUS).
#include "sonoshape/publish/mesh_stream.hpp"
#include "sonoshape/scan/report.hpp"

namespace sonoshape::apps {

/// The counters, stage times (ms), state and message of `status`.
publish::StatusReport report_of(const scan::ScanStatus& status);

}  // namespace sonoshape::apps
