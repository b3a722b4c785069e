// Attribute seams under decimation (decimate/src/seams.h): a mesh that stores a vertex once per side of a
// texture seam is decimated welded, so it cannot crack, and each side keeps its own texture coordinates.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "ocsimp/decimate/decimate.h"
#include "test_support.h"

namespace ocsimp {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kMajor = 1.0, kMinor = 0.4;

// A torus of n x m quads with the uv map u = angle around the axis / 2 pi, v = angle around the tube / 2 pi,
// and its normals: a texture-mapped mesh as exporters write it, with the first row and column of vertices
// stored twice (at u = 0 and u = 1, v = 0 and v = 1), so each seam is two borders at the same positions.
IndexedMesh uv_torus(int n, int m) {
  IndexedMesh mesh;
  for (int i = 0; i <= n; ++i) {
    for (int j = 0; j <= m; ++j) {
      // The seam copies take the very same position: angles of the wrapped index.
      const double a = 2 * kPi * (i % n) / n, b = 2 * kPi * (j % m) / m;
      const double r = kMajor + kMinor * std::cos(b);
      mesh.positions.emplace_back(static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)),
                                  static_cast<float>(kMinor * std::sin(b)));
      mesh.normals.emplace_back(static_cast<float>(std::cos(b) * std::cos(a)),
                                static_cast<float>(std::cos(b) * std::sin(a)),
                                static_cast<float>(std::sin(b)));
      mesh.uvs.emplace_back(static_cast<float>(i) / static_cast<float>(n),
                            static_cast<float>(j) / static_cast<float>(m));
    }
  }
  auto id = [m](int i, int j) { return static_cast<Index>(i * (m + 1) + j); };
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      mesh.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      mesh.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  }
  return mesh;
}

// The torus's (u, v) at a point near it, in [0, 1).
Eigen::Vector2d torus_uv(const Vec3f& p) {
  const double a = std::atan2(p.y(), p.x());
  const double b = std::atan2(p.z(), std::hypot(p.x(), p.y()) - kMajor);
  auto unit = [](double angle) { return angle / (2 * kPi) - std::floor(angle / (2 * kPi)); };
  return {unit(a), unit(b)};
}

// Distance between two values of a periodic coordinate of period 1.
double wrapped(double x, double y) {
  const double d = std::abs(x - y);
  return std::min(d, 1 - d);
}

// Border edges of the mesh once vertices at equal positions are taken as one: cracks, on a closed surface.
std::size_t open_edges(const IndexedMesh& mesh) {
  std::map<std::array<float, 3>, Index> ids;
  std::vector<Index> id(mesh.vertex_count());
  for (std::size_t v = 0; v < id.size(); ++v) {
    const Vec3f& p = mesh.positions[v];
    id[v] =
        ids.emplace(std::array<float, 3>{p.x(), p.y(), p.z()}, static_cast<Index>(ids.size())).first->second;
  }
  std::map<std::pair<Index, Index>, int> uses;
  for (const Triangle& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const Index a = id[t[k]], b = id[t[(k + 1) % 3]];
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  }
  return static_cast<std::size_t>(
      std::count_if(uses.begin(), uses.end(), [](const auto& e) { return e.second == 1; }));
}

std::size_t distinct_positions(const IndexedMesh& mesh) {
  std::map<std::array<float, 3>, int> seen;
  for (const Vec3f& p : mesh.positions) seen[{p.x(), p.y(), p.z()}] = 1;
  return seen.size();
}

TEST(Seams, AUvTorusDecimatesClosedWithEachSideKeepingItsTextureCoordinates) {
  const IndexedMesh torus = uv_torus(48, 24);
  ASSERT_EQ(open_edges(torus), 0u);  // closed, seams and all
  for (const std::uint64_t target : {1000u, 300u, 100u}) {
    DecimateOptions o;
    o.target_faces = target;
    const DecimateResult r = decimate(QuadricMesh{torus, {}}, o);
    const IndexedMesh& out = r.mesh;
    ASSERT_EQ(out.face_count(), target);
    EXPECT_EQ(open_edges(out), 0u) << target;
    // The vertex counts are of positions; the seams add one copy of a position per extra side.
    EXPECT_EQ(distinct_positions(out), r.stats.vertices) << target;
    EXPECT_GT(r.stats.seam_copies, 0u) << target;
    EXPECT_EQ(out.vertex_count(), r.stats.vertices + r.stats.seam_copies) << target;
    ASSERT_EQ(out.uvs.size(), out.vertex_count());
    ASSERT_EQ(out.normals.size(), out.vertex_count());
    // Each corner's uv is the map's value at its vertex, on its own side of the seams: no face reaches
    // across one (the u of its corners would span nearly 1), and each uv is within a small part of a
    // texture from the torus's own (u, v) at the vertex, taken periodically.
    double worst = 0, worst_normal = 0;
    for (const Triangle& t : out.triangles) {
      for (int axis = 0; axis < 2; ++axis) {
        float lo = 1, hi = 0;
        for (Index v : t) lo = std::min(lo, out.uvs[v][axis]), hi = std::max(hi, out.uvs[v][axis]);
        EXPECT_LT(hi - lo, 0.5f) << target;
      }
      for (Index v : t) {
        const Eigen::Vector2d expected = torus_uv(out.positions[v]);
        worst =
            std::max({worst, wrapped(out.uvs[v].x(), expected.x()), wrapped(out.uvs[v].y(), expected.y())});
        const Vec3d p = out.positions[v].cast<double>();
        const Vec3d centre = Vec3d(p.x(), p.y(), 0).normalized() * kMajor;
        const Vec3d normal = (p - centre).normalized();
        worst_normal = std::max(worst_normal, (normal - out.normals[v].cast<double>()).norm());
      }
    }
    EXPECT_LT(worst, 0.01) << target;
    EXPECT_LT(worst_normal, 0.05) << target;
  }
}

