#pragma once
#include <cstddef>
#include <vector>

namespace sonoshape::recon {

/// v.resize(n) (or v.resize(n, value)), with room for 2n when the elements must move. Cells on
/// demand grow the arrangement's and the face images' arrays by every batch of the octree, often
/// by more than they held (then std::vector reserves exactly n, and the next batch moves
/// everything again); the moves and the page faults of the new storage are serial steps of a
/// 16-thread reconstruction. Room not yet written is not resident memory.
template <typename T>
void grow(std::vector<T>& v, std::size_t n) {
  if (n > v.capacity()) v.reserve(2 * n);
  v.resize(n);
}
template <typename T>
void grow(std::vector<T>& v, std::size_t n, const T& value) {
  if (n > v.capacity()) v.reserve(2 * n);
  v.resize(n, value);
}

}  // namespace sonoshape::recon
