#include "sonoshape/publish/mesh_writer.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>

namespace sonoshape::publish {
namespace {

std::string lower_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

bool is_mesh_extension(const std::string& ext) {
  return ext == ".ply" || ext == ".obj" || ext == ".off";
}

// Shortest text that reads back as the same double.
void append_number(std::string& out, double value) {
  std::array<char, 32> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  out.append(buffer.data(), ec == std::errc() ? end : buffer.data());
}

// Little-endian whatever the host: the header says binary_little_endian.
void append_u32_le(std::string& out, std::uint32_t bits) {
  for (int k = 0; k < 4; ++k) out.push_back(static_cast<char>((bits >> (8 * k)) & 0xffu));
}

void append_float_le(std::string& out, float value) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &value, sizeof bits);
  append_u32_le(out, bits);
}

std::string ply_bytes(const TriangleMesh& mesh) {
  std::string out = "ply\nformat binary_little_endian 1.0\ncomment written by sonoshape\n";
  out += "element vertex " + std::to_string(mesh.vertices.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  out += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  out += "property list uchar int vertex_indices\nend_header\n";
  out.reserve(out.size() + mesh.vertices.size() * 12 + mesh.triangles.size() * 13);
  for (const Vec3& p : mesh.vertices)
    for (int k = 0; k < 3; ++k) append_float_le(out, static_cast<float>(p[k]));
  for (const auto& t : mesh.triangles) {
    out.push_back(static_cast<char>(3));
    for (std::uint32_t index : t) append_u32_le(out, index);  // int32: indices checked < 2^31
  }
  return out;
}

std::string obj_text(const TriangleMesh& mesh) {
  std::string out = "# written by sonoshape\n";
  for (const Vec3& p : mesh.vertices) {
    out += "v ";
    append_number(out, p.x());
    out += ' ';
    append_number(out, p.y());
    out += ' ';
    append_number(out, p.z());
    out += '\n';
  }
  for (const auto& t : mesh.triangles)  // OBJ indices are 1-based
    out += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " +
           std::to_string(t[2] + 1) + "\n";
  return out;
}

std::string off_text(const TriangleMesh& mesh) {
  std::string out = "OFF\n" + std::to_string(mesh.vertices.size()) + " " +
                    std::to_string(mesh.triangles.size()) + " 0\n";
  for (const Vec3& p : mesh.vertices) {
    append_number(out, p.x());
    out += ' ';
    append_number(out, p.y());
    out += ' ';
    append_number(out, p.z());
    out += '\n';
  }
  for (const auto& t : mesh.triangles)
    out += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) +
           "\n";
  return out;
}

}  // namespace

Status write_mesh(const TriangleMesh& mesh, const std::filesystem::path& path) {
  const std::string ext = lower_extension(path);
  if (!is_mesh_extension(ext))
    return Status::error("cannot write " + path.string() + ": unknown mesh format \"" + ext +
                         "\"; use one of the supported extensions .ply, .obj or .off");
  for (std::size_t k = 0; k < mesh.triangles.size(); ++k)
    for (std::uint32_t index : mesh.triangles[k])
      if (index >= mesh.vertices.size() ||
          index > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max()))
        return Status::error("cannot write " + path.string() + ": triangle " + std::to_string(k) +
                             " uses vertex " + std::to_string(index) + " but the mesh has " +
                             std::to_string(mesh.vertices.size()) + " vertices");
  const std::string bytes = ext == ".ply"   ? ply_bytes(mesh)
                            : ext == ".obj" ? obj_text(mesh)
                                            : off_text(mesh);
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
  const std::string ext = lower_extension(out);
  if (is_mesh_extension(ext)) {
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

}  // namespace sonoshape::publish
