// The grid the cluster stage lays over a bounding box: cell keys, Morton order, locating points.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <string>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "ocsimp/core/types.h"

namespace ocsimp::cluster_detail {

// A cell's integer coordinates packed into one word: x | y << 21 | z << 42.
using CellKey = std::uint64_t;
inline constexpr int kCoordBits = 21;
inline constexpr std::uint32_t kMaxCellsPerAxis = 1u << kCoordBits;
inline constexpr std::uint64_t kCoordMask = kMaxCellsPerAxis - 1;
inline constexpr CellKey kNoKey = ~CellKey{0};  // never a key: bit 63 is always clear in keys

inline CellKey make_key(std::uint64_t x, std::uint64_t y, std::uint64_t z) {
  return x | (y << kCoordBits) | (z << (2 * kCoordBits));
}
inline std::array<std::uint32_t, 3> key_coords(CellKey key) {
  return {static_cast<std::uint32_t>(key & kCoordMask),
          static_cast<std::uint32_t>((key >> kCoordBits) & kCoordMask),
          static_cast<std::uint32_t>((key >> (2 * kCoordBits)) & kCoordMask)};
}
// The cell of the grid with half the resolution that contains this one.
inline CellKey parent_key(CellKey key) {
  const auto c = key_coords(key);
  return make_key(c[0] >> 1, c[1] >> 1, c[2] >> 1);
}

inline std::uint64_t spread_bits(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}
// Morton order (interleaved coordinate bits): the cells of an octree node are contiguous in it, so it numbers
// output vertices coherently and lets the octree find siblings by shifting.
inline std::uint64_t morton(CellKey key) {
  const auto c = key_coords(key);
  return spread_bits(c[0]) | (spread_bits(c[1]) << 1) | (spread_bits(c[2]) << 2);
}

inline std::uint64_t mix64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

// Cubic cells of edge `cell` with cell (0,0,0) starting at `origin`.
struct Grid {
  Vec3d origin = Vec3d::Zero();
  double cell = 1.0;
  double inverse_cell = 1.0;
  std::array<std::uint32_t, 3> dims{1, 1, 1};
  std::uint32_t along_longest = 1;  // cells along the longest axis of the box the grid was made for
  int level = -1;                   // power-of-two grids: log2(along_longest); -1 otherwise

  // `cells` cubes along the box's longest axis. Throws Error for a non-finite box.
  static Grid uniform(const Box3& bounds, std::uint32_t cells);
  // Cubes of edge `size`. Throws Error naming `file` (the input the box is of) when that makes more than
  // 2^21 cells along an axis.
  static Grid sized(const Box3& bounds, double size, const std::string& file);
  // 2^level cubes along the longest axis; coarser() halves it, keeping every old cell inside one new cell.
  static Grid power_of_two(const Box3& bounds, int level);
  Grid coarser() const;

  // The cell holding p (clamped into the grid, which also catches NaN) and p's offset inside it in cell
  // units.
  CellKey locate(const Vec3d& p, Vec3d& local) const {
#ifdef __SSE2__
    return locate(_mm_loadu_pd(p.data()), p.z(), local);
#else
    return locate_axes(p, local, 0);
#endif
  }
  CellKey locate(const Vec3d& p) const {
    Vec3d local;
    return locate(p, local);
  }
  // The same for a float point (an input vertex), converted exactly. Named apart: Eigen expressions convert
  // to either vector type, so overloads would be ambiguous for them.
  CellKey locate_float(const Vec3f& p, Vec3d& local) const {
#ifdef __SSE2__
    return locate(_mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p.data())))),
                  static_cast<double>(p.z()), local);
#else
    return locate(Vec3d(p.cast<double>()), local);
#endif
  }
  CellKey locate_float(const Vec3f& p) const {
    Vec3d local;
    return locate_float(p, local);
  }
#ifdef __SSE2__
  // x and y in the two lanes of one vector, each lane the scalar path's value: max(t, 0) is 0 for t <= 0 and
  // for NaN (maxpd returns its second operand then), min(., dims - 1) is the clamp above, and truncation the
  // floor of what is left.
  CellKey locate(__m128d xy, double z, Vec3d& local) const {
    const __m128d t = _mm_mul_pd(_mm_sub_pd(xy, _mm_loadu_pd(origin.data())), _mm_set1_pd(inverse_cell));
    const __m128d top = _mm_set_pd(static_cast<double>(dims[1] - 1), static_cast<double>(dims[0] - 1));
    const __m128i i = _mm_cvttpd_epi32(_mm_min_pd(_mm_max_pd(t, _mm_setzero_pd()), top));
    _mm_storeu_pd(local.data(), _mm_sub_pd(t, _mm_cvtepi32_pd(i)));
    const Vec3d p(0.0, 0.0, z);
    const CellKey z_key = locate_axes(p, local, 2);
    const auto x = static_cast<std::uint32_t>(_mm_cvtsi128_si32(i));
    const auto y = static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_shuffle_epi32(i, 1)));
    return z_key | make_key(x, y, 0);
  }
#endif
  // Axes `first` to 2 of locate(), one at a time: the key holds zeros and `local` keeps its values for the
  // axes before.
  CellKey locate_axes(const Vec3d& p, Vec3d& local, int first) const {
    std::uint64_t c[3] = {0, 0, 0};
    for (int a = first; a < 3; ++a) {
      const double t = (p[a] - origin[a]) * inverse_cell;
      // Truncation is the floor for t >= 0 and, unlike std::floor without SSE4.1, needs no library call.
      std::uint64_t i = 0;
      if (t >= static_cast<double>(dims[a])) {
        i = dims[a] - 1;
      } else if (t > 0.0) {
        // Through a signed integer: t < 2^21, and converting to unsigned 64 bits costs a branch on x86-64.
        i = static_cast<std::uint64_t>(static_cast<std::int64_t>(t));
      }
      c[a] = i;
      local[a] = t - static_cast<double>(i);
    }
    return make_key(c[0], c[1], c[2]);
  }
  Vec3d cell_origin(CellKey key) const {
    const auto c = key_coords(key);
    return origin + cell * Vec3d(static_cast<std::int32_t>(c[0]), static_cast<std::int32_t>(c[1]),
                                 static_cast<std::int32_t>(c[2]));
  }
  Box3 cell_box(CellKey key) const {
    Box3 box;
    box.lo = cell_origin(key);
    box.hi = box.lo + Vec3d::Constant(cell);
    return box;
  }
};

}  // namespace ocsimp::cluster_detail
