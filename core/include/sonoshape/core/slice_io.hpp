#pragma once
// Reading and writing slice sets: the JSON format (docs/formats/slices.md) and the `.csl`
// contour-slice format of the literature (docs/formats/csl.md).
#include <filesystem>
#include <string>
#include <vector>

#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape {

/// Reads a slice set, choosing the format by extension (`.csl` or JSON otherwise). Every error of
/// slices.md is reported with the file, the slice index and the region index, and the fix.
/// What can be repaired (merged duplicate planes, projected vertices, ...) is, with one warning
/// per slice on stderr and a record in SliceSet::repairs; with `options.strict` it is an error.
Result<SliceSet> read_slice_set(const std::filesystem::path& path, const ReadOptions& options = {});

/// Parses slice-set JSON text; `source_name` names the input in messages.
Result<SliceSet> parse_slice_set_json(const std::string& text, const std::string& source_name,
                                      const ReadOptions& options = {});
/// Parses `.csl` text; `source_name` names the input in messages.
Result<SliceSet> parse_csl(const std::string& text, const std::string& source_name,
                           const ReadOptions& options = {});

/// Writes JSON (version 1). Fails with a message if the file cannot be written.
Status write_slice_set_json(const SliceSet& set, const std::filesystem::path& path);
/// Writes `.csl`. Fails for sets the format cannot hold (unknown regions or a fov).
Status write_csl(const SliceSet& set, const std::filesystem::path& path);
/// Writes by extension: `.csl` or JSON.
Status write_slice_set(const SliceSet& set, const std::filesystem::path& path);

/// One slice object of the JSON format (an element of "slices") on a single line, numbers in
/// shortest round-trip form: what messages and JSON-lines logs embed. Fails for NaN or infinite
/// numbers, which JSON cannot hold.
Result<std::string> write_slice_json(const LabeledSlice& slice);

/// Parses one slice object (what write_slice_json writes) and checks it by the per-slice rules of
/// slices.md (unit orthogonal u and v, usable rings, no overlapping regions; any positive label).
/// Keys listed in `also_known` pass without a warning: formats that embed a slice add their own.
/// Errors start with `source_name`.
Result<LabeledSlice> parse_slice_json(const std::string& text, const std::string& source_name,
                                      const std::vector<std::string>& also_known = {});

/// Checks a slice set against every rule of slices.md (geometry, labels, overlaps, bounds).
Status validate_slice_set(const SliceSet& set, const std::string& source_name);

}  // namespace sonoshape
