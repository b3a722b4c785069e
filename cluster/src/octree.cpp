// The adaptive octree: bottom-up merging of sibling clusters on the fine power-of-two grid.
//
// Nodes are Morton prefixes of the fine cells. Every cluster sits at one node: a fine cell starts at its
// parent, and a node whose children have all merged into a single cluster hands that cluster up to its own
// parent. Two clusters at the same node may merge; the cost of a merge is the increase of quadric error,
// E(a + b) - E(a) - E(b), with E a cluster's placement quadric at its representative (many times more for two
// clusters no input triangle joins). The cheapest merge (then the lowest pair of cluster ids) goes first, one
// pair at a time, so the cluster count steps down by exactly one; a node's merges wait until each of its
// child nodes has merged its own clusters up to itself.
//
// The bookkeeping is laid out for the merge loop's memory traffic. A node's pair costs live in a small
// triangular table of its child slots, with the merged cluster's error, so a merge recomputes only the
// survivor's pairs, places nothing twice, and no cost is ever stale; a heap holds one entry per node (its
// cheapest pair) and is updated in place. The face count of a face target is not tracked merge by merge:
// it can only fall as clusters merge, so the loop runs in batches sized to reach the target, recounts the
// (shrinking) list of distinct faces after each batch, and finds the exact stopping merge inside the batch
// that crossed the target by bisection. Clusters left without a face are found the same way, by counting
// at chosen points of the merge sequence (see FacedClusters), never merge by merge.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>

#include "ocsimp/core/big_vector.h"
#include "place.h"
#include "regroup.h"

namespace ocsimp::cluster_detail {
namespace {

constexpr std::uint32_t kEnd = ~std::uint32_t{0};
constexpr std::size_t kNone = ~std::size_t{0};

// Merging clusters that no input triangle joins costs this many times its error increase: such a union is
// not a connected region and its output triangles fold over its neighbours', so it should wait, but not for
// every neighbour merge however expensive (that leaves small clusters stranded beside large ones). Measured
// on the shared scans and a generated 10 M scan (bench/cluster_quality.sh, octree at 10, 2 and 0.5 % of the
// faces): x4 kept folds that set the scan's Hausdorff distance (2.4x the uniform grid's at 0.5 %); x16-x32
// left some; x64 removed them; x128-x1000 left stray single cells as clusters of their own (vertices without
// faces, holes) and lost RMS.
constexpr double kDetachedPenalty = 64.0;

// A node's cheapest merge; the order is total (cost, then the pair's ids), so the merge sequence does not
// depend on how the heap happens to be laid out.
struct Best {
  double cost;
  std::uint32_t a, b;  // a < b
  std::uint32_t node;
};
bool before(const Best& x, const Best& y) {
  if (x.cost != y.cost) return x.cost < y.cost;
  if (x.a != y.a) return x.a < y.a;
  return x.b < y.b;
}

// 4-ary min-heap of the nodes' cheapest merges with the nodes' positions, so that a node's entry is
// replaced rather than pushed anew. An entry leaves out the pair's second cluster: the first sits at only one
// node, so two entries never tie on (cost, first), and 16 bytes put four siblings in a cache line or two.
class NodeHeap {
 public:
  explicit NodeHeap(std::size_t nodes) : position_(nodes, kEnd) {}
  bool empty() const { return heap_.empty(); }
  std::uint32_t top() const { return heap_.front().node; }
  // The cheapest of the top entry's children: the node most often on top once the top's merge is done (kEnd
  // when there is none).
  std::uint32_t runner_up() const {
    const std::size_t last = std::min<std::size_t>(5, heap_.size());
    std::size_t best = 1;
    for (std::size_t c = 2; c < last; ++c) {
      if (before(heap_[c], heap_[best])) best = c;
    }
    return best < last ? heap_[best].node : kEnd;
  }

  // Sets the node's entry (inserting it when absent).
  void set(const Best& best) {
    const Entry entry{best.cost, best.a, best.node};
    std::uint32_t i = position_[best.node];
    if (i == kEnd) {
      i = static_cast<std::uint32_t>(heap_.size());
      heap_.push_back(entry);
      up(i, entry);
      return;
    }
    if (before(entry, heap_[i])) {
      up(i, entry);
    } else {
      down(i, entry);
    }
  }
  void erase(std::uint32_t node) {
    const std::uint32_t i = position_[node];
    if (i == kEnd) return;
    position_[node] = kEnd;
    const Entry last = heap_.back();
    heap_.pop_back();
    if (i == heap_.size()) return;
    if (before(last, heap_[i])) {
      up(i, last);
    } else {
      down(i, last);
    }
  }
  // Builds the heap from entries of distinct nodes at once.
  void assign(const std::vector<Best>& entries) {
    heap_.clear();
    for (const Best& b : entries) heap_.push_back({b.cost, b.a, b.node});
    for (std::size_t i = heap_.size() / 4 + 1; i-- > 0;) {
      if (i < heap_.size()) down(static_cast<std::uint32_t>(i), heap_[i]);
    }
    for (std::size_t i = 0; i < heap_.size(); ++i) position_[heap_[i].node] = static_cast<std::uint32_t>(i);
  }

