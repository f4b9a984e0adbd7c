#pragma once
// Reading and writing slice sets: the JSON format (docs/formats/slices.md) and the `.csl`
// contour-slice format of the literature (docs/formats/csl.md).
#include <filesystem>
#include <string>

#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape {

/// Reads a slice set, choosing the format by extension (`.csl` or JSON otherwise). Every error of
/// slices.md is reported with the file, the slice index and the region index, and the fix.
/// Warnings (merged duplicate planes, projected vertices, ...) go to log_warning.
Result<SliceSet> read_slice_set(const std::filesystem::path& path);

/// Parses slice-set JSON text; `source_name` names the input in messages.
Result<SliceSet> parse_slice_set_json(const std::string& text, const std::string& source_name);
/// Parses `.csl` text; `source_name` names the input in messages.
Result<SliceSet> parse_csl(const std::string& text, const std::string& source_name);

/// Writes JSON (version 1). Fails with a message if the file cannot be written.
Status write_slice_set_json(const SliceSet& set, const std::filesystem::path& path);
/// Writes `.csl`. Fails for sets the format cannot hold (unknown regions or a fov).
Status write_csl(const SliceSet& set, const std::filesystem::path& path);
/// Writes by extension: `.csl` or JSON.
Status write_slice_set(const SliceSet& set, const std::filesystem::path& path);

/// Checks a slice set against every rule of slices.md (geometry, labels, overlaps, bounds).
Status validate_slice_set(const SliceSet& set, const std::string& source_name);

}  // namespace sonoshape
