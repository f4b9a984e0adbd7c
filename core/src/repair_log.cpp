#include "repair_log.hpp"

#include <map>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::detail {

void RepairLog::add(const std::string& slice_name, Repair repair) {
  if (strict_)
    throw InputError(source_name_, repair.where,
                     repair.detail +
                         " (--strict refuses input that needs repairs; fix the file, or run "
                         "without --strict to accept the repair)");
  repairs_.emplace_back(slice_name, std::move(repair));
}

std::vector<Repair> RepairLog::finish() {
  // One line per slice: a file with a pinched contour on every plane stays readable.
  std::vector<std::string> order;
  std::map<std::string, std::string> lines;
  for (const auto& [slice, repair] : repairs_) {
    auto [it, first] = lines.try_emplace(slice);
    if (first) order.push_back(slice);
    std::string item = repair.detail;
    if (!repair.where.empty() && repair.where != slice) {
      const std::string element = repair.where.rfind(slice + ", ", 0) == 0 && !slice.empty()
                                      ? repair.where.substr(slice.size() + 2)
                                      : repair.where;
      item = element + ": " + item;
    }
    it->second += (first ? "" : "; ") + item;
  }
  for (const std::string& slice : order)
    log_warning(source_name_ + ": " + (slice.empty() ? "" : slice + ": ") + lines[slice]);
  std::vector<Repair> records;
  records.reserve(repairs_.size());
  for (auto& entry : repairs_) records.push_back(std::move(entry.second));
  repairs_.clear();
  return records;
}

}  // namespace sonoshape::detail
