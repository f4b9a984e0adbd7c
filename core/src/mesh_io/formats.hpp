#pragma once
// The mesh formats behind mesh_io.hpp's dispatcher, one source file each. Readers take the whole
// file and throw InputError naming the element (line, vertex, face, facet); read_mesh adds the
// file. Writers return the file's bytes.
#include <string>
#include <string_view>

#include "sonoshape/core/mesh.hpp"

namespace sonoshape::mesh_io {

TriangleMesh read_obj(std::string_view text);     // obj.cpp
std::string obj_text(const TriangleMesh& mesh);   // obj.cpp
TriangleMesh read_off(std::string_view text);     // off.cpp
std::string off_text(const TriangleMesh& mesh);   // off.cpp
TriangleMesh read_ply(std::string_view bytes);    // ply.cpp: ascii or binary little-endian
std::string ply_bytes(const TriangleMesh& mesh);  // ply.cpp: binary little-endian
TriangleMesh read_stl(std::string_view bytes);    // stl.cpp: ascii or binary

}  // namespace sonoshape::mesh_io
