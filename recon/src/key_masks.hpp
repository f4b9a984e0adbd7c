#pragma once
// The neighbour sets of sorted_keys.hpp (union_of_shifts with the cube-corner or the 7-point
// stencil shifts) built on bit masks: one row of bits along k per (i, j). Dilating a set is then
// a few word operations per row, and where a key lies in the sorted result is a count of the set
// bits before it. Same keys in the same order, and the same positions, as union_of_shifts, whose
// merge of seven or eight shifted copies (a compare and a store per copy and key) costs more
// than anything else in an online update's smoothing set-up. Used where the
// keys' bounding box needs at most kMaxMaskWords words (the whole finest grid up to depth 9; the
// default depth is 7); union_of_shifts otherwise.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <vector>

#include "octree_field.hpp"
#include "sorted_keys.hpp"

namespace sonoshape::recon {

// Set bits of a word, without a call: a portable build (x86-64 without POPCNT) makes
// std::popcount a library call per word.
inline std::uint32_t bit_count(std::uint64_t x) {
  x = x - ((x >> 1) & 0x5555555555555555ull);
  x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
  x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0full;
  return static_cast<std::uint32_t>((x * 0x0101010101010101ull) >> 56);
}

/// A set of grid keys in a box, as rows of bits along k.
class KeyMask {
 public:
  /// The keys of `sorted` (sorted, unique) in their bounding box padded by `pad` on every side
  /// (a pad of one keeps every key shifted by one step inside it); empty (see valid()) if that
  /// box would need more than `max_words` words.
  KeyMask(const std::vector<std::uint64_t>& sorted, int pad, std::size_t max_words) {
    if (sorted.empty()) return;
    int lo[3] = {1 << 30, 1 << 30, 1 << 30}, hi[3] = {-(1 << 30), -(1 << 30), -(1 << 30)};
    for (const std::uint64_t key : sorted) {
      int c[3];
      grid_unkey(key, c[0], c[1], c[2]);
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], c[a]);
        hi[a] = std::max(hi[a], c[a]);
      }
    }
    for (int a = 0; a < 3; ++a) {
      low_[a] = lo[a] - pad;
      size_[a] = hi[a] - lo[a] + 1 + 2 * pad;
    }
    words_ = static_cast<std::size_t>((size_[2] + 63) / 64);
    if (static_cast<std::size_t>(size_[0]) * static_cast<std::size_t>(size_[1]) * words_ >
        max_words)
      return;
    bits_.assign(static_cast<std::size_t>(size_[0]) * static_cast<std::size_t>(size_[1]) * words_,
                 0);
    for (const std::uint64_t key : sorted) {
      int i, j, k;
      grid_unkey(key, i, j, k);
      const std::size_t b = static_cast<std::size_t>(k - low_[2]);
      row(i - low_[0], j - low_[1])[b / 64] |= std::uint64_t{1} << (b % 64);
    }
    valid_ = true;
  }
  bool valid() const { return valid_; }

  /// The union of the set shifted by every cube-corner offset {0, 1}^3 (kCubeCornerShifts).
  KeyMask cube_corners() const {
    KeyMask out = empty_like();
    tbb::parallel_for(0, size_[0], [&](int i) {
      std::vector<std::uint64_t> shifted(words_);
      for (int j = 0; j < size_[1]; ++j) {
        std::uint64_t* to = out.row(i, j);
        for (int di = 0; di <= 1; ++di)
          for (int dj = 0; dj <= 1; ++dj) {
            if (i - di < 0 || j - dj < 0) continue;
            const std::uint64_t* from = row(i - di, j - dj);
            shift_up(from, shifted.data());
            for (std::size_t w = 0; w < words_; ++w) to[w] |= from[w] | shifted[w];
          }
      }
    });
    return out;
  }
  /// The union of the set shifted by the 7-point stencil (kStencilShifts).
  KeyMask stencil() const {
    KeyMask out = empty_like();
    tbb::parallel_for(0, size_[0], [&](int i) {
      std::vector<std::uint64_t> up(words_), down(words_);
      for (int j = 0; j < size_[1]; ++j) {
        std::uint64_t* to = out.row(i, j);
        const std::uint64_t* from = row(i, j);
        shift_up(from, up.data());
        shift_down(from, down.data());
        for (std::size_t w = 0; w < words_; ++w) to[w] = from[w] | up[w] | down[w];
        for (const auto& [ni, nj] :
             {std::pair{i - 1, j}, std::pair{i + 1, j}, std::pair{i, j - 1}, std::pair{i, j + 1}}) {
          if (ni < 0 || nj < 0 || ni >= size_[0] || nj >= size_[1]) continue;
          const std::uint64_t* neighbour = row(ni, nj);
          for (std::size_t w = 0; w < words_; ++w) to[w] |= neighbour[w];
        }
      }
    });
    return out;
  }

  /// The keys, sorted; also counts the bits before each word, for position().
  std::vector<std::uint64_t> keys() {
    // Counts per plane of constant i in parallel, then the planes' offsets.
    const std::size_t plane_words = static_cast<std::size_t>(size_[1]) * words_;
    word_start_.assign(bits_.size() + 1, 0);
    std::vector<std::uint32_t> plane_start(static_cast<std::size_t>(size_[0]) + 1, 0);
    tbb::parallel_for(0, size_[0], [&](int i) {
      std::uint32_t count = 0;
      for (std::size_t w = static_cast<std::size_t>(i) * plane_words;
           w < static_cast<std::size_t>(i + 1) * plane_words; ++w) {
        word_start_[w] = count;
        count += bit_count(bits_[w]);
      }
      plane_start[static_cast<std::size_t>(i) + 1] = count;
    });
    for (std::size_t i = 0; i < static_cast<std::size_t>(size_[0]); ++i)
      plane_start[i + 1] += plane_start[i];
    word_start_.back() = plane_start.back();
    tbb::parallel_for(0, size_[0], [&](int i) {
      for (std::size_t w = static_cast<std::size_t>(i) * plane_words;
           w < static_cast<std::size_t>(i + 1) * plane_words; ++w)
        word_start_[w] += plane_start[static_cast<std::size_t>(i)];
    });
    std::vector<std::uint64_t> out(word_start_.back());
    tbb::parallel_for(0, size_[0], [&](int i) {
      for (int j = 0; j < size_[1]; ++j) {
        const std::size_t first =
            (static_cast<std::size_t>(i) * static_cast<std::size_t>(size_[1]) +
             static_cast<std::size_t>(j)) *
            words_;
        std::uint32_t n = word_start_[first];
        for (std::size_t w = 0; w < words_; ++w)
          for (std::uint64_t word = bits_[first + w]; word != 0; word &= word - 1) {
            const int b = static_cast<int>(w * 64) + std::countr_zero(word);
            out[n++] = grid_key(i + low_[0], j + low_[1], b + low_[2]);
          }
      }
    });
    return out;
  }
  /// Where the key (i, j, k), which must be in the set, lies in keys() (called before this).
  std::uint32_t position(int i, int j, int k) const {
    const std::size_t b = static_cast<std::size_t>(k - low_[2]);
    const std::size_t w =
        (static_cast<std::size_t>(i - low_[0]) * static_cast<std::size_t>(size_[1]) +
         static_cast<std::size_t>(j - low_[1])) *
            words_ +
        b / 64;
    return word_start_[w] + bit_count(bits_[w] & ((std::uint64_t{1} << (b % 64)) - 1));
  }

 private:
  KeyMask() = default;
  KeyMask empty_like() const {
    KeyMask out;
    std::copy(low_, low_ + 3, out.low_);
    std::copy(size_, size_ + 3, out.size_);
    out.words_ = words_;
    out.bits_.assign(bits_.size(), 0);
    out.valid_ = valid_;
    return out;
  }
  std::uint64_t* row(int i, int j) {
    return &bits_[(static_cast<std::size_t>(i) * static_cast<std::size_t>(size_[1]) +
                   static_cast<std::size_t>(j)) *
                  words_];
  }
  const std::uint64_t* row(int i, int j) const {
    return &bits_[(static_cast<std::size_t>(i) * static_cast<std::size_t>(size_[1]) +
                   static_cast<std::size_t>(j)) *
                  words_];
  }
  // Bits moved one place up (k + 1) and down (k - 1) along the row.
  void shift_up(const std::uint64_t* from, std::uint64_t* to) const {
    for (std::size_t w = words_; w-- > 0;) to[w] = (from[w] << 1) | (w > 0 ? from[w - 1] >> 63 : 0);
  }
  void shift_down(const std::uint64_t* from, std::uint64_t* to) const {
    for (std::size_t w = 0; w < words_; ++w)
      to[w] = (from[w] >> 1) | (w + 1 < words_ ? from[w + 1] << 63 : 0);
  }
  int low_[3] = {0, 0, 0};
  int size_[3] = {0, 0, 0};
  std::size_t words_ = 0;
  std::vector<std::uint64_t> bits_;
  std::vector<std::uint32_t> word_start_;  // per word, the set bits before it
  bool valid_ = false;
};

