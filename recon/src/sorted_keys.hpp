#pragma once
// Sets of grid vertices or cells as sorted lists of grid keys (see grid_key). A key is linear in
// (i, j, k), so a list shifted by a constant stays sorted: the octree smoothing and the mesher
// build their neighbour sets, and find every element's neighbours in them, by merging shifted
// copies in linear time, where hashing every stencil's vertices cost more than the work on them.
#include <algorithm>
#include <array>
#include <cstdint>
#include <initializer_list>
#include <iterator>
#include <vector>

namespace sonoshape::recon {

// The union of the copies of `sorted` (sorted, unique keys) shifted by each of `shifts` (at most
// eight; a shift of 0 is `sorted` itself), sorted and unique. A grid key is linear in (i, j, k)
// (grid_key), so a shifted copy of a sorted list is sorted: one merge of the copies builds the
// corner and neighbour sets of the smoothing and the mesher in linear time, instead of sorting
// eight or seven keys per element or hashing them. With `positions`, it also gives where each
// shifted key lies in the result: positions[n * shifts.size() + c] for key n shifted by shift c,
// so that stencils are found without a search.
template <typename Shifts = std::initializer_list<std::int64_t>>
std::vector<std::uint64_t> union_of_shifts(const std::vector<std::uint64_t>& sorted, const Shifts& shifts,
                                           std::vector<std::uint32_t>* positions = nullptr) {
  std::array<std::uint64_t, 8> offset{};  // per copy
  std::array<std::size_t, 8> next{};      // per copy, its next key
  std::size_t copies = 0;
  for (const std::int64_t shift : shifts) offset[copies++] = static_cast<std::uint64_t>(shift);
  const std::size_t count = sorted.size();
  if (positions != nullptr) positions->resize(count * copies);
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
    const auto position = static_cast<std::uint32_t>(result.size());
    result.push_back(least);
    for (std::size_t c = 0; c < copies; ++c)
      if (next[c] < count && sorted[next[c]] + offset[c] == least) {
        if (positions != nullptr) (*positions)[next[c] * copies + c] = position;
        ++next[c];
      }
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

}  // namespace sonoshape::recon
