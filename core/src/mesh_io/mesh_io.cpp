// The dispatcher of mesh_io.hpp: one table row per format, the file read or written whole here,
// the bytes parsed or made in the format's own source (formats.hpp).
#include "sonoshape/core/mesh_io.hpp"

#include <array>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <utility>

#include "formats.hpp"
#include "mesh_text.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/input_file.hpp"

namespace sonoshape {
namespace {

struct MeshFormat {
  std::string_view extension;                      // lower case, with the dot
  TriangleMesh (*read)(std::string_view bytes);    // throws InputError
  std::string (*write)(const TriangleMesh& mesh);  // null: read only
};

constexpr std::array<MeshFormat, 4> kFormats = {{
    {".obj", mesh_io::read_obj, mesh_io::obj_text},
    {".ply", mesh_io::read_ply, mesh_io::ply_bytes},
    {".off", mesh_io::read_off, mesh_io::off_text},
    {".stl", mesh_io::read_stl, nullptr},
}};

const MeshFormat* format_of(const std::filesystem::path& path) {
  const std::string extension = mesh_io::lower(path.extension().string());
  for (const MeshFormat& format : kFormats)
    if (format.extension == extension) return &format;
  return nullptr;
}

bool is_writable_mesh_path(const std::filesystem::path& path) {
  const MeshFormat* format = format_of(path);
  return format && format->write;
}

// Refuses indices a reader would reject, and those PLY's int32 cannot hold.
Status check_indices(const TriangleMesh& mesh, const std::filesystem::path& path) {
  for (std::size_t k = 0; k < mesh.triangles.size(); ++k)
    for (std::uint32_t index : mesh.triangles[k])
      if (index >= mesh.vertices.size() ||
          index > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max()))
        return Status::error("cannot write " + path.string() + ": triangle " + std::to_string(k) +
                             " uses vertex " + std::to_string(index) + " but the mesh has " +
                             std::to_string(mesh.vertices.size()) + " vertices");
  return Status::ok();
}

}  // namespace

Result<TriangleMesh> read_mesh(const std::filesystem::path& path, bool allow_empty) {
  Result<std::string> bytes = read_input_file(path, "mesh file");
  if (!bytes) return bytes.status();
  const std::string text = std::move(*bytes);
  const MeshFormat* format = format_of(path);
  if (!format)
    return Status::error("mesh file " + path.string() + ": unsupported extension '" +
                         mesh_io::lower(path.extension().string()) +
                         "' (use .obj, .ply, .off or .stl)");
  TriangleMesh mesh;
  try {
    mesh = format->read(text);
  } catch (const InputError& e) {
    return Status::error(e.message_in("mesh file " + path.string()));
  }
  if (mesh.triangles.empty() && !allow_empty)
    return Status::error("mesh file " + path.string() +
                         ": no faces (a closed mesh is needed; export the surface with its "
                         "triangles, not only its points)");
  return mesh;
}

void orient_outward(TriangleMesh& mesh) {
  if (signed_volume(mesh) >= 0.0) return;
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
}

Status write_mesh(const TriangleMesh& mesh, const std::filesystem::path& path) {
  if (!is_writable_mesh_path(path))
    return Status::error("cannot write " + path.string() + ": unknown mesh format \"" +
                         mesh_io::lower(path.extension().string()) +
                         "\"; use one of the supported extensions .ply, .obj or .off");
  if (Status indices = check_indices(mesh, path); !indices) return indices;
  const std::string bytes = format_of(path)->write(mesh);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out)
    return Status::error("cannot write " + path.string() + ": " + std::strerror(errno) +
                         "; check that the folder exists and is writable");
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.flush();
  // errno says which limit it was: ENOSPC (a full disk) or EFBIG (ulimit -f).
  if (!out)
    return Status::error("cannot write " + path.string() + ": " + std::strerror(errno) +
                         "; free disk space or raise the file-size limit, then run again");
  return Status::ok();
}

Result<std::vector<std::filesystem::path>> write_mesh_set(const MeshSet& meshes,
                                                          const std::filesystem::path& out) {
  if (is_writable_mesh_path(out)) {
    // A mesh-file name with several labels is a mistake, not a folder to create.
    if (meshes.meshes.size() != 1)
      return Status::error("cannot write " + out.string() +
                           ": it names one mesh file but the "
                           "reconstruction has " +
                           std::to_string(meshes.meshes.size()) +
                           " labels; give a directory to get one label_<id>.ply per label");
    if (Status status = write_mesh(meshes.meshes.front().mesh, out); !status) return status;
    return std::vector<std::filesystem::path>{out};
  }
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec || !std::filesystem::is_directory(out))
    return Status::error("cannot create the output directory " + out.string() + ": " +
                         (ec ? ec.message() : std::string("a file of that name exists")));
  std::vector<std::filesystem::path> written;
  for (const MeshSet::Entry& entry : meshes.meshes) {
    const std::filesystem::path path = out / ("label_" + std::to_string(entry.label) + ".ply");
    if (Status status = write_mesh(entry.mesh, path); !status) return status;
    written.push_back(path);
  }
  return written;
}

}  // namespace sonoshape