 private:
  struct Entry {
    double cost;
    std::uint32_t a, node;
  };
  static bool before(const Entry& x, const Entry& y) {
    return x.cost != y.cost ? x.cost < y.cost : x.a < y.a;
  }
  // Moves `item` from position i towards the root to where it belongs.
  void up(std::uint32_t i, const Entry item) {
    while (i > 0) {
      const std::uint32_t parent = (i - 1) / 4;
      if (!before(item, heap_[parent])) break;
      heap_[i] = heap_[parent];
      position_[heap_[i].node] = i;
      i = parent;
    }
    heap_[i] = item;
    position_[item.node] = i;
  }
  void down(std::uint32_t i, const Entry item) {
    const std::size_t size = heap_.size();
    for (;;) {
      const std::size_t first = 4 * std::size_t{i} + 1;
      if (first >= size) break;
      std::size_t child = first;
      const std::size_t last = std::min(first + 4, size);
      for (std::size_t c = first + 1; c < last; ++c) {
        if (before(heap_[c], heap_[child])) child = c;
      }
      if (!before(heap_[child], item)) break;
      heap_[i] = heap_[child];
      position_[heap_[i].node] = i;
      i = static_cast<std::uint32_t>(child);
    }
    heap_[i] = item;
    position_[item.node] = i;
  }

  std::vector<Entry> heap_;
  std::vector<std::uint32_t> position_;
};

// An internal node of the octree: its child slots, where their pairs are stored, and how far it is from
// handing a single cluster up. One cache line: the merge loop reaches nodes in no order.
struct alignas(64) Node {
  std::uint64_t pairs = 0;  // first of its children * (children - 1) / 2 pairs
  std::array<std::uint32_t, 8> member{kEnd, kEnd, kEnd, kEnd, kEnd, kEnd, kEnd, kEnd};  // per slot, or kEnd
  std::uint32_t parent = kEnd;
  std::uint8_t children = 0;
  std::uint8_t pending = 0;  // children still to hand their cluster up
  std::uint8_t present = 0;  // clusters sitting at the node
  std::uint8_t octant = 0;   // which octant of its parent it is (the low three bits of its Morton prefix)
  std::uint8_t slot = 0;     // which of its parent's slots it fills (children are numbered in Morton order)
  // Its cheapest pair, the one its heap entry stands for: the merge needs no look into the pair table.
  std::uint8_t best_i = 0, best_j = 0;
  double best_error = 0;
};
static_assert(sizeof(Node) == 64);

// A pair of clusters at a node: its merge cost, and the merged cluster's error, which the merge takes over.
struct Pair {
  double cost, error;
};

struct Cluster {
  PlacementSums sums;
  double error = 0;
  std::uint32_t node = kEnd;  // the node it sits at (kEnd: above the root)
  std::uint8_t octants = 0;   // the octants of its node it covers (neighbours: see `joined`)
  std::uint8_t slot = 0;      // which of the node's slots it fills
};

}  // namespace
}  // namespace ocsimp::cluster_detail

namespace ocsimp {
// Cluster records are written in full by the loop that fills them (octree_merge).
template <>
inline constexpr bool filled_after_resize<cluster_detail::Cluster> = true;
}  // namespace ocsimp

