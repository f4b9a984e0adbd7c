#pragma once
// Mesh files are read in core/ (mesh_io.hpp). These names keep the scan pipeline's sources that
// still say sim::read_mesh compiling while they move to their own module; new code includes
// sonoshape/core/mesh_io.hpp.
#include "sonoshape/core/mesh_io.hpp"

namespace sonoshape::sim {

using sonoshape::orient_outward;
using sonoshape::read_mesh;

}  // namespace sonoshape::sim
