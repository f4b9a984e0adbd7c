#pragma once
// A map from grid-vertex keys to rows: a direct table over the grid when it is small enough,
// open addressing with linear probing for the other keys.
//
// The sparse octree field looks keys up millions of times per reconstruction (refinement, band
// closure, smoothing stencils, meshing); std::unordered_map's node allocations and pointer chasing
// made those lookups the largest cost after the field itself, and at the default depth
// (129^3 vertices) a direct table costs one load where the hash costs a multiply and a probe
// sequence on a table several times larger than the field.
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace sonoshape::recon {

class GridIndex {
 public:
  static constexpr std::uint32_t kNone = 0xffffffffu;

  GridIndex() { rehash(1024); }
  /// Direct table for the vertices of a grid of `resolution` cells per axis (stencils included,
  /// see kDirectPadding) when it has at most kMaxDirectSlots slots.
  explicit GridIndex(int resolution) : GridIndex() {
    direct_side_ = direct_side_for(resolution);
    direct_.assign(direct_side_ * direct_side_ * direct_side_, kNone);
  }

  /// Empties the index for a grid of `resolution` cells per axis, keeping its tables when they
  /// were made for that resolution (a new direct table costs a 9 MiB allocation and fill at the
  /// default depth: more than an online update's octree passes).
  void reset(int resolution) {
    const std::size_t side = direct_side_for(resolution);
    if (side == direct_side_ && direct_.size() == side * side * side && !keys_.empty()) {
      clear();
      return;
    }
    *this = GridIndex(resolution);
  }

  std::size_t size() const { return size_; }
  void reserve(std::size_t count) {
    if (direct_side_ != 0) return;  // the few keys outside the direct table need no room
    std::size_t capacity = keys_.size();
    while (capacity < 2 * count) capacity *= 2;
    if (capacity != keys_.size()) rehash(capacity);
  }
  /// The row of `key`, or kNone.
  std::uint32_t find(std::uint64_t key) const {
    if (const std::size_t slot = direct_slot(key); slot != kNoSlot) return direct_[slot];
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
    for (const std::size_t slot : direct_used_) direct_[slot] = kNone;
    direct_used_.clear();
    std::fill(keys_.begin(), keys_.end(), kEmptyKey);
    size_ = 0;
    hashed_ = 0;
  }
  /// Inserts unless present; returns whether it inserted.
  bool insert(std::uint64_t key, std::uint32_t value) {
    if (const std::size_t slot = direct_slot(key); slot != kNoSlot) {
      if (direct_[slot] != kNone) return false;
      direct_[slot] = value;
      direct_used_.push_back(slot);
      ++size_;
      return true;
    }
    if (2 * (hashed_ + 1) > keys_.size()) rehash(2 * keys_.size());
    for (std::size_t slot = home(key);; slot = (slot + 1) & mask_) {
      if (keys_[slot] == key) return false;
      if (keys_[slot] == kEmptyKey) {
        keys_[slot] = key;
        values_[slot] = value;
        ++size_;
        ++hashed_;
        return true;
      }
    }
  }

 private:
  static constexpr std::uint64_t kEmptyKey = ~std::uint64_t{0};  // grid keys use 63 bits
  static constexpr std::size_t kNoSlot = ~std::size_t{0};
  // The smoothing stencils reach two vertices beyond the grid.
  static constexpr std::size_t kDirectPadding = 2;
  // 16 MiB of rows: depth 7 (the default) fits, depth 8 would take 70 MiB per table.
  static constexpr std::size_t kMaxDirectSlots = std::size_t{1} << 22;

  // The side of the direct table for a grid of `resolution` cells per axis; 0: too large for one.
  static std::size_t direct_side_for(int resolution) {
    const std::size_t side = static_cast<std::size_t>(resolution) + 1 + 2 * kDirectPadding;
    return side * side * side > kMaxDirectSlots ? 0 : side;
  }
  // The slot of `key` in the direct table, or kNoSlot when there is none (no table, or the
  // vertex lies outside it). Keys are grid_key()'s: 21 bits per axis, biased by 2^20.
  std::size_t direct_slot(std::uint64_t key) const {
    if (direct_side_ == 0) return kNoSlot;
    constexpr std::uint64_t kBias = (std::uint64_t{1} << 20) - kDirectPadding;
    const std::uint64_t i = (key >> 42) - kBias, j = ((key >> 21) & 0x1fffff) - kBias,
                        k = (key & 0x1fffff) - kBias;  // unsigned: below the table wraps high
    if (i >= direct_side_ || j >= direct_side_ || k >= direct_side_) return kNoSlot;
    return static_cast<std::size_t>((i * direct_side_ + j) * direct_side_ + k);
  }
  std::size_t home(std::uint64_t key) const {
    return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> 20) & mask_;
  }
  void rehash(std::size_t capacity) {
    std::vector<std::uint64_t> old_keys(capacity, kEmptyKey);
    std::vector<std::uint32_t> old_values(capacity);
    old_keys.swap(keys_);
    old_values.swap(values_);
    mask_ = capacity - 1;
    size_ -= hashed_;
    hashed_ = 0;
    for (std::size_t i = 0; i < old_keys.size(); ++i)
      if (old_keys[i] != kEmptyKey) insert(old_keys[i], old_values[i]);
  }

  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::size_t size_ = 0;    // keys in both tables
  std::size_t hashed_ = 0;  // keys in the hash table
  std::size_t mask_ = 0;
  std::size_t direct_side_ = 0;           // 0: no direct table
  std::vector<std::uint32_t> direct_;     // row per slot, kNone where absent
  std::vector<std::size_t> direct_used_;  // occupied slots, for clear()
};

}  // namespace sonoshape::recon
