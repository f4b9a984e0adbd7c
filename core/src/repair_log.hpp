#pragma once
// The repairs a slice-set reader makes (docs/formats/slices.md, "Repairs are data"): records,
// warnings, and the refusal of any repair under ReadOptions::strict.
#include <string>
#include <utility>
#include <vector>

#include "sonoshape/core/repairs.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::detail {

/// Collects a reader's repairs: the records for SliceSet::repairs, one warning per slice on
/// stderr when finished, and under ReadOptions::strict an error at the first repair.
class RepairLog {
 public:
  RepairLog(std::string source_name, const ReadOptions& options)
      : source_name_(std::move(source_name)), strict_(options.strict) {}

  /// Records a repair of the slice named `slice_name` ("" when it concerns the whole file).
  /// Strict: throws InputError naming the file, the element and the way out (the readers turn
  /// it into their Status).
  void add(const std::string& slice_name, Repair repair);
  /// Prints the warnings (one line per slice, slices in the order first repaired) and hands the
  /// records over.
  std::vector<Repair> finish();

 private:
  std::string source_name_;
  bool strict_ = false;
  std::vector<std::pair<std::string, Repair>> repairs_;  // (slice name, repair) in order
};

}  // namespace sonoshape::detail