namespace ocsimp::cluster_detail {
namespace {

// A triangle of three distinct cluster ids, ascending.
struct Face {
  std::uint32_t a, b, c;
};

// The distinct faces a clustering leaves of a list of faces, each corner mapped through `label`. The faces
// are bucketed by their lowest label (a counting sort) and each bucket is deduplicated on its own: ids of
// nearby cells are close and the list keeps the order of its lowest labels, so both passes run nearly
// sequentially through memory, where a hash set of faces would miss the cache on every face.
class FaceCounter {
 public:
  // The count, `label` mapping to ids below `labels`; with `kept`, also the distinct faces themselves,
  // ordered by (a, b, c).
  template <class Label>
  std::size_t count(const std::vector<Face>& faces, std::size_t labels, Label&& label,
                    std::vector<Face>* kept) {
    end_.assign(labels + 1, 0);
    relabelled_.clear();
    for (const Face& f : faces) {
      std::uint32_t a = label(f.a), b = label(f.b), c = label(f.c);
      if (a == b || b == c || c == a) continue;
      if (a > b) std::swap(a, b);
      if (b > c) std::swap(b, c);
      if (a > b) std::swap(a, b);
      relabelled_.push_back({a, b, c});
      ++end_[a + 1];
    }
    for (std::size_t i = 1; i < end_.size(); ++i) end_[i] += end_[i - 1];
    bucketed_.resize(relabelled_.size());
    for (const Face& f : relabelled_) bucketed_[end_[f.a]++] = f;
    if (kept) kept->clear();
    std::size_t distinct = 0;
    auto later = [](const Face& x, const Face& y) { return x.b != y.b ? x.b < y.b : x.c < y.c; };
    for (std::size_t begin = 0; begin < bucketed_.size();) {
      std::size_t end = begin + 1;
      while (end < bucketed_.size() && bucketed_[end].a == bucketed_[begin].a) ++end;
      Face* run = bucketed_.data();
      std::sort(run + begin, run + end, later);
      for (std::size_t i = begin; i < end; ++i) {
        if (i > begin && run[i].b == run[i - 1].b && run[i].c == run[i - 1].c) continue;
        ++distinct;
        if (kept) kept->push_back(run[i]);
      }
      begin = end;
    }
    return distinct;
  }

 private:
  std::vector<std::size_t> end_;
  std::vector<Face> relabelled_, bucketed_;
};

std::uint32_t find_root(std::vector<std::uint32_t>& up, std::uint32_t x) {
  std::uint32_t r = x;
  while (up[r] != r) r = up[r];
  while (up[x] != r) {
    const std::uint32_t next = up[x];
    up[x] = r;
    x = next;
  }
  return r;
}

using Merges = std::vector<std::array<std::uint32_t, 2>>;

// The vertices the clusters make after the first m merges of a merge sequence. A cluster all of whose fine
// triangles have collapsed is a vertex of no face: an output point that spends the vertex budget and shows
// nothing. A "stray" one, which a collapsed triangle links to another cluster, joins that cluster instead;
// the others (a part of the input smaller than a cluster, or cells whose every triangle collapsed inside
// them) stay points. So the vertices are the clusters less the strays.
class ClusterVertices {
 public:
  ClusterVertices(const CellTriangles& triangles, std::size_t cells) : triangles_(triangles), root_(cells) {}

  // The state after the first m merges, cell by cell: the cluster holding a fine cell (named by its lowest
  // cell) and whether it is a stray. Returns the vertices.
  std::size_t settle(const Merges& merges, std::size_t m) {
    replay(merges, m);
    flags_.assign(root_.size(), 0);
    for (const CellTriangle& t : triangles_) mark({root(t.first()), root(t.second()), root(t.third())});
    return root_.size() - m - strays(root_.size());
  }
  std::uint32_t root(std::uint32_t cell) { return find_root(root_, cell); }
  bool stray(std::uint32_t root) const { return flags_[root] == kLinked; }
  // Joins two clusters of the settled state, given by their roots.
  void join(std::uint32_t a, std::uint32_t b) { root_[std::max(a, b)] = std::min(a, b); }

  // Counts from here on are of `m` merges or more. They need only the fine triangles whose corners lie in
  // two or three clusters after the first m merges, over those clusters numbered densely: a count is then a
  // pass over about the output's triangles, not the fine ones.
  void start_at(const Merges& merges, std::size_t m) {
    replay(merges, m);
    base_ = m;
    dense_.assign(root_.size(), kEnd);
    ids_ = 0;
    linking_.clear();
    for (const CellTriangle& t : triangles_) {
      const std::uint32_t a = root(t.first()), b = root(t.second()), c = root(t.third());
      if (a != b || b != c) linking_.push_back({dense(a), dense(b), dense(c)});
    }
  }
  // The vertices after the first m merges, m not below start_at's.
  std::size_t count(const Merges& merges, std::size_t m) {
    for (std::size_t k = base_; k < m; ++k) {
      dense(merges[k][0]);
      dense(merges[k][1]);
    }
    up_.resize(ids_);
    for (std::uint32_t i = 0; i < ids_; ++i) up_[i] = i;
    for (std::size_t k = base_; k < m; ++k) up_[dense_[merges[k][1]]] = dense_[merges[k][0]];
    flags_.assign(ids_, 0);
    for (const Face& f : linking_) mark({find_root(up_, f.a), find_root(up_, f.b), find_root(up_, f.c)});
    return root_.size() - m - strays(ids_);
  }

 private:
  static constexpr std::uint8_t kLinked = 1, kFaced = 2;

  void replay(const Merges& merges, std::size_t m) {
    for (std::size_t i = 0; i < root_.size(); ++i) root_[i] = static_cast<std::uint32_t>(i);
    for (std::size_t k = 0; k < m; ++k) root_[merges[k][1]] = merges[k][0];
  }

