// The adaptive octree: bottom-up merging of sibling clusters on the fine power-of-two grid.
//
// Nodes are Morton prefixes of the fine cells. Every cluster sits at one node: a fine cell starts at its
// parent, and a node whose children have all merged into a single cluster hands that cluster up to its own
// parent. Two clusters at the same node may merge; the cost of a merge is the increase of quadric error,
// E(a + b) - E(a) - E(b), with E a cluster's placement quadric at its representative. A priority queue
// takes the cheapest merge first, one pair at a time, so the cluster count steps down by exactly one.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <functional>
#include <memory>
#include <queue>

#include "place.h"
#include "regroup.h"

namespace ocsimp::cluster_detail {
namespace {

constexpr std::uint32_t kEnd = ~std::uint32_t{0};

// Multiset of triangles of three distinct labels, counting how many fine triangles map onto each.
class TripleCounter {
 public:
  explicit TripleCounter(std::size_t expected) {
    capacity_ = power_of_two_at_least(2 * expected + 16);
    slots_.assign(capacity_, Slot{kEnd, 0, 0, 0});
  }
  std::size_t size() const { return size_; }

  void add(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    sort3(a, b, c);
    std::size_t i = home(a, b, c);
    while (slots_[i].a != kEnd) {
      if (slots_[i].a == a && slots_[i].b == b && slots_[i].c == c) {
        ++slots_[i].count;
        return;
      }
      i = (i + 1) & (capacity_ - 1);
    }
    slots_[i] = {a, b, c, 1};
    if (2 * ++size_ > capacity_) grow();
  }
  void remove(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    sort3(a, b, c);
    std::size_t i = home(a, b, c);
    while (!(slots_[i].a == a && slots_[i].b == b && slots_[i].c == c)) i = (i + 1) & (capacity_ - 1);
    if (--slots_[i].count > 0) return;
    // Backward-shift deletion keeps linear probing free of tombstones.
    std::size_t hole = i;
    for (std::size_t j = (hole + 1) & (capacity_ - 1); slots_[j].a != kEnd; j = (j + 1) & (capacity_ - 1)) {
      const std::size_t h = home(slots_[j].a, slots_[j].b, slots_[j].c);
      const bool movable = hole <= j ? (h <= hole || h > j) : (h <= hole && h > j);
      if (movable) {
        slots_[hole] = slots_[j];
        hole = j;
      }
    }
    slots_[hole].a = kEnd;
    --size_;
  }

 private:
  struct Slot {
    std::uint32_t a, b, c, count;
  };
  static void sort3(std::uint32_t& a, std::uint32_t& b, std::uint32_t& c) {
    if (a > b) std::swap(a, b);
    if (b > c) std::swap(b, c);
    if (a > b) std::swap(a, b);
  }
  std::size_t home(std::uint32_t a, std::uint32_t b, std::uint32_t c) const {
    return mix64((static_cast<std::uint64_t>(a) << 32 | b) ^ mix64(c + 0x9E3779B97F4A7C15ull)) &
           (capacity_ - 1);
  }
  void grow() {
    std::vector<Slot> old = std::move(slots_);
    capacity_ *= 2;
    slots_.assign(capacity_, Slot{kEnd, 0, 0, 0});
    for (const Slot& s : old) {
      if (s.a == kEnd) continue;
      std::size_t i = home(s.a, s.b, s.c);
      while (slots_[i].a != kEnd) i = (i + 1) & (capacity_ - 1);
      slots_[i] = s;
    }
  }

  std::vector<Slot> slots_;
  std::size_t capacity_ = 0;
  std::size_t size_ = 0;
};

// The exact face count of the current clustering, updated merge by merge. Each fine triangle's corners carry
// labels; merging relabels the corners of the smaller side (each corner is relabeled O(log n) times).
class FaceTracker {
 public:
  FaceTracker(const CellTriangles& triangles, std::size_t cells)
      : label_(3 * triangles.size()),
        next_(3 * triangles.size(), kEnd),
        head_(cells, kEnd),
        tail_(cells, kEnd),
        size_(cells, 0),
        faces_(triangles.size()) {
    for (std::size_t t = 0; t < triangles.size(); ++t) {
      const std::uint32_t corner[3] = {triangles[t].first(), triangles[t].second(), triangles[t].third()};
      for (int k = 0; k < 3; ++k) {
        const std::size_t s = 3 * t + k;
        label_[s] = corner[k];
        append(corner[k], static_cast<std::uint32_t>(s));
      }
      faces_.add(corner[0], corner[1], corner[2]);
    }
  }
  std::size_t faces() const { return faces_.size(); }

