#include <algorithm>
#include <cmath>
#include <limits>

#include "regroup.h"

namespace ocsimp::cluster_detail {
namespace {

// Distinct triangles of three distinct clusters.
std::size_t count_faces(const CellTriangles& triangles, const Clustering& clustering) {
  // Sized for a closed surface's faces, about twice its vertices: sized for the fine triangles instead, the
  // set was written whole on every step of regrid_to_faces's search, several times the distinct faces it
  // holds (160 MB a step for a 10 M-triangle scan to 1 M faces).
  TripleSet<std::uint32_t> set(2 * std::size_t{clustering.count});
  const std::vector<std::uint32_t>& cluster_of = clustering.cluster_of;
  for (const CellTriangle& t : triangles) {
    const std::uint32_t a = cluster_of[t.first()], b = cluster_of[t.second()], c = cluster_of[t.third()];
    if (a != b && b != c && c != a) set.add(CellTriangle::of(a, b, c));
  }
  return set.size();
}

}  // namespace

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
  // Fine cells come in Morton order, so runs of them share a coarse cell: those skip the map.
  CellKey last = kNoKey;
  std::uint32_t last_id = 0;
  for (std::size_t i = 0; i < cells.size(); ++i) {
    const auto c = key_coords(cells.keys[i]);
    std::uint64_t coarse[3];
    for (int a = 0; a < 3; ++a) {
      // The coarse cell holding the fine cell's center.
      const double t = (c[a] + 0.5) * scale;
      coarse[a] = std::min(top[a], static_cast<std::uint64_t>(t));
    }
    const CellKey key = make_key(coarse[0], coarse[1], coarse[2]);
    if (key != last) {
      bool inserted;
      last = key;
      last_id = ids.insert(key, result.count, inserted);
      if (inserted) ++result.count;
    }
    result.cluster_of[i] = last_id;
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
  // Faces grow with the resolution, though not strictly, about as a power of it (its square for a surface's
  // cells much larger than its triangles, less near the fine grid). The search narrows a bracket [lo, hi] of
  // the target's boundary, faces(lo) <= target < faces(hi), down to 1e-3 of the resolution, keeping the best
  // count within the target seen along the way. Each step is a Newton step on faces ~ resolution^k from the
  // last count (the fine grid's own triangles to start with; k = 2 until two counts give it), aimed a hair
  // past the target on the far side of that count, so that once the estimate is good the next count lands
  // across the boundary and closes the bracket. A step that would land outside the bracket, or that follows
  // one which failed to halve how far its count missed the target (in log terms), takes the bracket's middle
  // instead. Each step re-clusters every fine cell and counts every fine triangle; halving the bracket every
  // time took 13 steps for a 10 M-triangle scan to 1 M faces, 4.4 s of the 7.9 s run, and now takes 5.
  const auto target = static_cast<double>(target_faces);
  double lo = 1.0, hi = fine, best = 1.0;
  std::size_t best_faces = 0;
  double last = fine, last_faces = static_cast<double>(cells.triangles.size());
  double miss = std::numeric_limits<double>::infinity(), slope = 2.0;
  bool bisect = false;
  for (int step = 0; step < 60 && hi - lo > 1e-3 * lo; ++step) {
    double mid = 0.5 * (lo + hi);
    if (!bisect) {
      const double aim = last_faces > target ? 1.0 - 4e-4 : 1.0 + 4e-4;
      const double newton = last * std::pow(target / last_faces, 1.0 / slope) * aim;
      if (newton > lo && newton < hi) mid = newton;
    }
    const std::size_t faces = count_faces(cells.triangles, regrid(cells, mid));
    if (faces <= target_faces) {
      if (faces >= best_faces) {
        best = mid;
        best_faces = faces;
      }
      lo = mid;
    } else {
      hi = mid;
    }
    const double new_miss = std::abs(std::log(static_cast<double>(faces) / target));
    bisect = !bisect && !(new_miss <= 0.5 * miss);
    miss = new_miss;
    // The local exponent from the last two counts (not the fine grid's: near it faces grow more slowly), when
    // they are far enough apart for the counts' own jitter not to decide it.
    const double exponent = std::log(static_cast<double>(faces) / last_faces) / std::log(mid / last);
    if (step > 0 && std::abs(std::log(mid / last)) > 0.01 && exponent > 0) {
      slope = std::clamp(exponent, 0.25, 4.0);
    }
    last = mid;
    last_faces = static_cast<double>(faces);
  }
  // Small counts jump about with the resolution (a leg falls into one cell or two; at 9 to 14 faces asked
  // for, the horse's counts went 0, 2, 16, ...), and the search above can close its bracket on a count far
  // below the target, or on none (bunny --faces 10 gave 0 faces where a grid gives 8). Then resolutions
  // spread evenly in log terms over the whole range get a look too, as many as a budget of fine-triangle
  // visits allows: hundreds where the fine grid is small, which is where counts jump, none past a few
  // million fine triangles, where they grow smoothly and the search lands close.
  constexpr double kSweepVisits = 4e6;
  constexpr int kMostSweeps = 256;
  if (best_faces < target_faces) {
    const int sweeps = static_cast<int>(
        std::min<double>(kMostSweeps, kSweepVisits / std::max<double>(1, cells.triangles.size())));
    for (int i = 0; i < sweeps; ++i) {
      const double along = std::pow(fine, (i + 0.5) / sweeps);
      const std::size_t faces = count_faces(cells.triangles, regrid(cells, along));
      if (faces <= target_faces && faces > best_faces) {
        best = along;
        best_faces = faces;
      }
    }
  }
  Clustering result = regrid(cells, best);
  result.target_met = true;
  return result;
}

}  // namespace ocsimp::cluster_detail
