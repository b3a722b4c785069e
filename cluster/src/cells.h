// What the single pass leaves behind: the occupied cells of a grid with their sums, and the distinct
// triangles of cells. Everything after the pass (merging, placing) works from this alone.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <new>
#include <utility>
#include <vector>

#include "grid.h"
#include "hash.h"
#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/quadric.h"

namespace ocsimp::cluster_detail {

using Vec2d = Eigen::Vector2d;

// Border sums of a cell, one slot per direction class of the edge (its dominant axis), for every edge
// crossing into or out of the cell, in fixed point in the cell's frame (cell units from its lower corner).
// With u the edge's unit direction, y its end in the cell and n its triangle's unit normal:
// - `exact`: the sums of u and of y x u, kExactScale units to 1. The two half-edges of an interior edge add
//   exactly opposite integers, so only the original's open borders are left, in any order of addition; with
//   the cell's normal N the border plane is (sum u) x N . y - N . sum(y x u) = 0.
// - `crease`: the sums of m = u x n, the normal of the plane through the edge perpendicular to its triangle,
//   and of its offset -m . y, kCreaseScale units to 1. Interior edges cancel here only up to the difference
//   of their two triangles' normals: what creases leave, which placement uses as feature planes.
// Integer sums wrap around, harmlessly as long as the totals fit (2048 units for the exact sums, 32 for the
// crease sums): every term is under 2 units (|y x u| and |m . y| are at most the distance from the corner to
// the edge's line, which passes through the cell), and what survives is the borders and creases crossing
// the cell, a few terms per slot. The exact sums need the finer units: their rounding moves a border plane.
inline constexpr double kExactScale = 1048576.0;
inline constexpr double kCreaseScale = 1024.0;
using ExactSums = std::array<std::array<std::int32_t, 6>, 3>;
template <class T>
using CreaseSums = std::array<std::array<T, 4>, 3>;
struct BorderSums {
  ExactSums exact{};
  CreaseSums<std::int16_t> crease{};
};

using CellTriangle = CellTriple<std::uint32_t>;

// The box of a cell's points (vertices, or a soup's corners), in 256ths of the cell rounded outward:
// placement keeps a quadric representative near the points it stands for (see quadric_reach). Bytes 0-2 hold
// 255 minus the lowest bin on each axis and bytes 3-5 the highest, so that all zeros is the empty box and
// boxes merge by a bytewise max, in any order, to the same bytes.
using PointBox = std::array<std::uint8_t, 6>;
inline constexpr double kPointBoxBins = 256.0;
inline void merge_box(PointBox& to, const PointBox& from) {
  for (int k = 0; k < 6; ++k) to[k] = std::max(to[k], from[k]);
}
// `bin`: floor(local * 256) of a point at cell coordinate `local` on `axis`, in 0..255.
inline void add_bin(PointBox& to, int axis, std::uint32_t bin) {
  to[axis] = std::max(to[axis], static_cast<std::uint8_t>(255 - bin));
  to[axis + 3] = std::max(to[axis + 3], static_cast<std::uint8_t>(bin));
}
inline void add_local(PointBox& to, const Vec3d& local) {
  for (int a = 0; a < 3; ++a) {
    const double bin = std::floor(local[a] * kPointBoxBins);
    add_bin(to, a, static_cast<std::uint32_t>(std::clamp(bin, 0.0, kPointBoxBins - 1)));
  }
}
inline bool box_empty(const PointBox& b) {
  return b[0] + b[3] < 255 || b[1] + b[4] < 255 || b[2] + b[5] < 255;
}

// Hands out zeroed memory (calloc) and leaves elements default-initialized, so that a large array of sums or
// records only costs memory as its pages are first written - the pass needs that to stay within its budget
// while the input's vertex array is still resident.
template <class T>
struct ZeroedAllocator {
  using value_type = T;
  ZeroedAllocator() = default;
  template <class U>
  ZeroedAllocator(const ZeroedAllocator<U>&) {}
  T* allocate(std::size_t n) {
    void* p = std::calloc(n, sizeof(T));
    if (!p && n) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t) { std::free(p); }
  template <class U>
  void construct(U*) noexcept {}  // calloc's zeros stand for "default"
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <class U>
  bool operator==(const ZeroedAllocator<U>&) const {
    return true;
  }
};
// Only for types whose all-zero bytes are their zero value (integers, floats, Eigen vectors of them).
template <class T>
using ZeroedVector = std::vector<T, ZeroedAllocator<T>>;
using CellTriangles = ZeroedVector<CellTriangle>;

struct FineCells {
  Grid grid;
  // Per occupied cell, in ascending Morton order of `keys`:
  std::vector<CellKey> keys;
  std::vector<Quadric> quadrics;       // area-weighted plane quadrics, once per triangle corner in the cell
  ZeroedVector<BorderSums> border;     // empty when boundary preservation is off
  std::vector<std::uint8_t> touched;   // 1 when some triangle has a corner in the cell
  ZeroedVector<std::uint32_t> points;  // vertices (indexed input) or triangle corners (soups) averaged in
  ZeroedVector<Vec3f> point_sum;       // their sum, in the cell's frame (cell units from its lower corner)
  ZeroedVector<PointBox> point_box;    // their box
  std::vector<Vec3f> normal_sum;       // input normals summed; empty when the input has none
  std::vector<std::array<std::uint64_t, 4>> color_sum;  // empty when the input has no colors
  std::vector<Vec2d> uv_sum;                            // empty when the input has no uvs
  // Distinct triangles of three cells, in no particular order.
  CellTriangles triangles;

  std::uint64_t input_vertices = 0;
  std::uint64_t input_triangles = 0;
  // Input triangles with three distinct cells (before merging repeats); for a soup whose grid was halved
  // during the pass, counted on the grid each triangle was read on.
  std::uint64_t surviving_instances = 0;

  // accept_fine_cells refused this many cells: nothing else is filled in.
  std::uint64_t declined_cells = 0;

  std::size_t size() const { return keys.size(); }
  bool has_border() const { return !border.empty(); }
};

struct PassOptions {
  Grid grid;
  bool boundary = true;
  unsigned threads = 1;
  ProgressFn progress;
  // Target-driven modes (power-of-two grids only): aim for about this many occupied cells, coarsening the
  // grid while there are more than twice as many and, for indexed input, refining it when there are far
  // fewer. 0: take the grid as given.
  std::uint64_t target_cells = 0;
  // The fewest occupied cells that can reach the target (its vertex count, or half its face count): an
  // indexed input's grid is refined until it has that many, or every vertex has a cell of its own.
  std::uint64_t needed_cells = 0;
  // Indexed input: asked with the chosen grid's occupied cells before any face is read (see ClusterOptions).
  std::function<bool(std::uint64_t)> accept_fine_cells;
};

// The single pass over the stream.
FineCells accumulate(TriangleStream& stream, const PassOptions& options);

}  // namespace ocsimp::cluster_detail
