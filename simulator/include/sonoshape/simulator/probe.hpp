#pragma once
// The simulator renders the images of acquisition's probe (acquisition/probe.hpp): these names
// let the simulator's code say Probe within sonoshape::sim. New code outside the simulator names
// acq:: directly.
#include "sonoshape/acquisition/probe.hpp"

namespace sonoshape::sim {

using acq::convex_probe_geometry;
using acq::linear_probe_geometry;
using acq::parse_probe_type;
using acq::Probe;
using acq::probe_fields;
using acq::probe_from_fields;
using acq::ProbeGeometry;
using acq::ProbeType;
using acq::to_string;

}  // namespace sonoshape::sim
