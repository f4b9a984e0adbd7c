#pragma once
// Sets of grid vertices or cells as sorted lists of grid keys (see grid_key). A key is linear in
// (i, j, k), so a list shifted by a constant stays sorted: the octree smoothing and the mesher
// build their neighbour sets by merging shifted copies and find neighbours by walking lists,
// in linear time, where hashing every stencil's vertices cost more than the work on them.
#include <algorithm>
#include <array>
#include <cstdint>
#include <initializer_list>
#include <iterator>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace sonoshape::recon {

// The union of `sorted` (sorted, unique keys) with its copies shifted by each of `shifts`,
// sorted and unique. A grid key is linear in (i, j, k) (grid_key), so a shifted copy of a sorted
// list is sorted: merging copies builds the corner and neighbour sets of the smoothing in linear
// time instead of sorting eight or seven keys per element.
inline std::vector<std::uint64_t> union_of_shifts(const std::vector<std::uint64_t>& sorted,
                                           std::initializer_list<std::int64_t> shifts) {
  std::vector<std::uint64_t> result = sorted, shifted, merged;
  for (const std::int64_t shift : shifts) {
    shifted.resize(sorted.size());
    std::transform(sorted.begin(), sorted.end(), shifted.begin(),
                   [shift](std::uint64_t key) { return key + static_cast<std::uint64_t>(shift); });
    merged.clear();
    merged.reserve(result.size() + shifted.size());
    std::set_union(result.begin(), result.end(), shifted.begin(), shifted.end(), std::back_inserter(merged));
    result.swap(merged);
  }
  return result;
}
/// The key steps of one grid step along k, j and i (see grid_key).
inline constexpr std::int64_t kKeyStepK = 1, kKeyStepJ = std::int64_t{1} << 21, kKeyStepI = std::int64_t{1} << 42;

// The key shifts of a 7-point stencil: centre, then the face neighbours along -i, +i, -j, +j,
// -k, +k.
inline constexpr std::array<std::int64_t, 7> kStencilShifts{0,          -kKeyStepI, kKeyStepI, -kKeyStepJ,
                                                     kKeyStepJ, -kKeyStepK, kKeyStepK};

// The position in `targets` of every key of `keys` shifted by `shift` (all there; both lists
// sorted, unique). The shifted keys are sorted too (see union_of_shifts), so each chunk finds its
// first one by binary search and the rest by walking forward.
inline std::vector<std::uint32_t> neighbour_positions(const std::vector<std::uint64_t>& keys, std::int64_t shift,
                                               const std::vector<std::uint64_t>& targets) {
  std::vector<std::uint32_t> positions(keys.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, keys.size(), 8192),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      const auto shifted = [&](std::size_t n) { return keys[n] + static_cast<std::uint64_t>(shift); };
                      auto it = std::lower_bound(targets.begin(), targets.end(), shifted(r.begin()));
                      for (std::size_t n = r.begin(); n < r.end(); ++n) {
                        const std::uint64_t key = shifted(n);
                        while (*it < key) ++it;
                        positions[n] = static_cast<std::uint32_t>(it - targets.begin());
                      }
                    });
  return positions;
}

}  // namespace sonoshape::recon
