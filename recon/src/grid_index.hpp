#pragma once
// A hash map from grid-vertex keys to rows, open addressing with linear probing.
//
// The sparse octree field looks keys up millions of times per reconstruction (refinement, band
// closure, smoothing stencils, meshing); std::unordered_map's node allocations and pointer chasing
// made those lookups the largest cost after the field itself.
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace sonoshape::recon {

class GridIndex {
 public:
  static constexpr std::uint32_t kNone = 0xffffffffu;

  GridIndex() { rehash(1024); }

  std::size_t size() const { return size_; }
  void reserve(std::size_t count) {
    std::size_t capacity = keys_.size();
    while (capacity < 2 * count) capacity *= 2;
    if (capacity != keys_.size()) rehash(capacity);
  }
  /// The row of `key`, or kNone.
  std::uint32_t find(std::uint64_t key) const {
    for (std::size_t slot = home(key);; slot = (slot + 1) & mask_) {
      if (keys_[slot] == key) return values_[slot];
      if (keys_[slot] == kEmptyKey) return kNone;
    }
  }
  std::size_t count(std::uint64_t key) const { return find(key) != kNone ? 1 : 0; }
  std::uint32_t at(std::uint64_t key) const {
    const std::uint32_t row = find(key);
    if (row == kNone) throw std::out_of_range("GridIndex: grid vertex has no value");
    return row;
  }
  /// Removes every key, keeping the capacity.
  void clear() {
    if (size_ == 0) return;
    std::fill(keys_.begin(), keys_.end(), kEmptyKey);
    size_ = 0;
  }
  /// Inserts unless present; returns whether it inserted.
  bool insert(std::uint64_t key, std::uint32_t value) {
    if (2 * (size_ + 1) > keys_.size()) rehash(2 * keys_.size());
    for (std::size_t slot = home(key);; slot = (slot + 1) & mask_) {
      if (keys_[slot] == key) return false;
      if (keys_[slot] == kEmptyKey) {
        keys_[slot] = key;
        values_[slot] = value;
        ++size_;
        return true;
      }
    }
  }

 private:
  static constexpr std::uint64_t kEmptyKey = ~std::uint64_t{0};  // grid keys use 63 bits
  std::size_t home(std::uint64_t key) const {
    return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> 20) & mask_;
  }
  void rehash(std::size_t capacity) {
    std::vector<std::uint64_t> old_keys(capacity, kEmptyKey);
    std::vector<std::uint32_t> old_values(capacity);
    old_keys.swap(keys_);
    old_values.swap(values_);
    mask_ = capacity - 1;
    size_ = 0;
    for (std::size_t i = 0; i < old_keys.size(); ++i)
      if (old_keys[i] != kEmptyKey) insert(old_keys[i], old_values[i]);
  }

  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::size_t size_ = 0;
  std::size_t mask_ = 0;
};

}  // namespace sonoshape::recon
