#include "seams.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace ocsimp::decimate_detail {
namespace {

constexpr Index kNone = std::numeric_limits<Index>::max();

// A walk that has not arrived after this many steps stops where it is: a step only ever moves to a strictly
// nearer face, so this is a bound on pathological input (a fan of near-coincident faces), not on real meshes,
// whose walks take a few steps (the collapsed region's radius in faces).
constexpr int kMaxSteps = 256;

// Two corners of one output vertex are on the same side when their attributes agree to this much: the
// differences left are the rounding of interpolating one point from either of two faces that share it.
constexpr float kSameNormal = 1e-4f;  // unit normals, per coordinate
constexpr float kSameUv = 1e-5f;      // relative to the larger of 1 and the coordinate
constexpr int kSameColor = 1;         // per 8-bit channel: the two values may round apart

struct Nearest {
  Index face = kNone;
  double d2 = std::numeric_limits<double>::infinity();
  double tie = std::numeric_limits<double>::infinity();  // see nearer()
  std::array<double, 3> w{1, 0, 0};                      // barycentric weights of the nearest point
};

// Whether n is nearer than best. Faces around a vertex that is the nearest point of them all (p above the
// pole of a uv sphere, off the tip of a cone) are equally near, and a walk among them would stop at the
// first: such ties, up to rounding, go to the face whose centroid is nearer, which leads the walk on to the
// face that actually lies under p.
bool nearer(const Nearest& n, const Nearest& best, double size2) {
  const double slack = 1e-9 * (best.d2 + size2);
  if (n.d2 < best.d2 - slack) return true;
  return n.d2 <= best.d2 + slack && n.tie < best.tie;
}

// The nearest point to p of segment (a, b): its parameter from a.
double segment_parameter(const Vec3d& p, const Vec3d& a, const Vec3d& b) {
  const Vec3d ab = b - a;
  const double l2 = ab.squaredNorm();
  return l2 > 0 ? std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
}

// Barycentric weights and squared distance of the point of triangle (a, b, c) nearest p: the projection
// onto the plane when it falls inside, else the nearest point of the nearest edge (a triangle without area
// is its edges).
Nearest nearest_point(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  Nearest best;
  const Vec3d e0 = b - a, e1 = c - a, ap = p - a;
  const Vec3d n = e0.cross(e1);
  const double nn = n.squaredNorm();
  if (nn > 1e-12 * e0.squaredNorm() * e1.squaredNorm()) {
    const double wb = ap.cross(e1).dot(n) / nn, wc = e0.cross(ap).dot(n) / nn;
    if (wb >= 0 && wc >= 0 && wb + wc <= 1) {
      best.w = {1 - wb - wc, wb, wc};
      best.d2 = (a + wb * e0 + wc * e1 - p).squaredNorm();
      return best;
    }
  }
  const Vec3d* corner[3] = {&a, &b, &c};
  for (int k = 0; k < 3; ++k) {
    const Vec3d& from = *corner[k];
    const Vec3d& to = *corner[(k + 1) % 3];
    const double t = segment_parameter(p, from, to);
    const double d2 = (from + t * (to - from) - p).squaredNorm();
    if (d2 < best.d2) {
      best.d2 = d2;
      best.w = {0, 0, 0};
      best.w[k] = 1 - t;
      best.w[(k + 1) % 3] = t;
    }
  }
  return best;
}

// Original vertex -> its faces, in CSR form.
struct FaceLists {
  std::vector<std::size_t> begin;
  std::vector<Index> faces;

  explicit FaceLists(const SeamSource& s) : begin(s.positions.size() + 1, 0) {
    for (const Triangle& t : s.triangles) {
      for (Index v : t) ++begin[v + 1];
    }
    for (std::size_t v = 0; v < s.positions.size(); ++v) begin[v + 1] += begin[v];
    faces.resize(begin.back());
    std::vector<std::size_t> at(begin.begin(), begin.end() - 1);
    for (std::size_t f = 0; f < s.triangles.size(); ++f) {
      for (Index v : s.triangles[f]) faces[at[v]++] = static_cast<Index>(f);
    }
  }
};

struct Attributes {
  Vec3f normal = Vec3f::Zero();
  Vec2f uv = Vec2f::Zero();
  Color color{0, 0, 0, 0};
};

class Walker {
 public:
  Walker(const SeamSource& s, const FaceLists& lists) : s_(s), lists_(lists) {}