  // Merges the clusters labelled x and y; returns the label the union carries.
  std::uint32_t merge(std::uint32_t x, std::uint32_t y) {
    if (size_[x] < size_[y]) std::swap(x, y);
    for (std::uint32_t s = head_[y]; s != kEnd; s = next_[s]) {
      const std::size_t base = s - s % 3;
      if (distinct(base)) faces_.remove(label_[base], label_[base + 1], label_[base + 2]);
      label_[s] = x;
      if (distinct(base)) faces_.add(label_[base], label_[base + 1], label_[base + 2]);
    }
    if (head_[y] != kEnd) {
      if (head_[x] == kEnd) {
        head_[x] = head_[y];
      } else {
        next_[tail_[x]] = head_[y];
      }
      tail_[x] = tail_[y];
      size_[x] += size_[y];
      head_[y] = tail_[y] = kEnd;
      size_[y] = 0;
    }
    return x;
  }

 private:
  bool distinct(std::size_t base) const {
    return label_[base] != label_[base + 1] && label_[base + 1] != label_[base + 2] &&
           label_[base + 2] != label_[base];
  }
  void append(std::uint32_t label, std::uint32_t slot) {
    if (head_[label] == kEnd) {
      head_[label] = slot;
    } else {
      next_[tail_[label]] = slot;
    }
    tail_[label] = slot;
    ++size_[label];
  }

  std::vector<std::uint32_t> label_, next_, head_, tail_, size_;
  TripleCounter faces_;
};

// Merging clusters that are not face neighbours costs this many times its error increase: such a union is
// not a compact region and its triangles tend to fold over its neighbours', so it should wait, but not for
// every neighbour merge however expensive (that leaves small clusters stranded beside large ones).
constexpr double kDetachedPenalty = 4.0;

struct Candidate {
  double cost;
  std::uint32_t a, b;  // a < b
  std::uint32_t version_a, version_b;
  // priority_queue pops the largest: make the cheapest (then the lowest pair) the largest.
  bool operator<(const Candidate& o) const {
    if (cost != o.cost) return cost > o.cost;
    if (a != o.a) return a > o.a;
    return b > o.b;
  }
};

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
  std::vector<std::uint8_t> pending(nodes, 0), member_count(nodes, 0);
  std::vector<std::array<std::uint32_t, 8>> members(nodes);
  std::vector<std::uint32_t> node_parent(nodes, kEnd);
  std::vector<std::uint32_t> cell_node(n, kEnd);
  // Which octant of its parent each node and each fine cell is (the low three bits of its Morton prefix).
  std::vector<std::uint8_t> node_octant(nodes, 0), cell_octant(n, 0);
  for (int l = 1; l <= levels; ++l) {
    for (std::size_t i = 0; i < prefix[l].size(); ++i) {
      const std::uint32_t up = offset[l - 1] + parent[l][i];
      ++pending[up];
      if (l < levels) {
        node_parent[offset[l] + i] = up;
        node_octant[offset[l] + i] = static_cast<std::uint8_t>(prefix[l][i] & 7);
      } else {
        cell_node[i] = up;
        cell_octant[i] = static_cast<std::uint8_t>(prefix[l][i] & 7);
      }
    }
  }
  prefix = {};
  parent = {};