  // Flags the clusters of a fine triangle: a face for each when they are three, a link for each when two.
  void mark(const std::array<std::uint32_t, 3>& r) {
    if (r[0] == r[1] && r[1] == r[2]) return;
    const bool face = r[0] != r[1] && r[1] != r[2] && r[2] != r[0];
    for (std::uint32_t c : r) flags_[c] |= face ? kFaced : kLinked;
  }
  std::size_t strays(std::size_t clusters) const {
    return static_cast<std::size_t>(std::count(flags_.begin(), flags_.begin() + clusters, kLinked));
  }
  // Clusters after start_at's merges get dense ids as they are first met (merges after it only join them).
  std::uint32_t dense(std::uint32_t cluster) {
    std::uint32_t& d = dense_[cluster];
    if (d == kEnd) d = ids_++;
    return d;
  }

  const CellTriangles& triangles_;
  std::vector<std::uint32_t> root_;
  std::vector<std::uint8_t> flags_;  // of roots only
  std::size_t base_ = 0;
  std::vector<std::uint32_t> dense_, up_;
  std::uint32_t ids_ = 0;
  std::vector<Face> linking_;
};

// Position of the pair of child slots i < j in a node's triangular cost table.
inline std::size_t pair_index(std::uint32_t i, std::uint32_t j) {
  return std::size_t{j} * (j - 1) / 2 + i;
}

}  // namespace

Clustering octree_merge(const FineCells& cells, const OctreeTarget& target, Representative representative,
                        double boundary_weight, const ProgressFn& progress) {
  const std::size_t n = cells.size();
  const int levels = std::max(0, cells.grid.level);
  Clustering result;
  result.cluster_of.resize(n);

  // Nodes: the Morton prefixes of the fine cells at each level; level `levels` is the fine cells themselves.
  std::vector<std::vector<std::uint64_t>> prefix(levels + 1);
  std::vector<std::vector<std::uint32_t>> parent(levels + 1);
  prefix[levels].resize(n);
  for (std::size_t i = 0; i < n; ++i) prefix[levels][i] = morton(cells.keys[i]);
  for (int l = levels; l > 0; --l) {
    const std::vector<std::uint64_t>& below = prefix[l];
    std::vector<std::uint64_t>& above = prefix[l - 1];
    parent[l].resize(below.size());
    for (std::size_t i = 0; i < below.size(); ++i) {
      const std::uint64_t p = below[i] >> 3;
      if (above.empty() || above.back() != p) above.push_back(p);
      parent[l][i] = static_cast<std::uint32_t>(above.size() - 1);
    }
  }
  // Internal nodes (levels 0 .. levels-1) get one global numbering.
  std::vector<std::uint32_t> offset(levels + 1, 0);
  for (int l = 1; l <= levels; ++l)
    offset[l] = offset[l - 1] + static_cast<std::uint32_t>(prefix[l - 1].size());
  const std::size_t nodes = offset[levels];
  // The large arrays of the merge (about 190 bytes a fine cell in all) on huge pages: see BigVector.
  BigVector<Node> node(nodes);
  std::vector<std::uint32_t> cell_node(n, kEnd);
  std::vector<std::uint8_t> cell_octant(n, 0), cell_slot(n, 0);
  for (int l = 1; l <= levels; ++l) {
    for (std::size_t i = 0; i < prefix[l].size(); ++i) {
      const std::uint32_t up = offset[l - 1] + parent[l][i];
      const std::uint8_t slot = node[up].children++;
      const auto octant = static_cast<std::uint8_t>(prefix[l][i] & 7);
      if (l < levels) {
        Node& v = node[offset[l] + i];
        v.parent = up;
        v.octant = octant;
        v.slot = slot;
      } else {
        cell_node[i] = up;
        cell_octant[i] = octant;
        cell_slot[i] = slot;
      }
    }
  }
  // Which octants of a node the surface joins: for every two cells of a surviving fine triangle, the two
  // octants of their lowest common node that hold them. Two clusters at a node are neighbours when one of
  // them covers an octant joined to an octant the other covers. Octants that merely share a face can hold
  // cells several cells apart, and merging those made long triangles across the surface. A bitwise OR per
  // triangle, so the result does not depend on the order or the threads.
  std::vector<std::uint64_t> joined(nodes, 0);
  {
    const std::vector<std::uint64_t>& fine = prefix[levels];
    tbb::parallel_for(std::size_t{0}, cells.triangles.size(), [&](std::size_t t) {
      const CellTriangle& triangle = cells.triangles[t];
      const std::uint32_t corner[3] = {triangle.first(), triangle.second(), triangle.third()};
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t u = corner[k], w = corner[k == 2 ? 0 : k + 1];
        const std::uint64_t mu = fine[u], mw = fine[w];
        // Levels from the cells' parent up to their lowest common node.
        const int up = (63 - std::countl_zero(mu ^ mw)) / 3;
        std::uint32_t id = cell_node[u];
        for (int i = 0; i < up; ++i) id = node[id].parent;
        const auto ou = static_cast<unsigned>(mu >> (3 * up)) & 7,
                   ow = static_cast<unsigned>(mw >> (3 * up)) & 7;
        const std::uint64_t bits = (std::uint64_t{1} << (8 * ou + ow)) | (std::uint64_t{1} << (8 * ow + ou));
        std::atomic_ref<std::uint64_t>(joined[id]).fetch_or(bits, std::memory_order_relaxed);
      }
    });
  }
  prefix = {};
  parent = {};
  std::uint64_t pairs_total = 0;
  for (Node& v : node) {
    v.pending = v.children;
    v.pairs = pairs_total;
    pairs_total += std::uint64_t{v.children} * (v.children - 1) / 2;
  }
  BigVector<Pair> pairs(pairs_total);  // each written before it is read (see pair_up)

