// Triangulation of a face of more than three corners (an OBJ or PLY polygon).
//
// A fan from the first corner is right only for a convex polygon: on a concave one (an L, a notched outline,
// as modelling and CAD tools export) some fan triangles cover the outside and overlap the others. A polygon
// convex in its own plane keeps its fan, so quads and convex n-gons read as they always did; a concave one is
// cut by ear clipping in that plane. Hand-written: of the triangulators Debian packages, CGAL would bring a
// large dependency into the readers for a few dozen lines, and Mapbox's earcut comes only as Python bindings.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "ocsimp/core/mesh.h"

namespace ocsimp::detail {

// Above this many corners a concave polygon keeps its fan: ear clipping tests each candidate ear against the
// reflex corners in its box, found through their Morton codes: a comb of 64 k corners reads in 0.4 s and a
// star in 1.0 s (4.6 and 4.8 s testing every reflex corner), but an outline whose ears' boxes all span most
// of the codes is still quadratic (about 5 s at this size). The readers say how many they fanned so (concave_fans_note): a comb of 4,098 corners covered
// 850 times its area, and decimating the fan of a 16 k-corner star took 4 minutes.
inline constexpr std::size_t kMaxClippedCorners = 65536;

// What ReadOptions::warn is told when `polygons` concave polygons were fanned for their size.
inline std::string concave_fans_note(std::uint64_t polygons) {
  const bool one = polygons == 1;
  return std::to_string(polygons) + (one ? " concave polygon has" : " concave polygons have") +
         " more than " + std::to_string(kMaxClippedCorners) +
         (one ? " corners and was" : " corners and were") +
         " fanned from the first corner: some triangles cover ground outside the polygon";
}

// Scratch of polygon_triangles, kept by a reader across faces so that it allocates once.
struct PolygonScratch {
  std::vector<double> x, y;
  std::vector<std::size_t> prev, next;
  std::vector<unsigned char> reflex;
  std::vector<std::pair<std::uint32_t, std::size_t>> by_code;  // reflex corners by Morton code
  std::vector<std::size_t> late_reflex;                        // corners that turned reflex while clipping
};

// The Morton code of a point quantized to 16 bits an axis: codes grow with each coordinate, so every point of
// a box has a code between those of its lowest and highest corners.
inline std::uint32_t morton16(std::uint32_t x, std::uint32_t y) {
  auto spread = [](std::uint32_t v) {
    v = (v | (v << 8)) & 0x00FF00FFu;
    v = (v | (v << 4)) & 0x0F0F0F0Fu;
    v = (v | (v << 2)) & 0x33333333u;
    return (v | (v << 1)) & 0x55555555u;
  };
  return spread(x) | (spread(y) << 1);
}

// Drops the corners of polygon `corners` that repeat the one before it (the first counting as the last
// one's next; `same(a, b)` says whether two corners are one point), as exporters write a triangle as a quad
// with a corner twice: each would add a triangle without area. Returns the corners left; a polygon that
// would keep fewer than three is left whole (it has no area anyway, and its triangles say so downstream).
template <class Corner, class Same>
std::size_t drop_repeated_corners(Corner* corners, std::size_t n, const Same& same) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) kept += !same(corners[i], corners[i == 0 ? n - 1 : i - 1]);
  if (kept < 3 || kept == n) return n;
  // In place: corner i is read before anything is written at i or beyond.
  Corner previous = corners[n - 1];
  std::size_t at = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Corner corner = corners[i];
    if (!same(corner, previous)) corners[at++] = corner;
    previous = corner;
  }
  return kept;
}

// The fan of polygon `corners` from its first corner: its n - 2 triangles, right for a convex polygon, and
// what a reader without the positions at hand can give.
template <class Corner, class Emit>
void fan_triangles(const Corner* corners, std::size_t n, const Emit& emit) {
  for (std::size_t i = 1; i + 1 < n; ++i) emit(Triangle{corners[0], corners[i], corners[i + 1]});
}

