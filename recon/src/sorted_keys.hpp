#pragma once
// Sets of grid vertices or cells as sorted lists of grid keys (see grid_key). A key is linear in
// (i, j, k), so a list shifted by a constant stays sorted: the octree smoothing and the mesher
// build their neighbour sets, and find every element's neighbours in them, by merging shifted
// copies in linear time, where hashing every stencil's vertices cost more than the work on them.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <initializer_list>
#include <stdexcept>
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
std::vector<std::uint64_t> union_of_shifts(const std::vector<std::uint64_t>& sorted,
                                           const Shifts& shifts,
                                           std::vector<std::uint32_t>* positions = nullptr) {
  constexpr std::uint64_t kDone = ~std::uint64_t{0};  // the head of a copy that is used up
  std::array<std::uint64_t, 8> offset{};              // per copy
  std::size_t copies = 0;
  for (const std::int64_t shift : shifts) {
    if (copies == offset.size()) throw std::length_error("union_of_shifts: more than eight shifts");
    offset[copies++] = static_cast<std::uint64_t>(shift);
  }
  const std::size_t count = sorted.size();
  if (positions != nullptr) positions->resize(count * copies);
  if (count == 0) return {};
  // The output is merged in parts, in parallel: part p holds the shifted keys in [split[p],
  // split[p + 1]), where each copy's keys start at lower_bound(split - offset).
  // Parts of at least this many keys: an online update's band is some 20k cells, which parts of
  // 16k left to one thread (the merges of the smoothing and the mesher then took twice as long).
  constexpr std::size_t kMinPart = 2048;
  const std::size_t part_count = std::clamp<std::size_t>(count / kMinPart, 1, 64);
  std::vector<std::uint64_t> split(part_count + 1);
  split[0] = 0;
  split[part_count] = kDone;
  for (std::size_t p = 1; p < part_count; ++p) split[p] = sorted[count * p / part_count];
  std::vector<std::array<std::size_t, 8>> first(part_count +
                                                1);  // per part and copy, its first key
  for (std::size_t p = 0; p <= part_count; ++p)
    for (std::size_t c = 0; c < copies; ++c)
      first[p][c] = p == 0 ? 0
                    : p == part_count
                        ? count
                        : static_cast<std::size_t>(
                              std::lower_bound(sorted.begin(), sorted.end(), split[p] - offset[c]) -
                              sorted.begin());
  std::vector<std::vector<std::uint64_t>> parts(part_count);
  tbb::parallel_for(std::size_t{0}, part_count, [&](std::size_t p) {
    std::vector<std::uint64_t>& out = parts[p];
    out.reserve(2 * (first[p + 1][0] - first[p][0]) + 16);
    std::array<std::size_t, 8> next = first[p];
    std::array<std::uint64_t, 8> head;
    head.fill(kDone);
    // Branch-free: which copies hold the least key is a coin toss per key, and the branches on it
    // were mispredicted most of the time.
    const auto load = [&](std::size_t c) {
      const std::uint64_t key = sorted[std::min(next[c], count - 1)] + offset[c];
      head[c] = next[c] < first[p + 1][c] ? key : kDone;
    };
    for (std::size_t c = 0; c < copies; ++c) load(c);
    std::uint32_t unused = 0;  // where the positions of copies without the least key go
    for (;;) {
      std::uint64_t least = head[0];
      for (std::size_t c = 1; c < copies; ++c) least = std::min(least, head[c]);
      if (least == kDone) break;
      const auto position = static_cast<std::uint32_t>(out.size());  // within the part, for now
      out.push_back(least);
      for (std::size_t c = 0; c < copies; ++c) {
        const bool here = head[c] == least;
        if (positions != nullptr)
          *(here ? &(*positions)[next[c] * copies + c] : &unused) = position;
        next[c] += here ? 1 : 0;
        load(c);
      }
    }
  });
  std::vector<std::size_t> base(part_count + 1, 0);
  for (std::size_t p = 0; p < part_count; ++p) base[p + 1] = base[p] + parts[p].size();
  std::vector<std::uint64_t> result(base[part_count]);
  tbb::parallel_for(std::size_t{0}, part_count, [&](std::size_t p) {
    std::copy(parts[p].begin(), parts[p].end(),
              result.begin() + static_cast<std::ptrdiff_t>(base[p]));
    if (positions == nullptr || p == 0) return;
    for (std::size_t c = 0; c < copies; ++c)
      for (std::size_t n = first[p][c]; n < first[p + 1][c]; ++n)
        (*positions)[n * copies + c] += static_cast<std::uint32_t>(base[p]);
  });
  return result;
}
/// The key steps of one grid step along k, j and i (see grid_key).
inline constexpr std::int64_t kKeyStepK = 1, kKeyStepJ = std::int64_t{1} << 21,
                              kKeyStepI = std::int64_t{1} << 42;

// The key shifts of a 7-point stencil: centre, then the face neighbours along -i, +i, -j, +j,
// -k, +k.
inline constexpr std::array<std::int64_t, 7> kStencilShifts{
    0, -kKeyStepI, kKeyStepI, -kKeyStepJ, kKeyStepJ, -kKeyStepK, kKeyStepK};
/// The key shifts from a cell's min corner to its corner c, offset (c & 1, (c >> 1) & 1, (c >> 2) &
/// 1).
inline constexpr std::array<std::int64_t, 8> kCubeCornerShifts{0,
                                                               kKeyStepI,
                                                               kKeyStepJ,
                                                               kKeyStepI + kKeyStepJ,
                                                               kKeyStepK,
                                                               kKeyStepI + kKeyStepK,
                                                               kKeyStepJ + kKeyStepK,
                                                               kKeyStepI + kKeyStepJ + kKeyStepK};

}  // namespace sonoshape::recon
