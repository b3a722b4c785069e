// Small geometric value types shared by every module.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace ocsimp {

using Vec2f = Eigen::Vector2f;
using Vec3f = Eigen::Vector3f;
using Vec3d = Eigen::Vector3d;

// Vertex indices are 32-bit: a billion-triangle scan has about half a billion vertices.
using Index = std::uint32_t;
using Triangle = std::array<Index, 3>;

// A face that names one vertex twice: no area, no edges of its own (readers keep it; stages drop it).
inline bool has_repeated_corner(const Triangle& t) {
  return t[0] == t[1] || t[1] == t[2] || t[2] == t[0];
}
// A position's exact bits, with -0 folded onto +0 so that equal coordinates have one key: welding by it
// never moves a point. For hash maps (PositionKeyHash) and hand-made tables (hash()).
struct PositionKey {
  std::uint32_t bits[3];
  explicit PositionKey(const Eigen::Vector3f& p) {
    for (int a = 0; a < 3; ++a) {
      const float f = p[a] == 0.0f ? 0.0f : p[a];
      bits[a] = std::bit_cast<std::uint32_t>(f);
    }
  }
  bool operator==(const PositionKey&) const = default;
  std::uint64_t hash() const {
    std::uint64_t h = bits[0] * 0x9E3779B97F4A7C15ull;
    h ^= (h >> 29) + bits[1] * 0xBF58476D1CE4E5B9ull;
    h ^= (h >> 31) + bits[2] * 0x94D049BB133111EBull;
    return h ^ (h >> 32);
  }
};
struct PositionKeyHash {
  std::size_t operator()(const PositionKey& k) const { return static_cast<std::size_t>(k.hash()); }
};

// RGBA, 8 bits a channel: what PLY, Draco and most scanners store.
using Color = std::array<std::uint8_t, 4>;

// A computed point as the nearest float point. Placements can lie a little beyond the input (where tangent
// planes meet past a curved surface's extreme), and for an input spanning nearly the float range that is past
// the largest float: rounded, it would be infinite.
inline Vec3f nearest_float(const Vec3d& p) {
  const double largest = std::numeric_limits<float>::max();
  return p.cwiseMax(-largest).cwiseMin(largest).cast<float>();
}

// Axis-aligned bounding box; empty (lo > hi) until the first point is added.
struct Box3 {
  Vec3d lo{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
           std::numeric_limits<double>::infinity()};
  Vec3d hi{-std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
           -std::numeric_limits<double>::infinity()};

  bool empty() const { return !(lo.x() <= hi.x() && lo.y() <= hi.y() && lo.z() <= hi.z()); }
  void add(const Vec3d& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  void add(const Vec3f& p) { add(Vec3d(p.cast<double>())); }
  void add(const Box3& b) {
    if (b.empty()) return;
    add(b.lo);
    add(b.hi);
  }
  Vec3d extent() const { return empty() ? Vec3d::Zero() : Vec3d(hi - lo); }
  Vec3d center() const { return empty() ? Vec3d::Zero() : Vec3d(0.5 * (lo + hi)); }
  double diagonal() const { return extent().norm(); }
};

}  // namespace ocsimp
