#pragma once
// Mesh files: one dispatcher over one source per format (core/src/mesh_io/), chosen by the
// extension (any case). Read: OBJ, PLY (ascii, binary little-endian), OFF, STL (ascii, binary).
// Write: binary little-endian PLY, OBJ, OFF.
#include <filesystem>
#include <vector>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape {

/// Reads a triangle mesh (polygons are fan-triangulated). STL corners with exactly equal
/// coordinates are welded into one vertex (no tolerance), and facets left without area by that
/// are dropped, so a closed STL reads as a closed indexed mesh. Fails with file and reason on
/// unreadable files, unsupported formats and out-of-range indices, and on files without faces
/// unless `allow_empty` (a reconstruction writes an empty mesh for a material that vanished).
Result<TriangleMesh> read_mesh(const std::filesystem::path& path, bool allow_empty = false);

/// Makes a closed mesh outward-oriented (reverses every triangle when its volume is negative):
/// exporters disagree on the orientation of the meshes read as ground truth.
void orient_outward(TriangleMesh& mesh);

/// Writes one mesh; the format follows the extension (.ply binary little-endian, .obj, .off).
Status write_mesh(const TriangleMesh& mesh, const std::filesystem::path& path);

/// Writes a mesh set as slices.md says: with one label and `out` ending in .ply/.obj/.off, that
/// file; otherwise `out` is a directory (created) holding `label_<id>.ply` for every label.
/// Returns the paths written.
Result<std::vector<std::filesystem::path>> write_mesh_set(const MeshSet& meshes,
                                                          const std::filesystem::path& out);

}  // namespace sonoshape
