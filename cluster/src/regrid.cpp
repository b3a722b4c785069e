#include <algorithm>

#include "regroup.h"

namespace ocsimp::cluster_detail {

std::size_t count_faces(const CellTriangles& triangles, const std::vector<std::uint32_t>& cluster_of) {
  TripleSet<std::uint32_t> set(triangles.size());
  for (const CellTriangle& t : triangles) {
    const std::uint32_t a = cluster_of[t.first()], b = cluster_of[t.second()], c = cluster_of[t.third()];
    if (a != b && b != c && c != a) set.add(CellTriangle::of(a, b, c));
  }
  return set.size();
}

Clustering regrid(const FineCells& cells, double along) {
  const double fine = cells.grid.along_longest;  // a power of two
  along = std::clamp(along, 1.0, fine);
  // The coarse grid's cells per axis, over the same origin: cubes of fine * cell / along.
  std::array<std::uint64_t, 3> top{};
  for (int a = 0; a < 3; ++a) {
    top[a] = static_cast<std::uint64_t>(std::max(1.0, std::ceil(cells.grid.dims[a] * along / fine))) - 1;
  }
  Clustering result;
  result.along_longest = along;
  result.cluster_of.resize(cells.size());
  CellMap ids(cells.size() / 4 + 16);
  const double scale = along / fine;
  for (std::size_t i = 0; i < cells.size(); ++i) {
    const auto c = key_coords(cells.keys[i]);
    std::uint64_t coarse[3];
    for (int a = 0; a < 3; ++a) {
      // The coarse cell holding the fine cell's center.
      const double t = (c[a] + 0.5) * scale;
      coarse[a] = std::min(top[a], static_cast<std::uint64_t>(t));
    }
    bool inserted;
    result.cluster_of[i] = ids.insert(make_key(coarse[0], coarse[1], coarse[2]), result.count, inserted);
    if (inserted) ++result.count;
  }
  return result;
}

Clustering regrid_to_faces(const FineCells& cells, std::uint64_t target_faces) {
  const double fine = cells.grid.along_longest;
  if (cells.triangles.size() <= target_faces) {
    Clustering all = regrid(cells, fine);
    all.target_met = true;
    return all;
  }
  // Faces grow with the resolution, though not strictly. Bisect the (real) resolution for the boundary of
  // the target, keeping the best count within it seen along the way.
  double lo = 1.0, hi = fine, best = 1.0;
  std::size_t best_faces = 0;
  for (int step = 0; step < 40 && hi - lo > 1e-3 * lo; ++step) {
    const double mid = 0.5 * (lo + hi);
    const std::size_t faces = count_faces(cells.triangles, regrid(cells, mid).cluster_of);
    if (faces <= target_faces) {
      if (faces >= best_faces) {
        best = mid;
        best_faces = faces;
      }
      lo = mid;
    } else {
      hi = mid;
    }
  }
  Clustering result = regrid(cells, best);
  result.target_met = true;
  return result;
}

}  // namespace ocsimp::cluster_detail
