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

// The union of `sorted` (sorted, unique keys) with its copies shifted by each of `shifts` (at
// most eight), sorted and unique. A grid key is linear in (i, j, k) (grid_key), so a shifted copy
// of a sorted list is sorted: one merge of the copies builds the corner and neighbour sets of the
// smoothing in linear time, instead of sorting seven keys per element (or merging the copies in
// one at a time, which passed over the growing result once per shift).
template <typename Shifts = std::initializer_list<std::int64_t>>
std::vector<std::uint64_t> union_of_shifts(const std::vector<std::uint64_t>& sorted, const Shifts& shifts) {
  std::array<std::uint64_t, 9> offset{};  // per copy; copy 0 is `sorted` itself
  std::array<std::size_t, 9> next{};      // per copy, its next key
  std::size_t copies = 1;
  for (const std::int64_t shift : shifts)
    if (shift != 0) offset[copies++] = static_cast<std::uint64_t>(shift);
  const std::size_t count = sorted.size();
  std::vector<std::uint64_t> result;
  result.reserve(2 * count);
  for (;;) {
    std::uint64_t least = ~std::uint64_t{0};
    bool any = false;
    for (std::size_t c = 0; c < copies; ++c)
      if (next[c] < count) {
        least = std::min(least, sorted[next[c]] + offset[c]);
        any = true;
      }
    if (!any) break;
    result.push_back(least);
    for (std::size_t c = 0; c < copies; ++c)
      if (next[c] < count && sorted[next[c]] + offset[c] == least) ++next[c];
  }
  return result;
}
/// The key steps of one grid step along k, j and i (see grid_key).
inline constexpr std::int64_t kKeyStepK = 1, kKeyStepJ = std::int64_t{1} << 21, kKeyStepI = std::int64_t{1} << 42;

// The key shifts of a 7-point stencil: centre, then the face neighbours along -i, +i, -j, +j,
// -k, +k.
inline constexpr std::array<std::int64_t, 7> kStencilShifts{0,          -kKeyStepI, kKeyStepI, -kKeyStepJ,
                                                            kKeyStepJ, -kKeyStepK, kKeyStepK};
/// The key shifts from a cell's min corner to its corner c, offset (c & 1, (c >> 1) & 1, (c >> 2) & 1).
inline constexpr std::array<std::int64_t, 8> kCubeCornerShifts{
    0, kKeyStepI, kKeyStepJ, kKeyStepI + kKeyStepJ, kKeyStepK, kKeyStepI + kKeyStepK, kKeyStepJ + kKeyStepK,
    kKeyStepI + kKeyStepJ + kKeyStepK};

// Per key n of `keys` and shift d of `shifts` (at most eight), the position in `targets` of key
// n shifted by shift d, into positions[n * stride + d] (every shifted key is there; both lists
// sorted, unique). The shifted keys are sorted too (see union_of_shifts): each chunk of keys
// finds its first ones by binary search and walks on, all shifts in one pass, so that each key's
// positions are written together.
template <typename Shifts = std::initializer_list<std::int64_t>>
void neighbour_positions(const std::vector<std::uint64_t>& keys, const Shifts& shifts,
                         const std::vector<std::uint64_t>& targets, std::uint32_t* positions, std::size_t stride) {
  std::array<std::uint64_t, 8> offset{};
  std::size_t count = 0;
  for (const std::int64_t shift : shifts) offset[count++] = static_cast<std::uint64_t>(shift);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, keys.size(), 8192),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::array<const std::uint64_t*, 8> at{};
                      for (std::size_t d = 0; d < count; ++d)
                        at[d] = &*std::lower_bound(targets.begin(), targets.end(), keys[r.begin()] + offset[d]);
                      for (std::size_t n = r.begin(); n < r.end(); ++n)
                        for (std::size_t d = 0; d < count; ++d) {
                          const std::uint64_t key = keys[n] + offset[d];
                          while (*at[d] < key) ++at[d];
                          positions[n * stride + d] = static_cast<std::uint32_t>(at[d] - targets.data());
                        }
                    });
}

}  // namespace sonoshape::recon
