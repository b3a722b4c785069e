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

// Two corners of one output vertex are on the same side when their walks ended in the same chart (a
// connected piece of the input, cut at its seams) and their attributes agree to this much. Within a chart
// the attributes are continuous, so corners of one side differ only where walks from different starts
// stopped at different points of a plateau (P nearly equidistant from a band of slivers); what still
// differs beyond this is a chart meeting itself across a seam (a cylinder's u = 0 and u = 1).
constexpr float kSideUv = 0.05f;     // of the chart's uv extent on that axis
constexpr float kSideNormal = 0.2f;  // unit normals, Euclidean (about 11.5 degrees)
constexpr int kSideColor = 8;        // per 8-bit channel

struct Nearest {
  Index face = kNone;
  double d2 = std::numeric_limits<double>::infinity();
  std::array<double, 3> w{1, 0, 0};  // barycentric weights of the nearest point
};

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

  // Faces without area are left out: the walk could only cross a seam through them (a face on both sides'
  // copies of one position, which welding drops), and they carry no attribute between their corners.
  explicit FaceLists(const SeamSource& s) : begin(s.positions.size() + 1, 0) {
    std::vector<std::uint8_t> has_area(s.triangles.size());
    for (std::size_t f = 0; f < s.triangles.size(); ++f) {
      const Triangle& t = s.triangles[f];
      const Vec3d p0 = s.positions[t[0]].cast<double>();
      const Vec3d n = (s.positions[t[1]].cast<double>() - p0).cross(s.positions[t[2]].cast<double>() - p0);
      has_area[f] = n.squaredNorm() > 0;
      if (!has_area[f]) continue;
      for (Index v : t) ++begin[v + 1];
    }
    for (std::size_t v = 0; v < s.positions.size(); ++v) begin[v + 1] += begin[v];
    faces.resize(begin.back());
    std::vector<std::size_t> at(begin.begin(), begin.end() - 1);
    for (std::size_t f = 0; f < s.triangles.size(); ++f) {
      if (!has_area[f]) continue;
      for (Index v : s.triangles[f]) faces[at[v]++] = static_cast<Index>(f);
    }
  }
};

struct Attributes {
  Vec3f normal = Vec3f::Zero();
  Vec2f uv = Vec2f::Zero();
  Color color{0, 0, 0, 0};
  Index chart = kNone;                                  // of the walk's end (see Charts)
  double d2 = std::numeric_limits<double>::infinity();  // squared distance from the position to it
};

// Connected pieces of the input through its own (unwelded) vertices and faces with area: a chart of a
// texture atlas, a face of a cube with its own normals. Numbered by their lowest vertex.
struct Charts {
  std::vector<Index> parent;

  Charts(const SeamSource& s, const FaceLists& lists) : parent(s.positions.size()) {
    for (std::size_t v = 0; v < parent.size(); ++v) parent[v] = static_cast<Index>(v);
    // Each corner joins its face's first corner: every face's three corners end up joined, at one join a
    // corner.
    for (std::size_t v = 0; v < parent.size(); ++v) {
      for (std::size_t i = lists.begin[v]; i < lists.begin[v + 1]; ++i)
        join(static_cast<Index>(v), s.triangles[lists.faces[i]][0]);
    }
    for (std::size_t v = 0; v < parent.size(); ++v) parent[v] = find(static_cast<Index>(v));
  }
  Index find(Index v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  }
  void join(Index a, Index b) {
    a = find(a), b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
  Index of(Index v) const { return parent[v]; }  // once built
};

class Walker {
 public:
  // `charts`: null where no side is told from another (no seam to split), and then no chart is named.
  Walker(const SeamSource& s, const FaceLists& lists, const Charts* charts)
      : s_(s), lists_(lists), charts_(charts) {}

  // The attributes of the side of original vertex `start` at position p (its own where no face with area
  // uses it).
  Attributes at(Index start, const Vec3d& p) const {
    Nearest best;
    // A fan looked at once has nothing more to offer: best only gets nearer. Walks are a few steps long,
    // so a short list does.
    thread_local std::vector<Index> seen;
    seen.assign(1, start);
    visit_fan(start, p, best);
    for (int step = 0; step < kMaxSteps && best.face != kNone; ++step) {
      const Index current = best.face;
      for (Index v : s_.triangles[current]) {
        if (std::find(seen.begin(), seen.end(), v) != seen.end()) continue;
        seen.push_back(v);
        visit_fan(v, p, best);
      }
      if (best.face == current) break;
    }
    Attributes a = best.face == kNone ? vertex_attributes(start) : interpolate(best);
    if (charts_) a.chart = charts_->of(start);
    a.d2 = best.d2;
    return a;
  }

