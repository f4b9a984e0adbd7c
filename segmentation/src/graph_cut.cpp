#include "graph_cut.hpp"

// GCC's flow analysis flags Boost.Graph's edge iterators (boost::optional members) as maybe
// uninitialised when it inlines the max-flow here, and the compressed sparse row graph's
// one-entry row-start vector as indexed out of bounds when it inlines the graph's
// construction: known false positives of Boost 1.74 with GCC 12, silenced for this file only.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Warray-bounds"
#endif

#include <algorithm>
#include <boost/graph/boykov_kolmogorov_max_flow.hpp>
#include <boost/graph/compressed_sparse_row_graph.hpp>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

namespace sonoshape::segmentation::detail {
namespace {

// The graph is a compressed sparse row graph, built from one sorted edge list: a frame's graph
// is new every frame (its band moves), and an adjacency_list spent more time allocating and
// freeing its per-vertex edge vectors than the max-flows took (callgrind).
using Vertex = std::size_t;
using Edge = boost::detail::csr_edge_descriptor<Vertex, std::size_t>;

// The cost of taking alpha for a cell that already has it (the binary choice is void there).
constexpr float kForbidden = 1e9f;

struct EdgeData {
  float capacity = 0.0f;
  float residual = 0.0f;
  Edge reverse;
};
struct VertexData {
  boost::default_color_type colour = boost::white_color;
  float distance = 0.0f;
  Edge predecessor;
};
using Graph = boost::compressed_sparse_row_graph<boost::directedS, VertexData, EdgeData,
                                                 boost::no_property, Vertex, std::size_t>;

// A neighbour pair's two directed edges (each the other's reverse).
struct Pair {
  std::size_t first = 0, second = 0;  // active-cell indices
  std::size_t grid = 0;               // grid index of `first`
  bool right = true;                  // `second` is the right (else the lower) neighbour
  Edge forward, backward;
};

}  // namespace

// The terms of one minimise call: per-cell label costs and the Potts weights of the pairs.
struct Terms {
  const std::vector<float>& cost;  // cell x label
  const std::vector<float>& right_weight;
  const std::vector<float>& down_weight;
  std::size_t labels;
  float unary(std::size_t grid, std::size_t label) const { return cost[grid * labels + label]; }
  float weight(const Pair& p) const { return p.right ? right_weight[p.grid] : down_weight[p.grid]; }
};

struct GridLabelling::Impl {
  Graph graph;
  Vertex source = 0, sink = 0;
  std::vector<std::size_t> cells;  // grid index of each active cell (= its vertex)
  std::vector<Edge> from_source, to_sink;
  std::vector<Pair> pairs;
  // The pairs each active cell takes part in (CSR: pair_of[pair_start[v] .. pair_start[v+1])).
  std::vector<std::size_t> pair_start, pair_of;

  // The energy of `labelling`: its unary terms and the Potts terms of the pairs it splits.
  double energy(const Terms& t, const std::vector<std::uint8_t>& labelling) const {
    double e = 0.0;
    for (const std::size_t c : cells) e += t.unary(c, labelling[c]);
    for (const Pair& p : pairs)
      if (labelling[p.grid] != labelling[cells[p.second]]) e += t.weight(p);
    return e;
  }

  // The capacities of the binary problem of expanding `alpha`: x = 0 keeps the label, x = 1
  // takes alpha. Unary terms first, then each pair's Potts term split into unary parts and one
  // edge (Kolmogorov and Zabih 2004). `keep` and `move`: scratch, one per cell.
  void set_expansion(const Terms& t, const std::vector<std::uint8_t>& labelling, std::size_t alpha,
                     std::vector<float>& keep, std::vector<float>& move) {
    for (std::size_t v = 0; v < cells.size(); ++v) {
      const std::size_t c = cells[v];
      keep[v] = t.unary(c, labelling[c]);
      move[v] = labelling[c] == alpha ? kForbidden : t.unary(c, alpha);
    }
    for (const Pair& p : pairs) {
      const std::size_t c = p.grid, d = cells[p.second];
      const float w = t.weight(p);
      const bool a_alpha = labelling[c] == alpha, b_alpha = labelling[d] == alpha;
      const float e00 = labelling[c] != labelling[d] ? w : 0.0f;
      const float e01 = a_alpha ? 0.0f : w;  // c keeps, d takes alpha
      const float e10 = b_alpha ? 0.0f : w;  // c takes alpha, d keeps
      // E = e00 + (e10 - e00) x_c + (0 - e10) x_d + (e01 + e10 - e00) (1 - x_c) x_d
      move[p.first] += e10 - e00;
      move[p.second] -= e10;
      const float edge = e01 + e10 - e00;  // >= 0 for a metric (Potts)
      graph[p.forward].capacity = edge;
      graph[p.backward].capacity = 0.0f;
    }
    for (std::size_t v = 0; v < cells.size(); ++v) {
      const float m = std::min(keep[v], move[v]);
      graph[from_source[v]].capacity = move[v] - m;  // paid when v takes alpha (sink side)
      graph[to_sink[v]].capacity = keep[v] - m;      // paid when v keeps (source side)
      graph[graph[from_source[v]].reverse].capacity = 0.0f;
      graph[graph[to_sink[v]].reverse].capacity = 0.0f;
    }
  }