// Appends the n - 2 triangles of polygon `corners` (n >= 3, in the file's order) to `out`, each turning as
// the polygon does. `position(i)` gives corner i's position. A polygon without area, or too large to clip, is
// fanned from its first corner. Returns whether it fanned a concave polygon (one too large to clip).
template <class Corner, class Position, class Emit>
bool polygon_triangles(const Corner* corners, std::size_t n, const Position& position, PolygonScratch& s,
                       const Emit& emit) {
  // Fans the polygon; returns `concave`, what polygon_triangles returns then.
  auto fan = [&](bool concave) {
    fan_triangles(corners, n, emit);
    return concave;
  };
  if (n <= 3) return fan(false);
  // Newell's normal of the polygon; its largest axis is dropped to work in the plane.
  double nx = 0, ny = 0, nz = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f& a = position(i);
    const Vec3f& b = position(i + 1 == n ? 0 : i + 1);
    nx += (double(a.y()) - b.y()) * (double(a.z()) + b.z());
    ny += (double(a.z()) - b.z()) * (double(a.x()) + b.x());
    nz += (double(a.x()) - b.x()) * (double(a.y()) + b.y());
  }
  const double ax = std::abs(nx), ay = std::abs(ny), az = std::abs(nz);
  if (!(ax + ay + az > 0)) return fan(false);
  const int drop = ax >= ay && ax >= az ? 0 : ay >= az ? 1 : 2;
  const double sign = (drop == 0 ? nx : drop == 1 ? ny : nz) > 0 ? 1.0 : -1.0;
  s.x.resize(n);
  s.y.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f& p = position(i);
    // (u, v) turning counterclockwise seen from the normal.
    const double u = drop == 0 ? p.y() : drop == 1 ? p.z() : p.x();
    const double v = drop == 0 ? p.z() : drop == 1 ? p.x() : p.y();
    s.x[i] = u;
    s.y[i] = sign * v;
  }
  auto turn = [&](std::size_t a, std::size_t b, std::size_t c) {
    return (s.x[b] - s.x[a]) * (s.y[c] - s.y[a]) - (s.y[b] - s.y[a]) * (s.x[c] - s.x[a]);
  };
  s.reflex.assign(n, 0);
  bool convex = true;
  for (std::size_t i = 0; i < n; ++i) {
    s.reflex[i] = turn(i == 0 ? n - 1 : i - 1, i, i + 1 == n ? 0 : i + 1) < 0;
    convex = convex && !s.reflex[i];
  }
  if (convex) return fan(false);
  if (n > kMaxClippedCorners) return fan(true);

  s.prev.resize(n);
  s.next.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    s.prev[i] = i == 0 ? n - 1 : i - 1;
    s.next[i] = i + 1 == n ? 0 : i + 1;
  }
  // Whether reflex corner r lies in triangle (a, b, c) or on its sides (a corner at the same place as one of
  // the three does not count: a polygon that touches itself there is still clipped).
  auto blocks = [&](std::size_t r, std::size_t a, std::size_t b, std::size_t c) {
    auto same = [&](std::size_t i, std::size_t j) { return s.x[i] == s.x[j] && s.y[i] == s.y[j]; };
    if (same(r, a) || same(r, b) || same(r, c)) return false;
    return turn(a, b, r) >= 0 && turn(b, c, r) >= 0 && turn(c, a, r) >= 0;
  };
  // Reflex corners by the Morton code of their place in the polygon's box; a corner clipped, or no longer
  // reflex, has its flag cleared and is skipped. (Every corner a blocking test could find is reflex: a
  // corner inside an ear's triangle makes the polygon turn back there.)
  double lo_x = s.x[0], lo_y = s.y[0], hi_x = s.x[0], hi_y = s.y[0];
  for (std::size_t i = 1; i < n; ++i) {
    lo_x = std::min(lo_x, s.x[i]), hi_x = std::max(hi_x, s.x[i]);
    lo_y = std::min(lo_y, s.y[i]), hi_y = std::max(hi_y, s.y[i]);
  }
  const double extent = std::max(hi_x - lo_x, hi_y - lo_y);
  const double scale = extent > 0 ? 65535.0 / extent : 0.0;
  auto code = [&](double x, double y) {
    auto bin = [&](double v) {
      return static_cast<std::uint32_t>(std::clamp(std::floor(v * scale), 0.0, 65535.0));
    };
    return morton16(bin(x - lo_x), bin(y - lo_y));
  };
  s.by_code.clear();
  s.late_reflex.clear();
  for (std::size_t i = 0; i < n; ++i) {
    if (s.reflex[i]) s.by_code.emplace_back(code(s.x[i], s.y[i]), i);
  }
  std::sort(s.by_code.begin(), s.by_code.end());
  auto is_ear = [&](std::size_t i) {
    const std::size_t a = s.prev[i], c = s.next[i];
    if (!(turn(a, i, c) > 0)) return false;
    const double box_lo_x = std::min({s.x[a], s.x[i], s.x[c]}), box_hi_x = std::max({s.x[a], s.x[i], s.x[c]});
    const double box_lo_y = std::min({s.y[a], s.y[i], s.y[c]}), box_hi_y = std::max({s.y[a], s.y[i], s.y[c]});
    const std::uint32_t first = code(box_lo_x, box_lo_y), last = code(box_hi_x, box_hi_y);
    auto at =
        std::lower_bound(s.by_code.begin(), s.by_code.end(), std::pair<std::uint32_t, std::size_t>{first, 0});
    for (; at != s.by_code.end() && at->first <= last; ++at) {
      if (s.reflex[at->second] && blocks(at->second, a, i, c)) return false;
    }
    for (std::size_t r : s.late_reflex) {
      if (s.reflex[r] && blocks(r, a, i, c)) return false;
    }
    return true;
  };
  std::size_t left = n, i = 0, tried = 0;
  while (left > 3) {
    if (tried == left) {
      // No ear: the polygon crosses itself or has no area left. Cut the corner at i anyway, so the count of
      // triangles stays n - 2 whatever the outline.
      tried = 0;
    } else if (!is_ear(i)) {
      i = s.next[i];
      ++tried;
      continue;
    }
    const std::size_t a = s.prev[i], c = s.next[i];
    emit(Triangle{corners[a], corners[i], corners[c]});
    s.next[a] = c;
    s.prev[c] = a;
    --left;
    // Clipping an ear makes its neighbours convex, but for rounding or an outline crossing itself.
    s.reflex[i] = 0;
    for (const std::size_t x : {a, c}) {
      const bool was = s.reflex[x];
      s.reflex[x] = turn(s.prev[x], x, s.next[x]) < 0;
      if (s.reflex[x] && !was) s.late_reflex.push_back(x);
    }
    i = a;
    tried = 0;
  }
  emit(Triangle{corners[s.prev[i]], corners[i], corners[s.next[i]]});
  return false;
}

}  // namespace ocsimp::detail