  // Clusters start as the fine cells.
  std::vector<PlacementSums> sums(n);
  std::vector<double> error(n);
  std::vector<std::uint32_t> version(n, 0), union_of(n);
  std::vector<std::uint8_t> alive(n, 1);
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
    sums[i] = cell_placement_sums(cells, i, boundary_weight);
    error[i] = place(sums[i], representative).error;
    union_of[i] = static_cast<std::uint32_t>(i);
  });
  // The octants of its node that each cluster covers. Two clusters are neighbours when an octant of one
  // shares a face with an octant of the other (the octant numbers differ in one bit).
  std::vector<std::uint8_t> octants(n, 0);
  static constexpr auto kNeighbours = [] {
    std::array<std::uint8_t, 256> near{};
    for (unsigned mask = 0; mask < 256; ++mask) {
      for (unsigned o = 0; o < 8; ++o) {
        if (mask & (1u << o))
          near[mask] |= static_cast<std::uint8_t>((1u << (o ^ 1)) | (1u << (o ^ 2)) | (1u << (o ^ 4)));
      }
    }
    return near;
  }();
  std::priority_queue<Candidate> queue;
  auto cost_of = [&](std::uint32_t a, std::uint32_t b, bool detached) {
    PlacementSums merged = sums[a];
    merged.add(sums[b]);
    const double cost = place(merged, representative).error - error[a] - error[b];
    return detached ? cost * kDetachedPenalty : cost;
  };
  // While the tree is first filled, pairs are only listed; their costs (a placement each, most of the
  // merge's arithmetic) are then taken in parallel and the queue is heapified from them at once. The pairs
  // are distinct and the order is total, so it pops exactly as if each had been pushed as it came.
  bool listing = true;
  std::vector<Candidate> listed;
  auto push = [&](std::uint32_t a, std::uint32_t b) {
    if (a > b) std::swap(a, b);
    // The octant masks change as clusters move up: the neighbour test is of this moment.
    const bool detached = !(kNeighbours[octants[a]] & octants[b]);
    if (listing) {
      listed.push_back({detached ? 1.0 : 0.0, a, b, version[a], version[b]});  // cost: the flag, for now
      return;
    }
    queue.push({cost_of(a, b, detached), a, b, version[a], version[b]});
  };
  std::vector<std::uint32_t> at(n, kEnd);  // the node a live cluster sits at (kEnd: the root's level)
  // Cluster c is the whole of a child of `node`: it joins the node's members, pairing with each, and while
  // it is the whole of the node too, moves on up.
  auto arrive = [&](std::uint32_t c, std::uint32_t node, std::uint8_t octant) {
    while (node != kEnd) {
      octants[c] = static_cast<std::uint8_t>(1u << octant);
      --pending[node];
      std::array<std::uint32_t, 8>& m = members[node];
      for (std::uint8_t k = 0; k < member_count[node]; ++k) push(c, m[k]);
      m[member_count[node]++] = c;
      at[c] = node;
      if (pending[node] != 0 || member_count[node] != 1) return;
      member_count[node] = 0;
      at[c] = kEnd;
      octant = node_octant[node];
      node = node_parent[node];
    }
  };
  for (std::size_t i = 0; i < n; ++i) arrive(static_cast<std::uint32_t>(i), cell_node[i], cell_octant[i]);
  cell_node = {};
  tbb::parallel_for(std::size_t{0}, listed.size(), [&](std::size_t k) {
    Candidate& c = listed[k];
    c.cost = cost_of(c.a, c.b, c.cost != 0.0);
  });
  queue = std::priority_queue<Candidate>(std::less<Candidate>(), std::move(listed));
  listing = false;

  std::unique_ptr<FaceTracker> faces;
  std::vector<std::uint32_t> label;
  if (target.faces > 0) {
    faces = std::make_unique<FaceTracker>(cells.triangles, n);
    label.resize(n);
    for (std::size_t i = 0; i < n; ++i) label[i] = static_cast<std::uint32_t>(i);
  }
  auto done = [&](std::size_t live) {
    if (target.faces > 0) return faces->faces() <= target.faces;
    return live <= target.vertices;
  };

  std::size_t live = n;
  std::size_t merges = 0;
  const std::size_t expected = target.faces > 0 ? 0 : (n > target.vertices ? n - target.vertices : 0);
  while (!done(live) && !queue.empty()) {
    const Candidate c = queue.top();
    queue.pop();
    if (!alive[c.a] || !alive[c.b] || version[c.a] != c.version_a || version[c.b] != c.version_b) continue;
    const std::uint32_t a = c.a, b = c.b, node = at[a];
    sums[a].add(sums[b]);
    octants[a] |= octants[b];
    error[a] = place(sums[a], representative).error;
    ++version[a];
    alive[b] = 0;
    union_of[b] = a;
    sums[b] = PlacementSums();
    if (faces) label[a] = faces->merge(label[a], label[b]);
    --live;
    if (++merges % 4096 == 0) report(progress, "cluster: merge", merges, expected);
    // Drop b from the node; a either completes the node and moves up, or pairs anew with the rest.
    std::array<std::uint32_t, 8>& m = members[node];
    std::uint8_t count = member_count[node];
    for (std::uint8_t k = 0; k < count; ++k) {
      if (m[k] == b) {
        m[k] = m[--count];
        break;
      }
    }
    member_count[node] = count;
    if (pending[node] == 0 && count == 1) {
      member_count[node] = 0;
      at[a] = kEnd;
      arrive(a, node_parent[node], node_octant[node]);
    } else {
      for (std::uint8_t k = 0; k < count; ++k)
        if (m[k] != a) push(a, m[k]);
    }
  }
  result.target_met = target.faces > 0 ? faces->faces() <= target.faces : live == target.vertices;

  // Number clusters by their first fine cell.
  std::vector<std::uint32_t> id(n, kEnd);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint32_t r = static_cast<std::uint32_t>(i);
    while (union_of[r] != r) r = union_of[r];
    // Path compression keeps later finds short.
    for (std::uint32_t x = static_cast<std::uint32_t>(i); union_of[x] != r;) {
      const std::uint32_t up = union_of[x];
      union_of[x] = r;
      x = up;
    }
    if (id[r] == kEnd) id[r] = result.count++;
    result.cluster_of[i] = id[r];
  }
  return result;
}

}  // namespace ocsimp::cluster_detail