  // Clusters start as the fine cells.
  BigVector<Cluster> cluster(n);  // filled in full here (filled_after_resize)
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
    const PlacementSums sums = cell_placement_sums(cells, i, boundary_weight);
    cluster[i] = Cluster{sums, place(sums, representative).error};  // the rest as Cluster defaults them
  });
  // The sums are added lower id first, as the merge itself adds them, so the pair holds the merge's error.
  auto pair_of = [&](std::uint32_t a, std::uint32_t b) {
    if (a > b) std::swap(a, b);
    const Cluster &x = cluster[a], &y = cluster[b];
    // The octant masks change as clusters move up: the neighbour test is of this moment.
    bool detached = true;
    const std::uint64_t row = joined[x.node];
    for (unsigned o = 0; o < 8; ++o) {
      if ((x.octants >> o & 1) && ((row >> (8 * o)) & y.octants)) detached = false;
    }
    PlacementSums merged = x.sums;
    merged.add(y.sums);
    const double error = place(merged, representative).error;
    const double cost = error - x.error - y.error;
    return Pair{detached ? cost * kDetachedPenalty : cost, error};
  };
  // The node's clusters and pairs lie scattered: ask for all of them before the first is needed.
  auto prefetch = [&](const Node& v) {
    for (std::uint32_t k = 0; k < v.children; ++k) {
      if (v.member[k] == kEnd) continue;
      const char* p = reinterpret_cast<const char*>(&cluster[v.member[k]]);
      for (std::size_t line = 0; line < sizeof(Cluster); line += 64) __builtin_prefetch(p + line);
    }
    const char* p = reinterpret_cast<const char*>(&pairs[v.pairs]);
    for (std::size_t line = 0; line < sizeof(Pair) * v.children * (v.children - 1) / 2; line += 64) {
      __builtin_prefetch(p + line);
    }
  };
  // Costs of cluster c's pairs with the other clusters at its node.
  auto pair_up = [&](std::uint32_t c) {
    const Node& v = node[cluster[c].node];
    const std::uint32_t s = cluster[c].slot;
    const std::uint32_t* slot = v.member.data();
    Pair* pair = &pairs[v.pairs];
    for (std::uint32_t k = 0; k < v.children; ++k) {
      if (k == s || slot[k] == kEnd) continue;
      pair[k < s ? pair_index(k, s) : pair_index(s, k)] = pair_of(c, slot[k]);
    }
  };
  // The node's cheapest pair; false when fewer than two clusters sit there.
  // Remembers it in the node.
  auto best_of = [&](std::uint32_t id, Best& best) {
    Node& v = node[id];
    const std::uint32_t* slot = v.member.data();
    const Pair* pair = &pairs[v.pairs];
    bool found = false;
    for (std::uint32_t j = 1; j < v.children; ++j) {
      if (slot[j] == kEnd) continue;
      for (std::uint32_t i = 0; i < j; ++i) {
        if (slot[i] == kEnd) continue;
        const Best candidate{pair[pair_index(i, j)].cost, std::min(slot[i], slot[j]),
                             std::max(slot[i], slot[j]), id};
        if (!found || before(candidate, best)) {
          best = candidate;
          v.best_i = static_cast<std::uint8_t>(i);
          v.best_j = static_cast<std::uint8_t>(j);
        }
        found = true;
      }
    }
    if (found) v.best_error = pair[pair_index(v.best_i, v.best_j)].error;
    return found;
  };
  // Cluster c is the whole of a child of node `id`: it takes its slot there and, while it is the whole of
  // the node too, moves on up. Returns the node it stays at (kEnd above the root).
  std::vector<std::uint32_t> completed;  // nodes whose last child handed its cluster up, since last looked at
  auto arrive = [&](std::uint32_t c, std::uint32_t id, std::uint8_t octant, std::uint8_t slot) {
    Cluster& x = cluster[c];
    while (id != kEnd) {
      Node& v = node[id];
      x.octants = static_cast<std::uint8_t>(1u << octant);
      if (--v.pending == 0) completed.push_back(id);
      if (v.pending != 0 || v.present != 0) {
        v.member[slot] = c;
        ++v.present;
        x.node = id;
        x.slot = slot;
        return id;
      }
      octant = v.octant;
      slot = v.slot;
      id = v.parent;
    }
    x.node = kEnd;
    return kEnd;
  };
  for (std::size_t i = 0; i < n; ++i) {
    arrive(static_cast<std::uint32_t>(i), cell_node[i], cell_octant[i], cell_slot[i]);
  }
  cell_node = {};
  // A node merges only once each of its child nodes has merged all of its own clusters up to itself: merges
  // then climb the levels together, and a cluster does not grow at a node while finer clusters beside it are
  // still forming below (big clusters next to small ones make the long, folded triangles). `waiting` counts a
  // node's child nodes still forming.
  completed.clear();
  std::vector<std::uint8_t> waiting(nodes, 0);
  for (std::uint32_t id = 0; id < nodes; ++id) {
    if (node[id].pending > 0 && node[id].parent != kEnd) ++waiting[node[id].parent];
  }
  cell_octant = {};
  cell_slot = {};
  // The first costs, a placement each and most of the merge's arithmetic, are taken in parallel, node by
  // node; every pair's cost is what it would be had it been taken as its second cluster arrived.
  NodeHeap heap(nodes);
  {
    tbb::parallel_for(std::size_t{0}, nodes, [&](std::size_t id) {
      const Node& v = node[id];
      if (v.present < 2) return;
      const std::uint32_t* slot = v.member.data();
      Pair* pair = &pairs[v.pairs];
      for (std::uint32_t j = 1; j < v.children; ++j) {
        if (slot[j] == kEnd) continue;
        for (std::uint32_t i = 0; i < j; ++i) {
          if (slot[i] != kEnd) pair[pair_index(i, j)] = pair_of(slot[i], slot[j]);
        }
      }
    });
    std::vector<Best> entries;
    for (std::size_t id = 0; id < nodes; ++id) {
      Best best{};
      if (node[id].present >= 2 && waiting[id] == 0 && best_of(static_cast<std::uint32_t>(id), best))
        entries.push_back(best);
    }
    heap.assign(entries);
  }

  // The merges in order, survivor (the lower id) first.
  std::vector<std::array<std::uint32_t, 2>> merges;
  const std::size_t expected = target.faces > 0 ? 0 : (n > target.vertices ? n - target.vertices : 0);
  merges.reserve(expected);
  // Puts node id's cheapest pair in the heap when it may merge now: two clusters there, no child node still
  // forming.
  auto offer = [&](std::uint32_t id) {
    Best best{};
    if (node[id].present >= 2 && waiting[id] == 0 && best_of(id, best)) heap.set(best);
  };
  auto merge_top = [&] {
    if (heap.empty()) return false;
    const std::uint32_t id = heap.top();
    Node& v = node[id];
    prefetch(v);
    // The loop waits on memory: the next merge's node record and neighbour row are fetched now, its clusters
    // and pairs once this merge is done (merge_next). 6.2 -> 5.3 s for the 4 M merges of a 10 M-triangle
    // scan to 1 M faces.
    if (const std::uint32_t next = heap.runner_up(); next != kEnd) {
      __builtin_prefetch(&node[next]);
      __builtin_prefetch(&joined[next]);
    }
    const std::uint32_t a = std::min(v.member[v.best_i], v.member[v.best_j]);
    const std::uint32_t b = std::max(v.member[v.best_i], v.member[v.best_j]);
    Cluster &x = cluster[a], &y = cluster[b];
    x.sums.add(y.sums);
    x.octants |= y.octants;
    x.error = v.best_error;
    v.member[y.slot] = kEnd;
    y.node = kEnd;
    --v.present;
    merges.push_back({a, b});
    if (merges.size() % 4096 == 0) report(progress, "cluster: merge", merges.size(), expected);
    if (v.pending == 0 && v.present == 1) {
      // a is the whole node now: it leaves for the parent and pairs with the clusters there.
      heap.erase(id);
      v.member[x.slot] = kEnd;
      v.present = 0;
      const std::uint32_t up = arrive(a, v.parent, v.octant, v.slot);
      if (up != kEnd && node[up].present >= 2) {
        prefetch(node[up]);
        pair_up(a);
        offer(up);
      }
      for (const std::uint32_t done : completed) {
        const std::uint32_t p = node[done].parent;
        if (p != kEnd && --waiting[p] == 0) offer(p);
      }
      completed.clear();
      return true;
    }
    if (v.present >= 2) {
      pair_up(a);
      offer(id);
    } else {
      heap.erase(id);
    }
    return true;
  };
  auto merge_next = [&] {
    if (!merge_top()) return false;
    if (!heap.empty()) prefetch(node[heap.top()]);
    return true;
  };

  std::size_t kept = 0;
  if (target.faces == 0) {
    while (n - merges.size() > target.vertices && merge_next()) {
    }
    kept = merges.size();
    result.target_met = n - kept == target.vertices;
  } else {
    // The face count after m merges only falls with m; find the first m at which it is within the target.
    std::vector<Face> faces;
    faces.reserve(cells.triangles.size());
    for (const CellTriangle& t : cells.triangles) faces.push_back({t.first(), t.second(), t.third()});
    std::vector<std::uint32_t> root(n);
    for (std::size_t i = 0; i < n; ++i) root[i] = static_cast<std::uint32_t>(i);
    FaceCounter counter;
    std::vector<Face> next;
    std::size_t count = faces.size();
    // Faces a merge removes, estimated from the last batch; a fine mesh loses about two a merge. A batch
    // aims short of the target, as a recount costs about one bisection step, until the batch crossing it
    // is short.
    double rate = 2.0;
    result.target_met = count <= target.faces;
    while (count > target.faces) {
      const double gap = static_cast<double>(count - target.faces);
      const double expected_merges = gap / rate;
      const std::size_t batch = expected_merges > 64
                                    ? static_cast<std::size_t>(0.9 * expected_merges)
                                    : static_cast<std::size_t>(std::ceil(expected_merges)) + 4;
      const std::size_t start = merges.size();
      while (merges.size() - start < batch && merge_next()) {
      }
      const std::size_t done = merges.size() - start;
      if (done == 0) break;  // nothing left to merge: the target is out of reach
      for (std::size_t m = start; m < merges.size(); ++m) root[merges[m][1]] = merges[m][0];
      const std::size_t now = counter.count(
          faces, n, [&](std::uint32_t c) { return find_root(root, c); }, &next);
      if (now > target.faces) {
        rate = std::max(static_cast<double>(count - now) / static_cast<double>(done), 1e-3);
        count = now;
        faces.swap(next);
        if (done < batch) break;  // the heap ran dry above the target
        continue;
      }
      // The target was crossed inside this batch: bisect for the first merge count within it. The faces
      // are labelled as at the batch's start; a probe replays a prefix of the batch on top. Only faces with
      // a cluster the batch merges can change, and they stay distinct from the others (they keep such a
      // cluster), so a probe counts those alone, its clusters numbered densely.
      std::vector<std::uint32_t> dense(n, kEnd);
      std::uint32_t ids = 0;
      std::vector<std::array<std::uint32_t, 2>> replay(done);
      for (std::size_t m = 0; m < done; ++m) {
        for (int k = 0; k < 2; ++k) {
          std::uint32_t& d = dense[merges[start + m][k]];
          if (d == kEnd) d = ids++;
          replay[m][k] = d;
        }
      }
      const std::uint32_t involved = ids;
      std::vector<Face> affected;
      for (const Face& f : faces) {
        if (dense[f.a] >= involved && dense[f.b] >= involved && dense[f.c] >= involved) continue;
        Face g;
        for (std::uint32_t Face::*corner : {&Face::a, &Face::b, &Face::c}) {
          std::uint32_t& d = dense[f.*corner];
          if (d == kEnd) d = ids++;
          g.*corner = d;
        }
        affected.push_back(g);
      }
      const std::size_t unaffected = count - affected.size();
      faces.swap(affected);
      dense = {};
      std::vector<std::uint32_t> probe(ids);
      for (std::uint32_t i = 0; i < ids; ++i) probe[i] = i;
      std::size_t lo = 0, hi = done;  // over the target after lo merges of the batch, within it after hi
      while (hi - lo > 1) {
        const std::size_t mid = lo + (hi - lo) / 2;
        for (std::size_t m = 0; m < mid; ++m) probe[replay[m][1]] = replay[m][0];
        const std::size_t faces_mid =
            unaffected + counter.count(
                             faces, ids, [&](std::uint32_t c) { return find_root(probe, c); }, nullptr);
        // Only the merged-away clusters' entries changed (path compression rewrites nothing else).
        for (std::size_t m = 0; m < mid; ++m) probe[replay[m][1]] = replay[m][1];
        if (faces_mid <= target.faces) {
          hi = mid;
        } else {
          lo = mid;
        }
      }
      kept = start + hi;
      count = target.faces;
      result.target_met = true;
    }
    if (!result.target_met) kept = merges.size();
  }

  // Strays (see ClusterVertices). The vertices left once they join their neighbours only fall as merges go
  // on, as the faces do, and a merge that only folds a stray into another cluster leaves them as they are. A
  // vertex target is met by the vertices, and the stop moves on to the last merge that keeps their count, so
  // the merge sequence rather than a stray's first link decides where most strays go; the strays left then
  // join the cluster of another corner of their first linking fine triangle. A count the merges step over
  // (a merge can make two strays) keeps as many strays as points as it takes. Should strays that join each
  // other still break an exact vertex target, the merge stops where the clusters alone number it.
  ClusterVertices vertices(cells.triangles, n);
  // The last merge count from `first` on (where the vertices are `level`) that keeps `level`; `beyond`, when
  // known, is a count with fewer. Merges beyond those made so far are made as needed.
  auto last_keeping = [&](std::size_t first, std::size_t level, std::size_t beyond) {
    std::size_t lo = first, hi = beyond;
    for (std::size_t step = 1; hi == kNone; step *= 2) {
      while (merges.size() < lo + step && merge_next()) {
      }
      const std::size_t probe = std::min(lo + step, merges.size());
      if (vertices.count(merges, probe) < level) {
        hi = probe;
      } else if (probe == merges.size() && probe < lo + step) {
        return probe;  // the heap ran dry
      } else {
        lo = probe;
      }
    }
    while (hi - lo > 1) {
      const std::size_t mid = lo + (hi - lo) / 2;
      (vertices.count(merges, mid) >= level ? lo : hi) = mid;
    }
    return lo;
  };
  const std::size_t all_clusters = kept;
  std::size_t spare = 0;  // strays kept as points
  std::size_t settled = kNone;
  if (result.target_met && target.faces == 0) {
    const std::size_t want = target.vertices;
    const std::size_t short_by = want - vertices.settle(merges, kept);
    settled = kept;
    if (short_by > 0) {
      settled = kNone;
      // The first merge count with no more than `want` vertices: step back until above it (a merge removes
      // about one), then bisect.
      std::size_t hi = kept, lo = kept;
      for (std::size_t step = 2 * short_by + 16;; step *= 2) {
        lo = hi > step ? hi - step : 0;
        vertices.start_at(merges, lo);
        if (vertices.count(merges, lo) > want || lo == 0) break;
        hi = lo;
      }
      while (hi - lo > 1) {
        const std::size_t mid = lo + (hi - lo) / 2;
        (vertices.count(merges, mid) <= want ? hi : lo) = mid;
      }
      if (vertices.count(merges, lo) <= want) hi = lo;  // lo == 0
      const std::size_t level = vertices.count(merges, hi);
      if (level == want) {
        kept = last_keeping(hi, want, kept);
      } else {
        kept = hi;
        spare = want - level;
      }
    }
  } else if (result.target_met) {
    vertices.start_at(merges, kept);
    kept = last_keeping(kept, vertices.count(merges, kept), kNone);
  }
  if (settled != kept) vertices.settle(merges, kept);
  if (result.target_met) {
    // Strays join the cluster of another corner of their first linking fine triangle; the `spare` lowest
    // stay.
    std::vector<std::uint32_t> into(n, kEnd);
    for (const CellTriangle& t : cells.triangles) {
      const std::uint32_t r[3] = {vertices.root(t.first()), vertices.root(t.second()),
                                  vertices.root(t.third())};
      for (int k = 0; k < 3; ++k) {
        if (!vertices.stray(r[k]) || into[r[k]] != kEnd) continue;
        const std::uint32_t other = r[k] != r[(k + 1) % 3] ? r[(k + 1) % 3] : r[(k + 2) % 3];
        if (other != r[k]) into[r[k]] = other;
      }
    }
    std::size_t skipped = 0;
    for (std::uint32_t c = 0; c < n; ++c) {
      if (into[c] == kEnd || skipped++ < spare) continue;
      const std::uint32_t a = vertices.root(c), b = vertices.root(into[c]);
      if (a != b) vertices.join(a, b);
    }
  }
  // Clusters numbered by their first fine cell.
  std::vector<std::uint32_t> id(n);
  auto number = [&] {
    std::fill(id.begin(), id.end(), kEnd);
    result.count = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t r = vertices.root(static_cast<std::uint32_t>(i));
      if (id[r] == kEnd) id[r] = result.count++;
    }
  };
  number();
  if (target.faces == 0 && result.target_met && result.count != target.vertices) {
    // Strays joined each other: stop where the clusters alone number the target.
    vertices.settle(merges, all_clusters);
    number();
  }
  for (std::size_t i = 0; i < n; ++i) result.cluster_of[i] = id[vertices.root(static_cast<std::uint32_t>(i))];
  return result;
}

}  // namespace ocsimp::cluster_detail