// The worst distance of a corner's uv from the torus's own at its vertex, periodically.
double worst_uv_error(const IndexedMesh& out) {
  double worst = 0;
  for (const Triangle& t : out.triangles) {
    for (Index v : t) {
      const Eigen::Vector2d expected = torus_uv(out.positions[v]);
      worst = std::max({worst, wrapped(out.uvs[v].x(), expected.x()), wrapped(out.uvs[v].y(), expected.y())});
    }
  }
  return worst;
}

TEST(Seams, ASoupOfTheSameCornersDecimatesAsTheIndexedMesh) {
  // Every face its own three vertices, each with its vertex's uv: copies with equal attributes are one
  // vertex, and only the seams' copies are sides. Walks confined to one soup triangle gave uvs 0.15 off and
  // treated every edge as a seam (largest cost 0.064 against 0.013).
  const IndexedMesh torus = uv_torus(64, 32);
  DecimateOptions o;
  o.target_faces = 400;
  const DecimateResult indexed = decimate(QuadricMesh{torus, {}}, o);
  const DecimateResult soup = decimate(QuadricMesh{test::triangle_soup(torus), {}}, o);
  EXPECT_EQ(soup.mesh.face_count(), 400u);
  EXPECT_EQ(soup.stats.vertices, indexed.stats.vertices);
  EXPECT_EQ(soup.stats.seam_copies, indexed.stats.seam_copies);
  EXPECT_DOUBLE_EQ(soup.stats.max_error, indexed.stats.max_error);
  EXPECT_EQ(open_edges(soup.mesh), 0u);
  EXPECT_LT(worst_uv_error(soup.mesh), 0.01);
}

TEST(Seams, FacesDroppedAsDegenerateDoNotJoinTheSides) {
  // Faces on both sides' copies of one seam position (a, b on one side, a's copy on the other): welding
  // makes them degenerate and drops them, and they must not let a corner's attributes come from the other
  // side.
  const int n = 64, m = 32;
  const IndexedMesh torus = uv_torus(n, m);
  IndexedMesh joined = torus;
  auto id = [m](int i, int j) { return static_cast<Index>(i * (m + 1) + j); };
  for (int j = 0; j < m; ++j) joined.triangles.push_back({id(0, j), id(0, j + 1), id(n, j)});
  DecimateOptions o;
  o.target_faces = 1000;
  const DecimateResult plain = decimate(QuadricMesh{torus, {}}, o);
  const DecimateResult r = decimate(QuadricMesh{joined, {}}, o);
  EXPECT_EQ(r.stats.dropped_degenerate_faces, static_cast<std::uint64_t>(m));
  EXPECT_EQ(r.mesh.triangles, plain.mesh.triangles);
  EXPECT_EQ(r.mesh.positions, plain.mesh.positions);
  EXPECT_EQ(r.mesh.uvs, plain.mesh.uvs);
}