 private:
  void visit_fan(Index v, const Vec3d& p, Nearest& best) const {
    for (std::size_t i = lists_.begin[v]; i < lists_.begin[v + 1]; ++i) {
      const Index f = lists_.faces[i];
      if (f == best.face) continue;
      const Triangle& t = s_.triangles[f];
      Nearest n = nearest_point(p, position(t[0]), position(t[1]), position(t[2]));
      // Strictly nearer only: around a vertex that is the nearest point of several faces (the pole of a uv
      // sphere, whose copies each carry their own u) the walk stays on the side it started from.
      if (n.d2 < best.d2) {
        n.face = f;
        best = n;
      }
    }
  }

  Vec3d position(Index v) const { return s_.positions[v].cast<double>(); }

  Attributes vertex_attributes(Index v) const {
    Attributes out;
    if (!s_.normals.empty()) out.normal = s_.normals[v];
    if (!s_.uvs.empty()) out.uv = s_.uvs[v];
    if (!s_.colors.empty()) out.color = s_.colors[v];
    return out;
  }

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
  const Charts* charts_;
};

// Each chart's uv extent per axis (zero for a chart of one vertex).
std::vector<Vec2f> chart_uv_extents(const SeamSource& s, const Charts& charts) {
  std::vector<Vec2f> lo(s.uvs.empty() ? 0 : s.positions.size(),
                        Vec2f::Constant(std::numeric_limits<float>::max()));
  std::vector<Vec2f> hi(lo.size(), Vec2f::Constant(std::numeric_limits<float>::lowest()));
  for (std::size_t v = 0; v < lo.size(); ++v) {
    const Index c = charts.of(static_cast<Index>(v));
    lo[c] = lo[c].cwiseMin(s.uvs[v]);
    hi[c] = hi[c].cwiseMax(s.uvs[v]);
  }
  for (std::size_t v = 0; v < lo.size(); ++v)
    lo[v] = charts.of(static_cast<Index>(v)) == v ? Vec2f(hi[v] - lo[v]) : Vec2f::Zero();
  return lo;
}

bool same_side(const Attributes& a, const Attributes& b, const SeamSource& s,
               const std::vector<Vec2f>& uv_extent) {
  if (a.chart != b.chart) return false;
  if (!s.normals.empty() && (a.normal - b.normal).norm() > kSideNormal) return false;
  if (!s.uvs.empty()) {
    for (int i = 0; i < 2; ++i) {
      if (std::abs(a.uv[i] - b.uv[i]) > kSideUv * uv_extent[a.chart][i]) return false;
    }
  }
  if (!s.colors.empty()) {
    for (int i = 0; i < 4; ++i) {
      if (std::abs(int(a.color[i]) - int(b.color[i])) > kSideColor) return false;
    }
  }
  return true;
}

}  // namespace

std::vector<Index> same_attribute_targets(const IndexedMesh& mesh,
                                          const std::vector<Index>& position_target) {
  const std::size_t n = mesh.positions.size();
  std::vector<Index> target(n);
  // Only vertices that share their position need looking at: sorted by position group, then attributes,
  // then index, each run of equal attributes starts at its lowest index. A sort rather than pairwise
  // comparisons: one position may have millions of copies (a soup of one repeated triangle).
  std::vector<Index> shared;
  for (std::size_t v = 0; v < n; ++v) {
    target[v] = static_cast<Index>(v);
    if (position_target[v] != v) {
      shared.push_back(static_cast<Index>(v));
      shared.push_back(position_target[v]);  // the position's lowest index, once sorted and made unique
    }
  }
  std::sort(shared.begin(), shared.end());
  shared.erase(std::unique(shared.begin(), shared.end()), shared.end());
  // Floats compare as values (-0 equals 0), as the weld does; they are finite (checked before).
  auto attributes_less = [&](Index a, Index b) {
    if (!mesh.normals.empty()) {
      for (int i = 0; i < 3; ++i) {
        if (mesh.normals[a][i] != mesh.normals[b][i]) return mesh.normals[a][i] < mesh.normals[b][i];
      }
    }
    if (!mesh.uvs.empty()) {
      for (int i = 0; i < 2; ++i) {
        if (mesh.uvs[a][i] != mesh.uvs[b][i]) return mesh.uvs[a][i] < mesh.uvs[b][i];
      }
    }
    return !mesh.colors.empty() && mesh.colors[a] < mesh.colors[b];
  };
  std::sort(shared.begin(), shared.end(), [&](Index a, Index b) {
    if (position_target[a] != position_target[b]) return position_target[a] < position_target[b];
    if (attributes_less(a, b)) return true;
    if (attributes_less(b, a)) return false;
    return a < b;
  });
  for (std::size_t i = 0; i < shared.size();) {
    std::size_t j = i + 1;
    while (j < shared.size() && position_target[shared[j]] == position_target[shared[i]] &&
           !attributes_less(shared[i], shared[j]))
      ++j;
    for (std::size_t k = i; k < j; ++k) target[shared[k]] = shared[i];
    i = j;
  }
  return target;
}

