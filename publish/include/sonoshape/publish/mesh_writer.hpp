#pragma once
// Mesh files: binary little-endian PLY, OBJ and OFF.
#include <filesystem>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::publish {

/// Writes one mesh; the format follows the extension (.ply binary little-endian, .obj, .off).
Status write_mesh(const TriangleMesh& mesh, const std::filesystem::path& path);

/// Writes a mesh set as slices.md says: with one label and `out` ending in .ply/.obj/.off, that
/// file; otherwise `out` is a directory (created) holding `label_<id>.ply` for every label.
/// Returns the paths written.
Result<std::vector<std::filesystem::path>> write_mesh_set(const MeshSet& meshes,
                                                          const std::filesystem::path& out);

}  // namespace sonoshape::publish