// A uv sphere as exporters write it: n x m quads, the u = 0 column stored twice and each pole once per
// column (its own u), the pole rows' degenerate triangles left out.
IndexedMesh uv_sphere(int n, int m) {
  IndexedMesh mesh;
  for (int j = 0; j <= m; ++j) {
    for (int i = 0; i <= n; ++i) {
      const double a = 2 * kPi * (i % n) / n, b = kPi * j / m;
      const bool pole = j == 0 || j == m;
      mesh.positions.emplace_back(pole ? 0.0f : static_cast<float>(std::sin(b) * std::cos(a)),
                                  pole ? 0.0f : static_cast<float>(std::sin(b) * std::sin(a)),
                                  static_cast<float>(std::cos(b)));
      // A pole's copy sits in the middle of its column's triangle.
      const double u = pole ? (i + 0.5) / n : static_cast<double>(i) / n;
      mesh.uvs.emplace_back(static_cast<float>(u), static_cast<float>(j) / static_cast<float>(m));
    }
  }
  auto id = [n](int i, int j) { return static_cast<Index>(j * (n + 1) + i); };
  for (int j = 0; j < m; ++j) {
    for (int i = 0; i < n; ++i) {
      if (j > 0) mesh.triangles.push_back({id(i, j), id(i, j + 1), id(i + 1, j)});
      if (j < m - 1) mesh.triangles.push_back({id(i + 1, j), id(i, j + 1), id(i + 1, j + 1)});
    }
  }
  return mesh;
}

TEST(Seams, APoleCornerKeepsAUOfItsOwnFace) {
  // Each pole copy carries its column's u; the pole's faces after decimation must take a u near their
  // other corners', not one from across the sphere (the walk went on to whichever face lay under the new
  // vertex: pole u 0.42 in a face spanning u 0 to 0.02).
  const IndexedMesh sphere = uv_sphere(64, 32);
  ASSERT_EQ(open_edges(sphere), 0u);
  for (const std::uint64_t target : {1000u, 500u, 300u}) {
    DecimateOptions o;
    o.target_faces = target;
    const DecimateResult r = decimate(QuadricMesh{sphere, {}}, o);
    EXPECT_EQ(open_edges(r.mesh), 0u);
    // The output vertex nearest each pole stands for it (it may have moved).
    std::array<Vec3f, 2> pole_at{};
    for (int side = 0; side < 2; ++side) {
      const Vec3f pole(0, 0, side == 0 ? 1.0f : -1.0f);
      pole_at[side] = *std::min_element(r.mesh.positions.begin(), r.mesh.positions.end(),
                                        [&](const Vec3f& a, const Vec3f& b) {
                                          return (a - pole).squaredNorm() < (b - pole).squaredNorm();
                                        });
    }
    std::size_t pole_faces = 0;
    for (const Triangle& t : r.mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        if (r.mesh.positions[t[k]] != pole_at[0] && r.mesh.positions[t[k]] != pole_at[1]) continue;
        ++pole_faces;
        const float a = r.mesh.uvs[t[(k + 1) % 3]].x(), b = r.mesh.uvs[t[(k + 2) % 3]].x();
        const float u = r.mesh.uvs[t[k]].x();
        EXPECT_GT(u, std::min(a, b) - 0.06f) << target;
        EXPECT_LT(u, std::max(a, b) + 0.06f) << target;
      }
    }
    EXPECT_GT(pole_faces, 0u) << target;
  }
}

TEST(Seams, ABandOfSliversDoesNotSplitTheVerticesOnIt) {
  // 2,000 columns: around a new vertex inside the sphere the slivers of a band are all about as near, and
  // walks from different columns stopped at points of it a few hundredths of u apart; each became a copy
  // (306 copies for 536 positions). Only the seam's and the poles' copies are due.
  DecimateOptions o;
  o.target_faces = 1000;
  const DecimateResult r = decimate(QuadricMesh{uv_sphere(2000, 16), {}}, o);
  EXPECT_EQ(open_edges(r.mesh), 0u);
  EXPECT_LT(r.stats.seam_copies, r.stats.vertices / 10);
}

TEST(Seams, UnweldedTheSeamsCrack) {
  // What welding prevents: decimated without it, each side of a seam is a border of its own and the two
  // move apart.
  DecimateOptions o;
  o.target_faces = 300;
  o.weld = false;
  const DecimateResult r = decimate(QuadricMesh{uv_torus(48, 24), {}}, o);
  EXPECT_GT(open_edges(r.mesh), 0u);
  EXPECT_EQ(r.stats.seam_copies, 0u);
}