  // The attributes of the side of original vertex `start` at position p.
  Attributes at(Index start, const Vec3d& p) const {
    Nearest best;
    visit_fan(start, p, best);
    for (int step = 0; step < kMaxSteps && best.face != kNone; ++step) {
      const Index current = best.face;
      for (Index v : s_.triangles[current]) visit_fan(v, p, best);
      if (best.face == current) break;
    }
    return interpolate(best);
  }

 private:
  void visit_fan(Index v, const Vec3d& p, Nearest& best) const {
    for (std::size_t i = lists_.begin[v]; i < lists_.begin[v + 1]; ++i) {
      const Index f = lists_.faces[i];
      if (f == best.face) continue;
      const Triangle& t = s_.triangles[f];
      const Vec3d a = position(t[0]), b = position(t[1]), c = position(t[2]);
      Nearest n = nearest_point(p, a, b, c);
      n.tie = ((a + b + c) / 3 - p).squaredNorm();
      const double size2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
      if (nearer(n, best, size2)) {
        n.face = f;
        best = n;
      }
    }
  }

  Vec3d position(Index v) const { return s_.positions[v].cast<double>(); }

  Attributes interpolate(const Nearest& at) const {
    Attributes out;
    if (at.face == kNone) return out;
    const Triangle& t = s_.triangles[at.face];
    if (!s_.normals.empty()) {
      Vec3d n = Vec3d::Zero();
      for (int k = 0; k < 3; ++k) n += at.w[k] * s_.normals[t[k]].cast<double>();
      const double length = n.norm();
      // Opposite normals cancel at the midpoint: keep the nearer corner's then.
      const int nearest_corner = static_cast<int>(std::max_element(at.w.begin(), at.w.end()) - at.w.begin());
      out.normal = length > 1e-12 ? Vec3f((n / length).cast<float>()) : s_.normals[t[nearest_corner]];
    }
    if (!s_.uvs.empty()) {
      Vec2d uv = Vec2d::Zero();
      for (int k = 0; k < 3; ++k) uv += at.w[k] * s_.uvs[t[k]].cast<double>();
      out.uv = uv.cast<float>();
    }
    if (!s_.colors.empty()) {
      for (int i = 0; i < 4; ++i) {
        double c = 0;
        for (int k = 0; k < 3; ++k) c += at.w[k] * s_.colors[t[k]][i];
        out.color[i] = static_cast<std::uint8_t>(std::clamp(std::lround(c), 0L, 255L));
      }
    }
    return out;
  }

  using Vec2d = Eigen::Vector2d;
  const SeamSource& s_;
  const FaceLists& lists_;
};

bool same_side(const Attributes& a, const Attributes& b, const SeamSource& s) {
  if (!s.normals.empty() && (a.normal - b.normal).cwiseAbs().maxCoeff() > kSameNormal) return false;
  if (!s.uvs.empty()) {
    for (int i = 0; i < 2; ++i) {
      const float scale = std::max({1.0f, std::abs(a.uv[i]), std::abs(b.uv[i])});
      if (std::abs(a.uv[i] - b.uv[i]) > kSameUv * scale) return false;
    }
  }
  if (!s.colors.empty()) {
    for (int i = 0; i < 4; ++i) {
      if (std::abs(int(a.color[i]) - int(b.color[i])) > kSameColor) return false;
    }
  }
  return true;
}

}  // namespace

bool attributes_differ(const IndexedMesh& mesh, Index a, Index b) {
  if (!mesh.normals.empty() && mesh.normals[a] != mesh.normals[b]) return true;
  if (!mesh.uvs.empty() && mesh.uvs[a] != mesh.uvs[b]) return true;
  return !mesh.colors.empty() && mesh.colors[a] != mesh.colors[b];
}

