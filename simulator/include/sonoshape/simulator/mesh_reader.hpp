#pragma once
// Loading closed triangle meshes (OBJ, PLY ascii/binary, OFF, STL ascii/binary) as ground truth.
#include <filesystem>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::sim {

/// Reads a triangle mesh (polygons are fan-triangulated). STL corners with exactly equal
/// coordinates are welded into one vertex (no tolerance), and facets left without area by that
/// are dropped, so a closed STL reads as a closed indexed mesh. Fails with file and reason on
/// unreadable files, unsupported formats and out-of-range indices, and on files without faces
/// unless `allow_empty` (a reconstruction writes an empty mesh for a material that vanished).
Result<TriangleMesh> read_mesh(const std::filesystem::path& path, bool allow_empty = false);

/// Makes a closed mesh outward-oriented (reverses every triangle when its volume is negative).
void orient_outward(TriangleMesh& mesh);

}  // namespace sonoshape::sim