// Masks of boxes up to this many words (32 MiB of bits: the finest grid up to depth 9).
constexpr std::size_t kMaxMaskWords = std::size_t{1} << 22;

// The union of `sorted` (sorted, unique) dilated by `dilate` (a KeyMask member) on masks, with
// per key `width` positions filled by fill(mask, i, j, k, p); the merge of `shifts` where the
// box is too large for masks.
template <typename Shifts, typename Dilate, typename Fill>
std::vector<std::uint64_t> masked_union(const std::vector<std::uint64_t>& sorted,
                                        const Shifts& shifts, Dilate dilate, std::size_t width,
                                        const Fill& fill, std::vector<std::uint32_t>* positions) {
  KeyMask mask(sorted, 1, kMaxMaskWords);
  if (!mask.valid()) return union_of_shifts(sorted, shifts, positions);
  KeyMask dilated = (mask.*dilate)();
  std::vector<std::uint64_t> out = dilated.keys();
  if (positions != nullptr) {
    positions->resize(sorted.size() * width);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, sorted.size(), 1024),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t n = r.begin(); n < r.end(); ++n) {
                          int i, j, k;
                          grid_unkey(sorted[n], i, j, k);
                          fill(dilated, i, j, k, &(*positions)[n * width]);
                        }
                      });
  }
  return out;
}

