#pragma once
// Far-field evaluation of long rings in the mean-value integral.
//
// The field at a point sums one closed-form term per contour edge of every face of its cell; a
// face crossed by an organ's contour carries hundreds of edges, and most of them are far from
// the point. A chain of consecutive edges a_0 -> ... -> a_m contributes exactly its chord
// a_0 -> a_m plus the integral of the kernel K(y) = 2 h^2 / (|y - foot|^2 + h^2)^2 over the
// signed region between chain and chord (Stokes on the closed loop). Far from the chain, that
// region integral is replaced by its Taylor expansion to fourth order about the chain's centre,
// from the region's area and its moments up to the fourth (precomputed): one atan2 for the chord
// and a few dozen products instead of one atan2 per edge, with a relative error of order
// (radius / distance)^5 on the region term. Near the chain, its two halves are visited (a binary
// tree over the edges). The fourth order lets a node be used whole from 0.2 of its distance
// instead of 0.1 with the second order, at a smaller error (chain_tree_test): fewer nodes are
// opened and fewer edges summed exactly (timings in docs/engine.md §3).
//
// This is the classic Barnes-Hut trade (a hierarchy with an opening criterion) applied to the
// boundary form of the integral; written here because no library evaluates this kernel.
#include <cstdint>
#include <vector>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon {

/// A node of the tree over the edges [first, last) of a ring (edge i: point i -> point i+1,
/// wrapping): its chord, bounding circle and the moments of the region between chain and chord.
struct ChainNode {
  Vec2 centre;
  double radius_sq = 0;  ///< bounding circle of the chain's points, squared
  std::uint32_t first = 0, last = 0;
  std::int32_t left = -1, right = -1;   ///< children (-1: a leaf, summed edge by edge)
  double area = 0;                      ///< signed area between chain and chord
  double m1x = 0, m1y = 0;              ///< first moments about `centre`
  double m2xx = 0, m2xy = 0, m2yy = 0;  ///< second moments about `centre`
  double m3[4] = {};                    ///< third moments about `centre`: x^3, x^2 y, x y^2, y^3
  double m4[5] = {};  ///< fourth moments about `centre`: x^4, x^3 y, x^2 y^2, x y^3, y^4
};

/// Rings with at least this many edges get a tree; shorter ones are summed directly.
constexpr std::size_t kChainTreeMinEdges = 32;

/// Appends the tree of the ring `points[0..count)` to `nodes` (root first); returns the root's
/// index.
std::uint32_t build_chain_tree(const Vec2* points, std::size_t count,
                               std::vector<ChainNode>& nodes);

/// projected_angle (mean_value.hpp) of the ring through its tree `root`: exact edge terms near
/// the point, chords plus fourth-order region terms where the node's bounding circle is seen
/// under a small angle.
double projected_angle_tree(const Vec2* points, std::size_t count, const ChainNode* nodes,
                            std::uint32_t root, const Vec2& foot, double height);

/// The same without the cancellation-free split for feet outside the ring (the plain edge sums,
/// as projected_angle_plain): for sums whose absolute accuracy suffices.
double projected_angle_tree_plain(const Vec2* points, std::size_t count, const ChainNode* nodes,
                                  std::uint32_t root, const Vec2& foot, double height);

}  // namespace sonoshape::recon
