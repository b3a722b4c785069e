// Grouping the fine cells of the pass into output clusters without touching the input again: the uniform
// grid re-clustered at a coarser resolution, and the adaptive octree.
#pragma once

#include <cstdint>
#include <vector>

#include "cells.h"
#include "ocsimp/cluster/cluster.h"

namespace ocsimp::cluster_detail {

// Which output cluster each fine cell joins, clusters numbered in order of their first fine cell.
struct Clustering {
  std::vector<std::uint32_t> cluster_of;
  std::uint32_t count = 0;
  bool target_met = true;
  double along_longest = 0;  // uniform re-clustering: the resolution chosen (cells along the longest axis)
};

// The uniform grid of `along` (not necessarily whole) cells along the longest axis over the same box; a fine
// cell joins the coarse cell holding its center. The fine grid must be a power-of-two grid.
Clustering regrid(const FineCells& cells, double along);

// The uniform resolution whose face count is the largest not above `target_faces`.
Clustering regrid_to_faces(const FineCells& cells, std::uint64_t target_faces);

struct OctreeTarget {
  std::uint64_t vertices = 0;  // exactly this many clusters, each with a face (see octree_merge), or
  std::uint64_t faces = 0;     // the largest face count not above this
};

// Merges sibling clusters of the fine power-of-two grid bottom-up, least increase of quadric error first,
// one pair at a time, so any vertex count is reachable exactly. A node's cluster joins its parent's siblings
// once all of the node's children have merged into it. Pairs whose octants share no face pay a penalty.
Clustering octree_merge(const FineCells& cells, const OctreeTarget& target, Representative representative,
                        double boundary_weight, const ProgressFn& progress);

}  // namespace ocsimp::cluster_detail
