#pragma once
// Mesh files are written in core/ (mesh_io.hpp). These names keep the scan pipeline's sources
// that still say publish::write_mesh compiling while they move to their own module; new code
// includes sonoshape/core/mesh_io.hpp.
#include "sonoshape/core/mesh_io.hpp"

namespace sonoshape::publish {

using sonoshape::write_mesh;
using sonoshape::write_mesh_set;

}  // namespace sonoshape::publish