TEST(Seams, SplitVerticesShareOutTheirQuadric) {
  // On a closed surface, without the planes that hold borders and seams in place, the output quadrics sum
  // to the input's face quadrics; a vertex split across a seam must not count its quadric once per copy.
  const IndexedMesh torus = uv_torus(48, 24);
  Quadric input;
  for (const Quadric& q : face_quadrics_per_vertex(torus)) input += q;
  DecimateOptions o;
  o.target_faces = 300;
  o.boundary_weight = 0;
  o.output_quadrics = true;
  const DecimateResult r = decimate(QuadricMesh{torus, {}}, o);
  ASSERT_EQ(r.quadrics.size(), r.mesh.vertex_count());
  ASSERT_GT(r.stats.seam_copies, 0u);
  Quadric output;
  for (const Quadric& q : r.quadrics) output += q;
  const double scale = input.a00 + input.a11 + input.a22;
  EXPECT_NEAR(output.a00 + output.a11 + output.a22, scale, 1e-9 * scale);
  EXPECT_NEAR(output.c, input.c, 1e-9 * scale);
  // Their areas are shared out the same way, one a copy (the next level of an LOD chain refused the result:
  // 300 areas for 330 quadrics).
  ASSERT_EQ(r.areas.size(), r.quadrics.size());
  double area = 0;
  for (double a : r.areas) area += a;
  EXPECT_NEAR(area, scale, 1e-7 * scale);  // the areas are summed apart from the quadrics
  o.target_faces = 100;
  const DecimateResult next = decimate(QuadricMesh{r.mesh, r.quadrics, r.areas}, o);
  EXPECT_EQ(next.mesh.face_count(), 100u);
  EXPECT_GT(next.stats.seam_copies, 0u);
}

// The unit normal of face t of `mesh`.
Vec3f unit_normal(const IndexedMesh& mesh, const Triangle& t) {
  return (mesh.positions[t[1]] - mesh.positions[t[0]])
      .cross(mesh.positions[t[2]] - mesh.positions[t[0]])
      .normalized();
}

// Every face its own three vertices with the face's normal: flat shading, as exporters write it.
IndexedMesh flat_shaded(const IndexedMesh& mesh) {
  IndexedMesh flat = test::triangle_soup(mesh);
  flat.normals.clear();
  for (const Triangle& t : mesh.triangles) flat.normals.insert(flat.normals.end(), 3, unit_normal(mesh, t));
  return flat;
}

// A seam whose sides differ only by a normal within 30 degrees is flat shading's, not a crease: a
// flat-shaded torus decimates as the torus without normals does (its seam planes pinned every vertex: 22
// times the error), while a flat-shaded cube keeps its 90-degree edges as seams, corners and all.
TEST(Seams, FlatShadingIsNotACrease) {
  IndexedMesh torus = uv_torus(48, 24);
  torus.normals.clear();
  torus.uvs.clear();
  DecimateOptions o;
  o.target_faces = 460;
  const DecimateResult smooth = decimate(QuadricMesh{torus, {}}, o);
  const DecimateResult flat = decimate(QuadricMesh{flat_shaded(torus), {}}, o);
  auto farthest = [](const IndexedMesh& m) {
    double d = 0;
    for (const Vec3f& p : m.positions)
      d = std::max(d, std::abs(std::hypot(std::hypot(p.x(), p.y()) - kMajor, double(p.z())) - kMinor));
    return d;
  };
  ASSERT_EQ(flat.mesh.face_count(), smooth.mesh.face_count());
  EXPECT_LE(farthest(flat.mesh), 1.05 * farthest(smooth.mesh));
  // The output is flat-shaded still: every corner's normal is near its own face's.
  ASSERT_EQ(flat.mesh.normals.size(), flat.mesh.vertex_count());
  for (const Triangle& t : flat.mesh.triangles) {
    for (Index v : t) EXPECT_GT(flat.mesh.normals[v].dot(unit_normal(flat.mesh, t)), std::cos(0.25 * kPi));
  }

  const IndexedMesh cube = flat_shaded(test::cube(6));
  o.target_faces = 12;
  const DecimateResult r = decimate(QuadricMesh{cube, {}}, o);
  EXPECT_EQ(r.mesh.face_count(), 12u);
  EXPECT_EQ(distinct_positions(r.mesh), 8u);
  for (const Vec3f& p : r.mesh.positions) {
    for (int a = 0; a < 3; ++a)
      EXPECT_LE(std::min(std::abs(p[a]), std::abs(p[a] - 1)), 1e-6) << p.transpose();
  }
  for (const Triangle& t : r.mesh.triangles) {
    for (Index v : t) EXPECT_GT(r.mesh.normals[v].dot(unit_normal(r.mesh, t)), 0.999f);
  }
}

TEST(Seams, TheSameInputGivesTheSameBytesAtAnyThreadCount) {
  const IndexedMesh torus = uv_torus(96, 48);
  DecimateOptions o;
  o.target_faces = 500;
  o.threads = 1;
  const IndexedMesh one = decimate(QuadricMesh{torus, {}}, o).mesh;
  o.threads = 2;
  const IndexedMesh two = decimate(QuadricMesh{torus, {}}, o).mesh;
  EXPECT_EQ(one.triangles, two.triangles);
  EXPECT_EQ(one.positions, two.positions);
  EXPECT_EQ(one.uvs, two.uvs);
  EXPECT_EQ(one.normals, two.normals);
}

}  // namespace
}  // namespace ocsimp