/// union_of_shifts(sorted, kCubeCornerShifts, positions) on masks where they fit.
inline std::vector<std::uint64_t> cube_corner_union(
    const std::vector<std::uint64_t>& sorted, std::vector<std::uint32_t>* positions = nullptr) {
  return masked_union(
      sorted, kCubeCornerShifts, &KeyMask::cube_corners, 8,
      [](const KeyMask& corners, int i, int j, int k, std::uint32_t* p) {
        // Corner c has offset (c & 1, (c >> 1) & 1, (c >> 2) & 1); (i, j, k + 1)
        // follows (i, j, k).
        for (int c = 0; c < 4; ++c) {
          p[c] = corners.position(i + (c & 1), j + ((c >> 1) & 1), k);
          p[c + 4] = p[c] + 1;
        }
      },
      positions);
}

/// union_of_shifts(sorted, kStencilShifts, positions) on masks where they fit.
inline std::vector<std::uint64_t> stencil_union(const std::vector<std::uint64_t>& sorted,
                                                std::vector<std::uint32_t>* positions = nullptr) {
  return masked_union(
      sorted, kStencilShifts, &KeyMask::stencil, 7,
      [](const KeyMask& dilated, int i, int j, int k, std::uint32_t* p) {
        // kStencilShifts: centre, -i, +i, -j, +j, -k, +k; the k neighbours lie
        // beside the centre.
        p[0] = dilated.position(i, j, k);
        p[1] = dilated.position(i - 1, j, k);
        p[2] = dilated.position(i + 1, j, k);
        p[3] = dilated.position(i, j - 1, k);
        p[4] = dilated.position(i, j + 1, k);
        p[5] = p[0] - 1;
        p[6] = p[0] + 1;
      },
      positions);
}

}  // namespace sonoshape::recon