std::uint64_t restore_attributes(const SeamSource& source, const std::vector<Index>& face_origin,
                                 IndexedMesh& out, std::vector<Quadric>* quadrics, std::vector<double>* areas,
                                 bool split_seams) {
  const std::size_t nv = out.positions.size(), nf = out.triangles.size();
  const FaceLists lists(source);

  // Without seams a vertex has one side: one walk a vertex, from its first corner, gives its attributes (a
  // walk per corner took a fifth of a 1 M-face decimation to 10 %).
  if (!split_seams) {
    out.normals.resize(source.normals.empty() ? 0 : nv);
    out.uvs.resize(source.uvs.empty() ? 0 : nv);
    out.colors.resize(source.colors.empty() ? 0 : nv);
    const Walker walker(source, lists, nullptr);
    std::vector<std::size_t> first(nv, 3 * nf);
    for (std::size_t c = 3 * nf; c-- > 0;) first[out.triangles[c / 3][c % 3]] = c;
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, nv, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t v = r.begin(); v < r.end(); ++v) {
            if (first[v] == 3 * nf) continue;  // no face uses it
            const Triangle& original = source.triangles[face_origin[first[v] / 3]];
            const Attributes a = walker.at(original[first[v] % 3], out.positions[v].cast<double>());
            if (!out.normals.empty()) out.normals[v] = a.normal;
            if (!out.uvs.empty()) out.uvs[v] = a.uv;
            if (!out.colors.empty()) out.colors[v] = a.color;
          }
        });
    return 0;
  }

  const Charts charts(source, lists);
  const Walker walker(source, lists, &charts);
  const std::vector<Vec2f> uv_extent = chart_uv_extents(source, charts);
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
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, nv, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        std::vector<Index> firsts;
        for (std::size_t v = r.begin(); v < r.end(); ++v) {
          firsts.clear();
          for (std::size_t i = begin[v]; i < begin[v + 1]; ++i) {
            const Index c = corners[i];
            std::size_t k = 0;
            while (k < firsts.size() && !same_side(corner[firsts[k]], corner[c], source, uv_extent)) ++k;
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
  std::vector<double> split_areas(areas ? total : 0);
  for (std::size_t v = 0; v < nv; ++v) {
    const std::size_t count = sides[v + 1] - sides[v];
    const double share = 1.0 / static_cast<double>(count);  // 1 for a vertex of one side: exact
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t to = sides[v] + k;
      split.positions[to] = out.positions[v];
      if (quadrics) {
        split_quadrics[to] = (*quadrics)[v];
        split_quadrics[to] *= share;
      }
      if (areas) split_areas[to] = (*areas)[v] * share;
    }
  }
  split.triangles.resize(nf);
  for (std::size_t c = 0; c < 3 * nf; ++c) {
    const Index v = out.triangles[c / 3][c % 3];
    split.triangles[c / 3][c % 3] = static_cast<Index>(sides[v] + side[c]);
  }
  // Each side takes the attributes of its corner whose walk came nearest (the first among equals).
  std::vector<Index> best(total, kNone);
  for (std::size_t c = 0; c < 3 * nf; ++c) {
    const Index to = split.triangles[c / 3][c % 3];
    if (best[to] == kNone || corner[c].d2 < corner[best[to]].d2) best[to] = static_cast<Index>(c);
  }
  for (std::size_t to = 0; to < total; ++to) {
    if (best[to] == kNone) continue;
    const Attributes& a = corner[best[to]];
    if (!split.normals.empty()) split.normals[to] = a.normal;
    if (!split.uvs.empty()) split.uvs[to] = a.uv;
    if (!split.colors.empty()) split.colors[to] = a.color;
  }
  out = std::move(split);
  if (quadrics) *quadrics = std::move(split_quadrics);
  if (areas) *areas = std::move(split_areas);
  return total - nv;
}

}  // namespace ocsimp::decimate_detail