  // The minimum cut of the expansion (Boykov-Kolmogorov), and the cells on its sink side that
  // do not have alpha yet: those that take it.
  void cut(const std::vector<std::uint8_t>& labelling, std::size_t alpha,
           std::vector<std::size_t>& moved) {
    boost::boykov_kolmogorov_max_flow(
        graph, boost::get(&EdgeData::capacity, graph), boost::get(&EdgeData::residual, graph),
        boost::get(&EdgeData::reverse, graph), boost::get(&VertexData::predecessor, graph),
        boost::get(&VertexData::colour, graph), boost::get(&VertexData::distance, graph),
        boost::get(boost::vertex_index, graph), source, sink);
    const boost::default_color_type source_colour = graph[source].colour;
    moved.clear();
    for (std::size_t v = 0; v < cells.size(); ++v)
      if (graph[v].colour != source_colour && labelling[cells[v]] != alpha) moved.push_back(v);
  }

  // The Potts terms of the pairs of the `moved` cells (each pair once; in_moved marks them).
  double moved_pair_terms(const Terms& t, const std::vector<std::uint8_t>& labelling,
                          const std::vector<std::size_t>& moved,
                          const std::vector<std::uint8_t>& in_moved) const {
    double e = 0.0;
    for (const std::size_t v : moved)
      for (std::size_t k = pair_start[v]; k < pair_start[v + 1]; ++k) {
        const Pair& p = pairs[pair_of[k]];
        const std::size_t other = p.first == v ? p.second : p.first;
        // A pair between two moved cells is counted from its first cell only.
        if (in_moved[other] && other < v) continue;
        if (labelling[p.grid] != labelling[cells[p.second]]) e += t.weight(p);
      }
    return e;
  }
};

GridLabelling::GridLabelling(int width, int height, const std::vector<std::uint8_t>& active,
                             int labels)
    : impl_(std::make_unique<Impl>()), width_(width), height_(height), labels_(labels) {
  if (width <= 0 || height <= 0 || labels < 1 || labels > 255 ||
      active.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    throw std::invalid_argument("GridLabelling: the active mask does not match the grid");
  const std::size_t n = active.size();
  std::vector<std::size_t> vertex_of(n, std::numeric_limits<std::size_t>::max());
  Impl& g = *impl_;
  for (std::size_t c = 0; c < n; ++c)
    if (active[c]) {
      vertex_of[c] = g.cells.size();
      g.cells.push_back(c);
    }
  const std::size_t cells = g.cells.size();
  for (std::size_t v = 0; v < cells; ++v) {
    const std::size_t c = g.cells[v];
    const int i = static_cast<int>(c % static_cast<std::size_t>(width));
    const int j = static_cast<int>(c / static_cast<std::size_t>(width));
    for (const bool right : {true, false}) {
      if (right ? i + 1 >= width : j + 1 >= height) continue;
      const std::size_t d = right ? c + 1 : c + static_cast<std::size_t>(width);
      if (!active[d]) continue;
      Pair p;
      p.first = v;
      p.second = vertex_of[d];
      p.grid = c;
      p.right = right;
      g.pairs.push_back(p);
    }
  }
  g.pair_start.assign(cells + 1, 0);
  for (const Pair& p : g.pairs) {
    ++g.pair_start[p.first + 1];
    ++g.pair_start[p.second + 1];
  }
  for (std::size_t v = 0; v < cells; ++v) g.pair_start[v + 1] += g.pair_start[v];
  g.pair_of.resize(2 * g.pairs.size());
  std::vector<std::size_t> fill(g.pair_start.begin(), g.pair_start.end() - 1);
  for (std::size_t k = 0; k < g.pairs.size(); ++k) {
    g.pair_of[fill[g.pairs[k].first]++] = k;
    g.pair_of[fill[g.pairs[k].second]++] = k;
  }

  // Edges sorted by their source vertex: each cell's to the sink, to the source, then to its
  // pair neighbours in pair_of order; then the source's to every cell, the sink's to every cell.
  // Edge e's index is its place in this list.
  g.source = cells;
  g.sink = cells + 1;
  auto first_edge = [&](std::size_t v) { return 2 * v + g.pair_start[v]; };
  const std::size_t from_source_0 = first_edge(cells), from_sink_0 = from_source_0 + cells;
  std::vector<std::pair<Vertex, Vertex>> edges;
  edges.reserve(from_sink_0 + cells);
  for (std::size_t v = 0; v < cells; ++v) {
    edges.emplace_back(v, g.sink);
    edges.emplace_back(v, g.source);
    for (std::size_t k = g.pair_start[v]; k < g.pair_start[v + 1]; ++k) {
      const Pair& p = g.pairs[g.pair_of[k]];
      edges.emplace_back(v, p.first == v ? p.second : p.first);
    }
  }
  for (std::size_t v = 0; v < cells; ++v) edges.emplace_back(g.source, v);
  for (std::size_t v = 0; v < cells; ++v) edges.emplace_back(g.sink, v);
  g.graph = Graph(boost::edges_are_sorted, edges.begin(), edges.end(), cells + 2, edges.size());
  auto link = [&](Edge a, Edge b) {
    g.graph[a].reverse = b;
    g.graph[b].reverse = a;
  };
  g.from_source.reserve(cells);
  g.to_sink.reserve(cells);
  for (std::size_t v = 0; v < cells; ++v) {
    g.to_sink.emplace_back(v, first_edge(v));
    g.from_source.emplace_back(g.source, from_source_0 + v);
    link(g.to_sink.back(), Edge(g.sink, from_sink_0 + v));
    link(Edge(v, first_edge(v) + 1), g.from_source.back());
    for (std::size_t k = g.pair_start[v]; k < g.pair_start[v + 1]; ++k) {
      Pair& p = g.pairs[g.pair_of[k]];
      (p.first == v ? p.forward : p.backward) = Edge(v, first_edge(v) + 2 + (k - g.pair_start[v]));
    }
  }
  for (const Pair& p : g.pairs) link(p.forward, p.backward);
}

GridLabelling::~GridLabelling() = default;

double GridLabelling::minimise(const std::vector<float>& cost,
                               const std::vector<float>& right_weight,
                               const std::vector<float>& down_weight,
                               std::vector<std::uint8_t>& labelling, int cycles) {
  const std::size_t n = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  const auto labels = static_cast<std::size_t>(labels_);
  if (cost.size() != n * labels || right_weight.size() != n || down_weight.size() != n ||
      labelling.size() != n)
    throw std::invalid_argument("GridLabelling::minimise: sizes do not match the grid");
  Impl& g = *impl_;
  const Terms terms{cost, right_weight, down_weight, labels};
  double best = g.energy(terms, labelling);
  std::vector<float> keep(g.cells.size()), move(g.cells.size());
  std::vector<std::size_t> moved;
  std::vector<std::uint8_t> in_moved(g.cells.size(), 0), old_label(g.cells.size(), 0);
  for (int cycle = 0; cycle < cycles; ++cycle) {
    bool improved = false;
    for (std::size_t alpha = 0; alpha < labels; ++alpha) {
      const bool takeable = std::any_of(g.cells.begin(), g.cells.end(), [&](std::size_t c) {
        return labelling[c] != alpha && cost[c * labels + alpha] < kExcludedCost;
      });
      if (!takeable) continue;
      g.set_expansion(terms, labelling, alpha, keep, move);
      g.cut(labelling, alpha, moved);
      if (moved.empty()) continue;
      // The energy change of the cells that take alpha: their unary terms and the Potts terms
      // of their pairs (each pair once), old labels against new.
      for (const std::size_t v : moved) in_moved[v] = 1;
      double change = -g.moved_pair_terms(terms, labelling, moved, in_moved);
      for (const std::size_t v : moved) {
        const std::size_t c = g.cells[v];
        change += cost[c * labels + alpha] - cost[c * labels + labelling[c]];
        old_label[v] = labelling[c];
        labelling[c] = static_cast<std::uint8_t>(alpha);
      }
      change += g.moved_pair_terms(terms, labelling, moved, in_moved);
      if (change < -1e-6 * std::max(1.0, std::abs(best))) {
        best += change;
        improved = true;
      } else {
        // An exact expansion never raises the energy; in floating point a tie may: keep the old.
        for (const std::size_t v : moved) labelling[g.cells[v]] = old_label[v];
      }
      for (const std::size_t v : moved) in_moved[v] = 0;
    }
    if (!improved) break;
  }
  return best;
}

}  // namespace sonoshape::segmentation::detail