std::uint64_t restore_seams(const SeamSource& source, const std::vector<Index>& face_origin, IndexedMesh& out,
                            std::vector<Quadric>* quadrics) {
  const std::size_t nv = out.positions.size(), nf = out.triangles.size();
  const FaceLists lists(source);
  const Walker walker(source, lists);

  // Each corner's attributes, from its own side.
  std::vector<Attributes> corner(3 * nf);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nf, 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t f = r.begin(); f < r.end(); ++f) {
                        const Triangle& original = source.triangles[face_origin[f]];
                        for (int k = 0; k < 3; ++k) {
                          const Vec3d p = out.positions[out.triangles[f][k]].cast<double>();
                          corner[3 * f + k] = walker.at(original[k], p);
                        }
                      }
                    });

  // Corners by output vertex, in face order.
  std::vector<std::size_t> begin(nv + 1, 0);
  for (const Triangle& t : out.triangles) {
    for (Index v : t) ++begin[v + 1];
  }
  for (std::size_t v = 0; v < nv; ++v) begin[v + 1] += begin[v];
  std::vector<Index> corners(3 * nf);
  {
    std::vector<std::size_t> at(begin.begin(), begin.end() - 1);
    for (std::size_t c = 0; c < 3 * nf; ++c)
      corners[at[out.triangles[c / 3][c % 3]]++] = static_cast<Index>(c);
  }

  // Sides per vertex: each corner joins the first side it agrees with (`side` holds that side's first
  // corner), in face order, so the numbering depends on the input alone.
  std::vector<Index> side(3 * nf);
  std::vector<Index> sides(nv + 1, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::vector<Index> firsts;
                      for (std::size_t v = r.begin(); v < r.end(); ++v) {
                        firsts.clear();
                        for (std::size_t i = begin[v]; i < begin[v + 1]; ++i) {
                          const Index c = corners[i];
                          std::size_t k = 0;
                          while (k < firsts.size() && !same_side(corner[firsts[k]], corner[c], source)) ++k;
                          if (k == firsts.size()) firsts.push_back(c);
                          side[c] = static_cast<Index>(k);
                        }
                        sides[v + 1] = static_cast<Index>(std::max<std::size_t>(firsts.size(), 1));
                      }
                    });
  for (std::size_t v = 0; v < nv; ++v) sides[v + 1] += sides[v];
  const std::size_t total = sides[nv];

  IndexedMesh split;
  split.origin = out.origin;
  split.positions.resize(total);
  if (!source.normals.empty()) split.normals.resize(total);
  if (!source.uvs.empty()) split.uvs.resize(total);
  if (!source.colors.empty()) split.colors.resize(total);
  std::vector<Quadric> split_quadrics(quadrics ? total : 0);
  for (std::size_t v = 0; v < nv; ++v) {
    const std::size_t count = sides[v + 1] - sides[v];
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t to = sides[v] + k;
      split.positions[to] = out.positions[v];
      if (quadrics) {
        split_quadrics[to] = (*quadrics)[v];
        if (count > 1) split_quadrics[to] *= 1.0 / static_cast<double>(count);
      }
    }
  }
  split.triangles.resize(nf);
  for (std::size_t c = 0; c < 3 * nf; ++c) {
    const Index v = out.triangles[c / 3][c % 3];
    split.triangles[c / 3][c % 3] = static_cast<Index>(sides[v] + side[c]);
  }
  // Each side takes its first corner's attributes (sides are numbered in the order their first corners
  // come, so a corner opening the next side is the first of it).
  for (std::size_t v = 0; v < nv; ++v) {
    Index written = 0;
    for (std::size_t i = begin[v]; i < begin[v + 1]; ++i) {
      const Index c = corners[i];
      if (side[c] != written) continue;
      const std::size_t to = sides[v] + written++;
      const Attributes& a = corner[c];
      if (!split.normals.empty()) split.normals[to] = a.normal;
      if (!split.uvs.empty()) split.uvs[to] = a.uv;
      if (!split.colors.empty()) split.colors[to] = a.color;
    }
  }
  out = std::move(split);
  if (quadrics) *quadrics = std::move(split_quadrics);
  return total - nv;
}

}  // namespace ocsimp::decimate_detail
