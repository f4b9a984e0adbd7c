#pragma once
// The LABEL:PATH[:NAME] mesh arguments of `sonoshape slice`, `evaluate` and `simulate`.
#include <charconv>
#include <filesystem>
#include <string>

#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/mesh_slicer.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::apps {

struct MeshSpec {
  int label = 1;
  std::filesystem::path path;
  std::string name;  ///< from the argument, else the file's stem
};

/// Parses "LABEL:PATH" or "LABEL:PATH:NAME" (the name follows the last ':' after the path).
inline Result<MeshSpec> parse_mesh_spec(const std::string& text, const std::string& option) {
  const auto fail = [&](const std::string& why) {
    return Status::error(option + " '" + text + "': " + why +
                         " (expected LABEL:PATH or LABEL:PATH:NAME, e.g. 1:liver.obj:liver)");
  };
  const std::size_t colon = text.find(':');
  if (colon == std::string::npos) return fail("no label");
  MeshSpec spec;
  const char* first = text.data();
  const auto [end, ec] = std::from_chars(first, first + colon, spec.label);
  if (ec != std::errc() || end != first + colon || spec.label < 1)
    return fail("the label must be a positive integer");
  std::string rest = text.substr(colon + 1);
  const std::size_t name_colon = rest.rfind(':');
  if (name_colon != std::string::npos) {
    spec.name = rest.substr(name_colon + 1);
    rest = rest.substr(0, name_colon);
  }
  if (rest.empty()) return fail("no path");
  spec.path = rest;
  if (spec.name.empty()) spec.name = spec.path.stem().string();
  return spec;
}

/// Parses the argument and reads its mesh, oriented outwards.
inline Result<LabeledMesh> load_mesh_spec(const std::string& text, const std::string& option) {
  const auto spec = parse_mesh_spec(text, option);
  if (!spec) return spec.status();
  auto mesh = read_mesh(spec->path);
  if (!mesh) return mesh.status();
  orient_outward(*mesh);
  return LabeledMesh{spec->label, spec->name, std::move(*mesh)};
}

}  // namespace sonoshape::apps
