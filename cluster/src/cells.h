// What the single pass leaves behind: the occupied cells of a grid with their sums, and the distinct
// triangles of cells. Everything after the pass (merging, placing) works from this alone.
#pragma once

#include <array>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <utility>
#include <vector>

#include "grid.h"
#include "hash.h"
#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/quadric.h"

namespace ocsimp::cluster_detail {

using Vec2d = Eigen::Vector2d;

// Border planes accumulated in a cell, one slot per direction class of the edge (its dominant axis): for
// each edge crossing into or out of the cell, the unit normal m of the plane through the edge perpendicular
// to its triangle (m = edge direction x triangle normal) and the plane's offset w = -m . (edge midpoint),
// taken in the cell's frame (cell units from its lower corner). Opposite half-edges of an interior edge fall
// in the same slot with opposite signs and cancel; floats are enough for that (the residue is ~1e-7 of the
// crossings), doubles would cost 48 more bytes a cell.
struct BorderSums {
  std::array<std::array<float, 4>, 3> slot{};
};

using CellTriangle = CellTriple<std::uint32_t>;

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
  std::vector<BorderSums> border;      // empty when boundary preservation is off
  std::vector<std::uint8_t> touched;   // 1 when some triangle has a corner in the cell
  ZeroedVector<std::uint32_t> points;  // vertices (indexed input) or triangle corners (soups) averaged in
  ZeroedVector<Vec3f> point_sum;       // their sum, in the cell's frame (cell units from its lower corner)
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
};

// The single pass over the stream.
FineCells accumulate(TriangleStream& stream, const PassOptions& options);

}  // namespace ocsimp::cluster_detail
