#include "ocsimp/cluster/cluster.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/mesh_stream.h"
#include "test_support.h"

namespace ocsimp {
namespace {

QuadricMesh run(const IndexedMesh& mesh, const ClusterOptions& options, ClusterStats* stats = nullptr,
                bool as_soup = false) {
  auto stream = make_mesh_stream(mesh, as_soup, 1000);
  return cluster(*stream, options, stats);
}

ClusterOptions grid_options(std::uint32_t grid, Representative representative = Representative::quadric) {
  ClusterOptions o;
  o.grid = grid;
  o.representative = representative;
  return o;
}

ClusterOptions octree_options(std::uint64_t vertices) {
  ClusterOptions o;
  o.octree = true;
  o.target_vertices = vertices;
  return o;
}

// Rotates and moves a mesh so that nothing lines up with the grid's axes; computed in double and rounded
// once.
const Eigen::Matrix3d kTilt = (Eigen::AngleAxisd(0.5, Vec3d(1, 2, 3).normalized()) *
                               Eigen::AngleAxisd(0.3, Vec3d(-2, 1, 0.5).normalized()))
                                  .toRotationMatrix();
const Vec3d kShift(0.3, -0.2, 0.1);
IndexedMesh tilted(IndexedMesh mesh) {
  for (Vec3f& p : mesh.positions) p = (kTilt * p.cast<double>() + kShift).cast<float>();
  return mesh;
}

double point_triangle_distance(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const Vec3d ab = b - a, ac = c - a, n = ab.cross(ac);
  const double area2 = n.squaredNorm();
  if (area2 > 0) {
    // Inside the prism over the triangle: the distance to the plane.
    const Vec3d ap = p - a;
    const double u = (ap.cross(ac)).dot(n) / area2, v = (ab.cross(ap)).dot(n) / area2;
    if (u >= 0 && v >= 0 && u + v <= 1) return std::abs(ap.dot(n)) / std::sqrt(area2);
  }
  auto segment = [&](const Vec3d& s, const Vec3d& t) {
    const Vec3d d = t - s;
    const double len2 = d.squaredNorm();
    const double x = len2 > 0 ? std::clamp((p - s).dot(d) / len2, 0.0, 1.0) : 0.0;
    return (s + x * d - p).norm();
  };
  return std::min(segment(a, b), std::min(segment(b, c), segment(c, a)));
}

double distance_to_mesh(const Vec3d& p, const IndexedMesh& mesh) {
  double best = std::numeric_limits<double>::infinity();
  for (const Triangle& t : mesh.triangles) {
    best = std::min(best, point_triangle_distance(p, mesh.positions[t[0]].cast<double>(),
                                                  mesh.positions[t[1]].cast<double>(),
                                                  mesh.positions[t[2]].cast<double>()));
  }
  return best;
}

// The mesh and a copy of it moved by `shift`, the copy's faces turned over on request.
IndexedMesh with_moved_copy(IndexedMesh mesh, const Vec3f& shift, bool reversed) {
  const auto n = static_cast<Index>(mesh.vertex_count());
  for (Index v = 0; v < n; ++v) mesh.positions.push_back(mesh.positions[v] + shift);
  const std::size_t faces = mesh.face_count();
  for (std::size_t f = 0; f < faces; ++f) {
    const Triangle t = mesh.triangles[f];
    mesh.triangles.push_back(reversed ? Triangle{t[0] + n, t[2] + n, t[1] + n}
                                      : Triangle{t[0] + n, t[1] + n, t[2] + n});
  }
  return mesh;
}

double farthest_off_unit_sphere(const IndexedMesh& mesh) {
  double worst = 0;
  for (const Vec3f& p : mesh.positions) worst = std::max(worst, std::abs(p.cast<double>().norm() - 1.0));
  return worst;
}

std::vector<Index> border_vertices(const IndexedMesh& mesh) {
  std::map<std::pair<Index, Index>, int> uses;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++uses[std::minmax(t[k], t[(k + 1) % 3])];
  std::vector<Index> border;
  for (const auto& [edge, count] : uses) {
    if (count == 1) {
      border.push_back(edge.first);
      border.push_back(edge.second);
    }
  }
  std::sort(border.begin(), border.end());
  border.erase(std::unique(border.begin(), border.end()), border.end());
  return border;
}

// A lumpy sphere with two holes: borders, curvature and uneven cells.
IndexedMesh lumpy_sphere_with_holes() {
  IndexedMesh mesh = test::sphere(5);
  for (Vec3f& p : mesh.positions) {
    p *= 1.0f + 0.08f * std::sin(5 * p.x()) * std::cos(3 * p.y() + p.z());
  }
  std::vector<Triangle> kept;
  for (const Triangle& t : mesh.triangles) {
    const Vec3f c = (mesh.positions[t[0]] + mesh.positions[t[1]] + mesh.positions[t[2]]) / 3;
    if ((c - Vec3f(0, 0, 1)).norm() < 0.35f || (c - Vec3f(0.8f, 0.6f, 0)).norm() < 0.25f) continue;
    kept.push_back(t);
  }
  mesh.triangles = kept;
  return mesh;
}

bool same_bytes(const QuadricMesh& a, const QuadricMesh& b) {
  auto bytes = [](const auto& va, const auto& vb) {
    return va.size() == vb.size() &&
           (va.empty() || std::memcmp(va.data(), vb.data(), va.size() * sizeof(va[0])) == 0);
  };
  return bytes(a.mesh.positions, b.mesh.positions) && bytes(a.mesh.triangles, b.mesh.triangles) &&
         bytes(a.quadrics, b.quadrics) && bytes(a.mesh.normals, b.mesh.normals) &&
         bytes(a.mesh.colors, b.mesh.colors) && bytes(a.mesh.uvs, b.mesh.uvs);
}

TEST(Cluster, TessellatedPlaneClustersOntoThePlane) {
  const IndexedMesh plane = tilted(test::grid_square(200));
  const Vec3d n = kTilt * Vec3d::UnitZ();
  const Vec3d origin = kShift;
  const double diagonal = plane.bounds().diagonal();
  for (Representative r : {Representative::quadric, Representative::constrained, Representative::mean}) {
    ClusterStats stats;
    const QuadricMesh out = run(plane, grid_options(16, r), &stats);
    ASSERT_GT(out.mesh.vertex_count(), 100u) << representative_name(r);
    ASSERT_GT(out.mesh.face_count(), 100u);
    EXPECT_EQ(out.quadrics.size(), out.mesh.vertex_count());
    double worst = 0;
    for (const Vec3f& p : out.mesh.positions)
      worst = std::max(worst, std::abs(n.dot(p.cast<double>() - origin)));
    EXPECT_LT(worst, 1e-6 * diagonal) << representative_name(r);
  }
}

// A stream read far from zero (IndexedMesh::origin) is clustered in its offsets, as it would be at zero, and
// the output keeps the origin, from indexed and soup streams alike.
TEST(Cluster, KeepsTheFrameOfAMeshFarFromZero) {
  IndexedMesh far = test::sphere(4);
  far.origin = Vec3d(652'113.25, 4'210'775.5, 312.125);
  IndexedMesh at_zero = far;
  at_zero.origin = Vec3d::Zero();
  for (bool soup : {false, true}) {
    const QuadricMesh out = run(far, grid_options(8), nullptr, soup);
    EXPECT_EQ(out.mesh.origin, far.origin) << (soup ? "soup" : "indexed");
    EXPECT_GT(out.mesh.face_count(), 50u);
    EXPECT_EQ(out.mesh.positions, run(at_zero, grid_options(8), nullptr, soup).mesh.positions);
  }
}

TEST(Cluster, SphereRepresentativesLieOnTheSphere) {
  const IndexedMesh sphere = test::sphere(6);  // 32768 triangles
  ClusterStats stats;
  const QuadricMesh quadric = run(sphere, grid_options(16), &stats);
  const QuadricMesh mean = run(sphere, grid_options(16, Representative::mean));
  ASSERT_GT(quadric.mesh.vertex_count(), 500u);
  const double cell = stats.output_cell_size;
  EXPECT_NEAR(cell, 2.0 / 16, 1e-6);
  EXPECT_LT(farthest_off_unit_sphere(quadric.mesh), 0.05 * cell);
  // As surfaces, the quadric's result is closer: the mean's vertices all sit inside the sphere, so its
  // chords do too.
  auto rms_to = [&](const IndexedMesh& out) {
    double sum = 0;
    std::size_t count = 0;
    for (std::size_t v = 0; v < sphere.positions.size(); v += 11, ++count) {
      const double d = distance_to_mesh(sphere.positions[v].cast<double>(), out);
      sum += d * d;
    }
    return std::sqrt(sum / count);
  };
  EXPECT_LT(rms_to(quadric.mesh), 0.8 * rms_to(mean.mesh));
  // A closed sphere clustered stays closed. Where four cells meet around a grid line, clustering may keep
  // both diagonals of their quad (a known trait of vertex clustering); those few faces are the only ones
  // whose edges disagree in direction.
  const MeshTopology topology = analyze_topology(quadric.mesh);
  EXPECT_EQ(topology.boundary_edges, 0u);
  EXPECT_EQ(topology.degenerate_faces, 0u);
  EXPECT_LT(topology.inconsistent_edges, topology.edges / 20);
}

TEST(Cluster, ASphereSpanningNearlyTheFloatRangeStaysFinite) {
  // A quadric's minimizer may lie a little beyond the surface's extreme (where tangent planes meet); on a
  // sphere of radius 0.999 * FLT_MAX that was past the largest float, and the output had infinite vertices.
  // A latitude-longitude sphere, each pole a ring of coincident points (as many exporters write it).
  const float radius = 0.999f * std::numeric_limits<float>::max();
  constexpr int kRings = 30, kSegments = 60;
  IndexedMesh sphere;
  for (int i = 0; i <= kRings; ++i) {
    const double theta = M_PI * i / kRings;
    for (int j = 0; j < kSegments; ++j) {
      const double phi = 2 * M_PI * j / kSegments;
      sphere.positions.push_back(
          (radius * Vec3d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)))
              .cast<float>());
    }
  }
  for (int i = 0; i < kRings; ++i) {
    for (int j = 0; j < kSegments; ++j) {
      const Index a = i * kSegments + j, b = i * kSegments + (j + 1) % kSegments;
      sphere.triangles.push_back({a, a + kSegments, b + kSegments});
      sphere.triangles.push_back({a, b + kSegments, b});
    }
  }
  for (Representative r : {Representative::quadric, Representative::constrained, Representative::mean}) {
    const QuadricMesh out = run(sphere, grid_options(4, r));
    ASSERT_GT(out.mesh.vertex_count(), 20u) << representative_name(r);
    for (const Vec3f& p : out.mesh.positions) {
      ASSERT_TRUE(p.allFinite()) << representative_name(r);
      EXPECT_LT(p.cast<double>().norm() / radius, 1.3) << representative_name(r);
      EXPECT_GT(p.cast<double>().norm() / radius, 0.5) << representative_name(r);
    }
  }
}

TEST(Cluster, CubeStaysSharpWithQuadricPlacementAndRoundsWithMean) {
  const IndexedMesh cube = test::cube(30);
  auto distance_to_cube_surface = [](const Vec3f& p) {
    // Inside or on the cube [0,1]^3: distance to the nearest face; outside: distance to the box.
    const Vec3d q = p.cast<double>();
    const Vec3d outside = (q - q.cwiseMax(Vec3d::Zero()).cwiseMin(Vec3d::Ones())).cwiseAbs();
    if (outside.maxCoeff() > 0) return outside.norm();
    return std::min(q.minCoeff(), (Vec3d::Ones() - q).minCoeff());
  };
  auto nearest_to_corners = [](const IndexedMesh& mesh) {
    double worst = 0;
    for (int c = 0; c < 8; ++c) {
      const Vec3f corner(c & 1, (c >> 1) & 1, (c >> 2) & 1);
      double best = 1e9;
      for (const Vec3f& p : mesh.positions) best = std::min<double>(best, (p - corner).norm());
      worst = std::max(worst, best);
    }
    return worst;
  };
  for (std::uint32_t grid : {7u, 10u}) {
    const QuadricMesh sharp = run(cube, grid_options(grid));
    const QuadricMesh round = run(cube, grid_options(grid, Representative::mean));
    double sharp_worst = 0, round_worst = 0;
    for (const Vec3f& p : sharp.mesh.positions)
      sharp_worst = std::max(sharp_worst, distance_to_cube_surface(p));
    for (const Vec3f& p : round.mesh.positions)
      round_worst = std::max(round_worst, distance_to_cube_surface(p));
    // Quadric placement: every vertex on the cube, the corners exactly there.
    EXPECT_LT(sharp_worst, 1e-5) << grid;
    EXPECT_LT(nearest_to_corners(sharp.mesh), 1e-5) << grid;
    // Mean placement: vertices of edge and corner cells sink inside.
    EXPECT_GT(round_worst, 0.1 / grid) << grid;
    EXPECT_GT(nearest_to_corners(round.mesh), 0.2 / grid) << grid;
  }
}

// How far each quadric representative lies outside its cell (0 inside), over the mesh's longest edge. The
// mean representative numbers the same cells the same way and its vertex lies in its cell, which names it.
double worst_escape_in_edges(const IndexedMesh& mesh, std::uint32_t grid) {
  const QuadricMesh quadric = run(mesh, grid_options(grid));
  const QuadricMesh mean = run(mesh, grid_options(grid, Representative::mean));
  EXPECT_EQ(quadric.mesh.vertex_count(), mean.mesh.vertex_count());
  const Box3 bounds = mesh.bounds();
  const double cell = bounds.extent().maxCoeff() / grid;
  double longest = 0;
  for (const Triangle& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      longest = std::max<double>(longest, (mesh.positions[t[k]] - mesh.positions[t[(k + 1) % 3]]).norm());
    }
  }
  double worst = 0;
  for (std::size_t v = 0; v < mean.mesh.vertex_count(); ++v) {
    const Vec3d m = mean.mesh.positions[v].cast<double>(), q = quadric.mesh.positions[v].cast<double>();
    for (int a = 0; a < 3; ++a) {
      const double lo = bounds.lo[a] + cell * std::floor((m[a] - bounds.lo[a]) / cell);
      worst = std::max(worst, std::max(lo - q[a], q[a] - (lo + cell)) / longest);
    }
  }
  return worst;
}

// The quadric sums the planes of the triangles with a corner in the cell, so it says nothing about the
// surface farther than one of those triangles beyond the cell; a minimizer out there comes from nearly
// parallel planes (slight curvature, scanner noise) and drags the cell's triangles off the surface. Cells
// holding a corner's worth of a lumpy surface sent their vertex up to 1.8 edges out (the limit was a whole
// cell on each axis).
TEST(Cluster, QuadricRepresentativeStaysWithinATriangleOfItsCell) {
  IndexedMesh noisy = test::sphere(5);
  std::mt19937 random(7);
  std::uniform_real_distribution<float> jitter(-0.01f, 0.01f);
  for (Vec3f& p : noisy.positions) p *= 1.0f + jitter(random);
  noisy = tilted(noisy);
  for (std::uint32_t grid : {24u, 40u, 64u}) EXPECT_LE(worst_escape_in_edges(noisy, grid), 1.0) << grid;
  const IndexedMesh lumpy = tilted(lumpy_sphere_with_holes());
  for (std::uint32_t grid : {8u, 16u, 32u}) EXPECT_LE(worst_escape_in_edges(lumpy, grid), 1.0) << grid;
}

// A horn: the paraboloid z = 0.9 - 3.6 r^2 around the axis x = y = 0.5, down to z = 0 (r = 0.5), closed by a
// flat base; `rings` rings of `segments` vertices and the tip's vertex.
IndexedMesh horn(int rings, int segments) {
  IndexedMesh mesh;
  constexpr float kPi = 3.14159265f;
  mesh.positions.emplace_back(0.5f, 0.5f, 0.9f);
  for (int i = 1; i <= rings; ++i) {
    const float r = 0.5f * static_cast<float>(i) / static_cast<float>(rings);
    for (int s = 0; s < segments; ++s) {
      const float angle = 2 * kPi * static_cast<float>(s) / static_cast<float>(segments);
      mesh.positions.emplace_back(0.5f + r * std::cos(angle), 0.5f + r * std::sin(angle),
                                  0.9f - 3.6f * r * r);
    }
  }
  auto at = [&](int i, int s) { return static_cast<Index>(1 + (i - 1) * segments + s % segments); };
  for (int s = 0; s < segments; ++s) mesh.triangles.push_back({0, at(1, s), at(1, s + 1)});
  for (int i = 1; i < rings; ++i) {
    for (int s = 0; s < segments; ++s) {
      mesh.triangles.push_back({at(i, s), at(i + 1, s), at(i + 1, s + 1)});
      mesh.triangles.push_back({at(i, s), at(i + 1, s + 1), at(i, s + 1)});
    }
  }
  const auto base = static_cast<Index>(mesh.positions.size());
  mesh.positions.emplace_back(0.5f, 0.5f, 0.0f);
  for (int s = 0; s < segments; ++s) mesh.triangles.push_back({at(rings, s + 1), at(rings, s), base});
  return mesh;
}

// The tangent planes of a horn cross its axis above the tip, the higher the farther down they touch, so the
// cell holding the tip has a well-conditioned quadric whose minimizer lies above it: a vertex where the
// surface never reaches. Held to the cell and a triangle beyond it, the vertex stood well above the tip
// (spot.obj's horns at 10 %: 4.8 % of the diagonal off the surface, 2.8 % now); held to the box of the points
// it stands for and a triangle beyond that, it stays within a triangle of the tip. Indexed and soup passes
// alike, and a soup pass that halved its grid on the way.
TEST(Cluster, QuadricRepresentativeStaysNearThePointsItStandsFor) {
  const IndexedMesh mesh = horn(50, 96);
  // The tip at z = 0.9 in the middle of the cell [1/3, 2/3)^2 x [2/3, 1) of cells of 1/3; its triangles.
  double edge = 0;
  for (const Triangle& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const Vec3f &a = mesh.positions[t[k]], &b = mesh.positions[t[(k + 1) % 3]];
      if (std::min(a.z(), b.z()) > 2.0f / 3) edge = std::max<double>(edge, (a - b).norm());
    }
  }
  auto highest = [](const QuadricMesh& out) {
    float z = -1;
    for (const Vec3f& p : out.mesh.positions) z = std::max(z, p.z());
    return z;
  };
  ClusterOptions options;
  options.cell_size = 1.0 / 3;
  for (const QuadricMesh& out : {run(mesh, options), run(mesh, options, nullptr, true)}) {
    EXPECT_LE(highest(out), 0.9 + edge);
    // And near it: the box does not pull the tip down.
    EXPECT_GE(highest(out), 0.9 - edge);
  }
  // At the fine grid of an octree, which a soup pass reaches by halving the grid of its first guess (the
  // halved boxes are those of a pass on the coarser grid, rounded outward).
  ClusterOptions fine;
  fine.octree = true;
  fine.target_vertices = 200;
  ClusterStats indexed_stats, soup_stats;
  const QuadricMesh indexed = run(mesh, fine, &indexed_stats), soup = run(mesh, fine, &soup_stats, true);
  ASSERT_EQ(soup_stats.fine_grid, indexed_stats.fine_grid);
  EXPECT_LE(highest(indexed), 0.9 + edge);
  EXPECT_NEAR(highest(soup), highest(indexed), 1e-3);
}

TEST(Cluster, OpenSquareBorderStaysInPlace) {
  // In-plane rotation so that the border runs across cells, not along cell faces.
  IndexedMesh square = test::grid_square(120);
  const Eigen::Matrix3f spin = Eigen::AngleAxisf(0.35f, Vec3f::UnitZ()).toRotationMatrix();
  for (Vec3f& p : square.positions) p = spin * p;
  const std::vector<Index> border = border_vertices(square);
  ASSERT_EQ(border.size(), 480u);
  auto worst_border_gap = [&](const IndexedMesh& out) {
    double worst = 0;
    for (Index v : border) worst = std::max(worst, distance_to_mesh(square.positions[v].cast<double>(), out));
    return worst;
  };
  ClusterOptions options = grid_options(12);
  ClusterStats stats;
  const QuadricMesh kept = run(square, options, &stats);
  options.preserve_boundary = false;
  const QuadricMesh shrunk = run(square, options);
  const double cell = stats.output_cell_size;
  // With the border planes the clustered square reaches the original border everywhere except where a
  // corner's cell cuts it; without them, border vertices sit at their cells' means, half a cell in.
  const double with_border = worst_border_gap(kept.mesh), without = worst_border_gap(shrunk.mesh);
  EXPECT_LT(with_border, 0.02 * cell);
  EXPECT_GT(without, 0.15 * cell);
  // The four corners stay put.
  for (const Vec3f& corner : {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(1, 1, 0)}) {
    const Vec3f c = spin * corner;
    double best = 1e9;
    for (const Vec3f& p : kept.mesh.positions) best = std::min<double>(best, (p - c).norm());
    EXPECT_LT(best, 1e-3 * cell);
  }
  // Output quadrics are the surface's alone: z = 0 for every vertex's quadric minimizer direction.
  for (const Quadric& q : kept.quadrics) {
    EXPECT_NEAR(q.a00, 0.0, 1e-12);
    EXPECT_NEAR(q.a11, 0.0, 1e-12);
  }
}

TEST(Cluster, OctreeReturnsExactlyTheRequestedVertexCount) {
  const IndexedMesh mesh = lumpy_sphere_with_holes();
  for (std::uint64_t n : {1ull, 7ull, 100ull, 333ull, 1000ull}) {
    ClusterOptions options;
    options.octree = true;
    options.target_vertices = n;
    ClusterStats stats;
    const QuadricMesh out = run(mesh, options, &stats);
    EXPECT_EQ(out.mesh.vertex_count(), n);
    EXPECT_EQ(out.quadrics.size(), n);
    EXPECT_TRUE(stats.target_met);
    EXPECT_GE(stats.fine_cells, n);
  }
  // More vertices than the input has cells to give: all of them, and the stats say the target was missed.
  ClusterOptions options;
  options.octree = true;
  options.target_vertices = 10 * mesh.vertex_count();
  ClusterStats stats;
  const QuadricMesh out = run(mesh, options, &stats);
  EXPECT_FALSE(stats.target_met);
  EXPECT_EQ(out.mesh.vertex_count(), stats.fine_cells);
  EXPECT_LE(out.mesh.vertex_count(), mesh.vertex_count());
}

TEST(Cluster, TargetsAreReachedOnPartsMuchCloserThanTheirWidth) {
  // Two layers of a thin shell, 1e-4 apart on a unit square: a surface spanning its box fills about 4x more
  // cells per grid level, but these layers share every cell until the cells are thinner than the gap. The
  // fine grid used to stop at the layers' shared cells (2601), short of both targets.
  const IndexedMesh shell = with_moved_copy(test::grid_square(50), Vec3f(0, 0, 1e-4f), true);
  ClusterStats stats;
  const QuadricMesh octree = run(shell, octree_options(3000), &stats);
  EXPECT_EQ(octree.mesh.vertex_count(), 3000u);
  EXPECT_TRUE(stats.target_met);
  ClusterOptions grid;
  grid.target_faces = 10000;
  const QuadricMesh regridded = run(shell, grid, &stats);
  EXPECT_LE(regridded.mesh.face_count(), 10000u);
  EXPECT_GE(regridded.mesh.face_count(), 9900u);
}

TEST(Cluster, FineGridChoiceEndsWhenCoarseningWouldFallShort) {
  // With about one fine cell per targeted vertex (the pipeline asks for few), halving a grid of too many
  // cells fell below the cells the target needs, refining took it back, and the two took turns forever (a 10
  // M scan's two-stage run hung). The coarsening now stops short of that.
  const IndexedMesh sphere = test::sphere(6);
  for (std::uint64_t faces : {1500ull, 3000ull, 6000ull}) {
    ClusterOptions options;
    options.target_faces = faces;
    options.fine_cells_per_target = 1;
    ClusterStats stats;
    const QuadricMesh out = run(sphere, options, &stats);
    EXPECT_GE(stats.fine_cells, faces / 2) << faces;
    EXPECT_LE(out.mesh.face_count(), faces);
    EXPECT_GT(out.mesh.face_count(), faces / 2) << faces;
  }
}

// Small face targets on a uniform grid: the counts jump with the resolution, and a fine grid of 64 cells
// left few resolutions to choose from, all of them far below the target or above it (three generated
// blobs, `ocsimp gen --components 3`, at 10 faces gave 2, at 100 faces 47; bunny at 10 faces none).
TEST(Cluster, SmallFaceTargetsOnAGridComeClose) {
  IndexedMesh spheres;
  for (int k = 0; k < 3; ++k) {
    IndexedMesh part = test::sphere(4);
    for (Vec3f& p : part.positions) p += Vec3f(3.0f * k, 0.5f * k, 0);
    const Index base = static_cast<Index>(spheres.positions.size());
    spheres.positions.insert(spheres.positions.end(), part.positions.begin(), part.positions.end());
    for (Triangle t : part.triangles) spheres.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  std::uint64_t asked = 0, reached = 0;
  for (std::uint64_t faces : {6ull, 10ull, 20ull, 30ull, 50ull, 100ull}) {
    ClusterOptions options;
    options.target_faces = faces;
    const QuadricMesh out = run(spheres, options);
    EXPECT_LE(out.mesh.face_count(), faces);
    EXPECT_GT(out.mesh.face_count(), 0u) << faces;
    asked += faces;
    reached += out.mesh.face_count();
  }
  EXPECT_GT(reached, asked * 8 / 10);
}

TEST(Cluster, AFarUnusedPointDoesNotCoarsenTheFineGrid) {
  // The fine grid's level comes from the bounding box, and one point no face uses, far from the surface,
  // stretches the box: the surface then filled a fraction of the cells its target asks for, and the
  // clusters made of them were ragged (on bunny.ply, RMS 23 % worse). The grid now refines until the
  // surface itself holds at least half the target's cells.
  const IndexedMesh sphere = test::sphere(7);
  IndexedMesh stretched = sphere;
  stretched.positions.emplace_back(500.0f, 500.0f, 500.0f);
  for (bool octree : {false, true}) {
    ClusterOptions options;
    options.octree = octree;
    options.target_faces = 3000;
    ClusterStats stretched_stats;
    const QuadricMesh clean = run(sphere, options);
    const QuadricMesh out = run(stretched, options, &stretched_stats);
    const double target_cells = options.fine_cells_per_target * double(options.target_faces) / 2;
    EXPECT_GE(double(stretched_stats.fine_cells), target_cells / 2) << octree;
    EXPECT_LE(out.mesh.face_count(), 3000u);
    EXPECT_GE(out.mesh.face_count(), 2900u) << octree;
    // The output stays as close to the sphere as without the point.
    EXPECT_LT(farthest_off_unit_sphere(out.mesh), 1.5 * farthest_off_unit_sphere(clean.mesh)) << octree;
  }
}

TEST(Cluster, FineGridStopsRefiningOnceCellsStopGrowing) {
  // Triangles with their own three vertices each: a cell per distinct position is all the refining can
  // give, which is short of half the cells a large target asks for. The refinement went on to the finest
  // grid, one pass over the vertices per level; it now stops once a level no longer doubles the cells.
  const IndexedMesh welded = test::sphere(6);
  const IndexedMesh unwelded = test::triangle_soup(welded);
  ClusterOptions options;
  options.target_faces = 10000;
  ClusterStats welded_stats, unwelded_stats;
  run(welded, options, &welded_stats);
  const QuadricMesh b = run(unwelded, options, &unwelded_stats);
  EXPECT_EQ(unwelded_stats.fine_cells, welded_stats.fine_cells);
  EXPECT_LE(unwelded_stats.fine_grid, 2 * welded_stats.fine_grid);
  EXPECT_LE(b.mesh.face_count(), 10000u);
  EXPECT_GE(b.mesh.face_count(), 9500u);
}

TEST(Cluster, OctreeFaceTargetGivesTheLargestCountNotAbove) {
  const IndexedMesh mesh = lumpy_sphere_with_holes();
  for (std::uint64_t faces : {200ull, 1500ull}) {
    ClusterOptions options;
    options.octree = true;
    options.target_faces = faces;
    ClusterStats stats;
    const QuadricMesh out = run(mesh, options, &stats);
    EXPECT_LE(out.mesh.face_count(), faces);
    // Each merge removes only the few faces around one pair: the count lands just under the target.
    EXPECT_GE(out.mesh.face_count(), faces - faces / 20 - 4);
    EXPECT_TRUE(stats.target_met);
  }
}

// A long thin strip (100 x 0.1, cells 0.25 x 0.05): the fine grid planned for a surface spanning its box put
// the strip's width in one cell, every triangle collapsed, and a 500-face target came out with no face at all
// although the next level holds 800. A face target now asks the fine grid for as many cells as faces.
TEST(Cluster, OctreeFaceTargetRefinesAThinStripUntilItsFacesSurvive) {
  const IndexedMesh strip = test::thin_strip();
  ClusterOptions options;
  options.octree = true;
  options.target_faces = 500;
  ClusterStats stats;
  const QuadricMesh out = run(strip, options, &stats);
  EXPECT_LE(out.mesh.face_count(), 500u);
  EXPECT_GE(out.mesh.face_count(), 475u);
  EXPECT_TRUE(stats.target_met);
  for (const Vec3f& p : out.mesh.positions) {
    EXPECT_TRUE(p.x() >= -1e-4f && p.x() <= 100.0001f && p.y() >= -1e-4f && p.y() <= 0.1001f &&
                std::abs(p.z()) < 1e-5f)
        << p.transpose();
  }
}

// A face target stops the very merge sequence a vertex target runs, at the first merge that brings the face
// count within the target (found by recounting batches of merges and bisecting the batch that crosses it):
// the result is the vertex-target result of its own vertex count, one merge fewer is over the target, and
// no thread count changes a bit.
TEST(Cluster, OctreeFaceTargetStopsAtTheFirstMergeWithinIt) {
  const IndexedMesh mesh = tilted(lumpy_sphere_with_holes());
  for (std::uint64_t faces : {40ull, 301ull, 1000ull, 4000ull}) {
    ClusterOptions by_faces;
    by_faces.octree = true;
    by_faces.target_faces = faces;
    by_faces.threads = 1;
    ClusterStats stats;
    const QuadricMesh out = run(mesh, by_faces, &stats);
    ASSERT_TRUE(stats.target_met);
    ASSERT_LE(out.mesh.face_count(), faces);
    const std::uint64_t vertices = out.mesh.vertex_count();
    ASSERT_LT(vertices, stats.fine_cells) << "the target must take merges";

    // The same fine grid for a vertex target: as many fine cells per target.
    const double fine_cells = by_faces.fine_cells_per_target * static_cast<double>(faces) / 2.0;
    auto by_vertices = [&](std::uint64_t n, ClusterStats& s) {
      ClusterOptions o;
      o.octree = true;
      o.target_vertices = n;
      o.fine_cells_per_target = fine_cells / static_cast<double>(n);
      o.threads = 1;
      return run(mesh, o, &s);
    };
    ClusterStats same_stats, fewer_stats;
    const QuadricMesh same = by_vertices(vertices, same_stats);
    ASSERT_EQ(same_stats.fine_grid, stats.fine_grid);
    ASSERT_EQ(same_stats.fine_cells, stats.fine_cells);
    EXPECT_TRUE(same_bytes(out, same)) << faces << " faces";
    const QuadricMesh fewer = by_vertices(vertices + 1, fewer_stats);
    ASSERT_EQ(fewer_stats.fine_grid, stats.fine_grid);
    EXPECT_GT(fewer.mesh.face_count(), faces);

    for (unsigned threads : {2u, 3u}) {
      by_faces.threads = threads;
      EXPECT_TRUE(same_bytes(out, run(mesh, by_faces))) << faces << " faces, " << threads << " threads";
    }
  }
}

// Exactly N vertices for every N of a run of consecutive targets, whatever the thread count: the merge takes
// one pair at a time.
TEST(Cluster, OctreeVertexTargetIsExactForConsecutiveCounts) {
  const IndexedMesh mesh = tilted(test::sphere(4));
  for (std::uint64_t n = 95; n <= 105; ++n) {
    ClusterOptions options;
    options.octree = true;
    options.target_vertices = n;
    options.fine_cells_per_target = 16;
    options.threads = 1;
    ClusterStats stats;
    const QuadricMesh one = run(mesh, options, &stats);
    EXPECT_EQ(one.mesh.vertex_count(), n);
    EXPECT_TRUE(stats.target_met);
    options.threads = 2;
    EXPECT_TRUE(same_bytes(one, run(mesh, options))) << n;
  }
}

// A cluster can end with all of its fine triangles collapsed: a vertex of no face. The octree does not
// spend its budget on such points: every one of the N vertices of a vertex target, and every vertex of a
// face target, is a corner of a face. A scanner-noisy sphere leaves many of them behind otherwise.
TEST(Cluster, OctreeVerticesAreAllCornersOfFaces) {
  IndexedMesh mesh = test::sphere(6);
  std::uint32_t state = 12345;
  for (Vec3f& p : mesh.positions) {
    state = state * 1664525u + 1013904223u;
    p *= 1.0f + 0.012f * (static_cast<float>(state >> 8) / 16777216.0f - 0.5f);
  }
  auto corners = [](const IndexedMesh& m) {
    std::vector<char> used(m.vertex_count(), 0);
    for (const Triangle& t : m.triangles)
      for (Index v : t) used[v] = 1;
    return static_cast<std::size_t>(std::count(used.begin(), used.end(), 1));
  };
  for (std::uint64_t n : {1000ull, 2000ull, 4000ull}) {
    ClusterStats stats;
    const QuadricMesh out = run(mesh, octree_options(n), &stats);
    EXPECT_EQ(out.mesh.vertex_count(), n);
    EXPECT_EQ(corners(out.mesh), n) << n << " vertices";
    EXPECT_EQ(stats.isolated_vertices, 0u);
    EXPECT_TRUE(stats.target_met);
    ClusterOptions by_faces;
    by_faces.octree = true;
    by_faces.target_faces = 2 * n;
    const QuadricMesh faces = run(mesh, by_faces);
    EXPECT_LE(faces.mesh.face_count(), 2 * n);
    EXPECT_EQ(corners(faces.mesh), faces.mesh.vertex_count()) << 2 * n << " faces";
  }
}

TEST(Cluster, OctreeBeatsTheUniformGridAtEqualVertexCount) {
  // A box elongated along x with one bumpy end: flat cells should grow, bumpy ones stay small.
  IndexedMesh mesh = test::sphere(6);
  for (Vec3f& p : mesh.positions) {
    p.x() *= 2.0f;
    if (p.x() > 1.0f) p *= 1.0f + 0.05f * std::sin(20 * p.y()) * std::sin(20 * p.z());
  }
  const QuadricMesh uniform = run(mesh, grid_options(12));
  ClusterOptions options;
  options.octree = true;
  options.target_vertices = uniform.mesh.vertex_count();
  const QuadricMesh octree = run(mesh, options);
  ASSERT_EQ(octree.mesh.vertex_count(), uniform.mesh.vertex_count());
  // Error of the original's vertices against each result.
  auto rms = [&](const IndexedMesh& out) {
    double sum = 0;
    std::size_t count = 0;
    for (std::size_t v = 0; v < mesh.positions.size(); v += 7, ++count) {
      const double d = distance_to_mesh(mesh.positions[v].cast<double>(), out);
      sum += d * d;
    }
    return std::sqrt(sum / count);
  };
  EXPECT_LT(rms(octree.mesh), rms(uniform.mesh));
}

// A gently lumpy sphere with fine noise, as a radius per direction, and the largest radial distance to it of
// points spread over a mesh's triangles (a stand-in for the distance from the mesh to that surface).
float lumpy_radius(const Vec3f& u) {
  return 1.0f + 0.06f * std::sin(4 * u.x()) * std::cos(3 * u.y() + 2 * u.z()) +
         0.002f * std::sin(97 * u.x() + 53 * u.y()) * std::sin(71 * u.y() - 43 * u.z());
}
double farthest_from_lumpy(const IndexedMesh& mesh) {
  double worst = 0;
  for (const Triangle& t : mesh.triangles) {
    const Vec3f a = mesh.positions[t[0]], b = mesh.positions[t[1]], c = mesh.positions[t[2]];
    for (int i = 0; i <= 4; ++i) {
      for (int j = 0; i + j <= 4; ++j) {
        const Vec3f p = a + (b - a) * (i / 4.0f) + (c - a) * (j / 4.0f);
        const float r = p.norm();
        if (r > 0) worst = std::max(worst, static_cast<double>(std::abs(r - lumpy_radius(p / r))));
      }
    }
  }
  return worst;
}

TEST(Cluster, OctreeMergesOnlyClustersTheSurfaceJoins) {
  // The octree makes clusters of several sizes side by side. Merging two clusters whose octants share a face
  // but whose cells no triangle joins made long triangles folded over the surface, which set the largest
  // distance to it: 1.04, 1.23 and 1.07 times the uniform grid's at equal vertex count below. Its clusters
  // are larger where the surface is flat, so it may sag a little more than the grid, but not fold.
  IndexedMesh mesh = test::sphere(7);
  for (Vec3f& p : mesh.positions) p *= lumpy_radius(p.normalized());
  for (std::uint32_t grid : {14u, 20u, 28u}) {
    const QuadricMesh uniform = run(mesh, grid_options(grid));
    const QuadricMesh octree = run(mesh, octree_options(uniform.mesh.vertex_count()));
    EXPECT_LT(farthest_from_lumpy(octree.mesh), 1.1 * farthest_from_lumpy(uniform.mesh)) << grid;
  }
}

TEST(Cluster, UniformGridFaceTargetPicksItsResolution) {
  const IndexedMesh mesh = test::sphere(6);
  for (std::uint64_t target : {300ull, 2000ull}) {
    ClusterOptions options;
    options.target_faces = target;
    ClusterStats stats;
    const QuadricMesh out = run(mesh, options, &stats);
    EXPECT_LE(out.mesh.face_count(), target);
    // The resolution is searched continuously, so the count lands close under the target.
    EXPECT_GE(out.mesh.face_count(), target * 9 / 10);
    EXPECT_LT(stats.output_grid, stats.fine_grid);
    EXPECT_TRUE(stats.target_met);
    // Clustering directly at the chosen cell size gives about the same faces (fine cells join coarse ones
    // by their centers, vertices by their positions).
    ClusterOptions direct_options;
    direct_options.cell_size = stats.output_cell_size;
    const QuadricMesh direct = run(mesh, direct_options);
    EXPECT_NEAR(static_cast<double>(direct.mesh.face_count()), static_cast<double>(out.mesh.face_count()),
                0.2 * out.mesh.face_count());
  }
}

TEST(Cluster, ThreadCountDoesNotChangeABit) {
  IndexedMesh mesh = lumpy_sphere_with_holes();
  mesh.colors.resize(mesh.positions.size());
  mesh.normals.resize(mesh.positions.size());
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
    mesh.colors[i] = {static_cast<std::uint8_t>(i * 7), static_cast<std::uint8_t>(i * 13), 50, 255};
    mesh.normals[i] = mesh.positions[i].normalized();
  }
  std::vector<ClusterOptions> modes(4);
  modes[0].grid = 20;
  modes[1].representative = Representative::constrained;
  modes[1].grid = 13;
  modes[2].octree = true;
  modes[2].target_vertices = 400;
  modes[3].target_faces = 900;
  for (bool soup : {false, true}) {
    for (ClusterOptions options : modes) {
      options.threads = 1;
      const QuadricMesh one = run(mesh, options, nullptr, soup);
      for (unsigned threads : {2u, 3u, 8u}) {
        options.threads = threads;
        const QuadricMesh many = run(mesh, options, nullptr, soup);
        EXPECT_TRUE(same_bytes(one, many)) << threads << " threads, soup " << soup;
      }
    }
  }
}

// Batches of many chunks (a chunk is 8192 triangles), so that chunks really run side by side and their
// partial sums are merged: every thread count must still give the same bytes, for indexed input and soups.
TEST(Cluster, ChunksMergeInChunkOrderForAnyThreadCount) {
  IndexedMesh mesh = tilted(test::sphere(6));
  ASSERT_GT(mesh.face_count(), 3 * 8192u);
  // Scatter a fifth of the triangles so that chunks share cells and a cell's sum spans several chunks.
  std::mt19937 random(11);
  std::shuffle(mesh.triangles.begin(), mesh.triangles.begin() + mesh.triangles.size() / 5, random);
  for (bool soup : {false, true}) {
    for (ClusterOptions options : {grid_options(40), grid_options(7, Representative::mean)}) {
      auto clustered = [&](unsigned threads) {
        options.threads = threads;
        auto stream = make_mesh_stream(mesh, soup, 1 << 16);
        return cluster(*stream, options);
      };
      const QuadricMesh one = clustered(1);
      ASSERT_GT(one.mesh.face_count(), 0u);
      for (unsigned threads : {2u, 3u, 7u}) {
        EXPECT_TRUE(same_bytes(one, clustered(threads))) << threads << " threads, soup " << soup;
      }
    }
  }
}

TEST(Cluster, ShufflingTrianglesChangesNothingButRounding) {
  const IndexedMesh mesh = lumpy_sphere_with_holes();
  IndexedMesh shuffled = mesh;
  std::mt19937 random(5);
  std::shuffle(shuffled.triangles.begin(), shuffled.triangles.end(), random);
  // Rotate some triangles' corners too: same triangle, different first corner.
  for (std::size_t i = 0; i < shuffled.triangles.size(); i += 3) {
    Triangle& t = shuffled.triangles[i];
    t = {t[1], t[2], t[0]};
  }
  for (Representative r : {Representative::quadric, Representative::mean}) {
    const QuadricMesh a = run(mesh, grid_options(18, r)), b = run(shuffled, grid_options(18, r));
    ASSERT_EQ(a.mesh.vertex_count(), b.mesh.vertex_count());
    EXPECT_EQ(a.mesh.triangles, b.mesh.triangles);
    double worst = 0;
    for (std::size_t v = 0; v < a.mesh.vertex_count(); ++v) {
      worst = std::max<double>(worst, (a.mesh.positions[v] - b.mesh.positions[v]).norm());
    }
    EXPECT_LT(worst, 1e-6) << representative_name(r);
  }
}

// A soup pass (out of core) halves its grid when its cells outgrow the target (here after its first batch of
// 1000 triangles). An edge whose two triangles fell on either side of that moment added its border sums to
// two sibling cells the halving merged, and then none from its twin, whose ends shared a cell: an open border
// inside the surface, which pulled the cell's vertex by up to 6 % of bunny's size, wherever the input's
// order put the twins.
TEST(Cluster, ASoupPassThatHalvesItsGridIgnoresTheTrianglesOrder) {
  // Lumpy, so that no two cells tie, and fine enough that the first batch's grid is halved.
  IndexedMesh mesh = test::sphere(7);
  for (Vec3f& p : mesh.positions) p *= 1.0f + 0.08f * std::sin(5 * p.x()) * std::cos(3 * p.y() + p.z());
  IndexedMesh shuffled = mesh;
  std::mt19937 random(7);
  std::shuffle(shuffled.triangles.begin(), shuffled.triangles.end(), random);
  ClusterStats stats;
  const QuadricMesh a = run(mesh, octree_options(300), &stats, true);
  const QuadricMesh b = run(shuffled, octree_options(300), nullptr, true);
  ASSERT_EQ(a.mesh.vertex_count(), b.mesh.vertex_count());
  // Each vertex of one run near one of the other's.
  double worst = 0;
  for (const Vec3f& p : a.mesh.positions) {
    double nearest = std::numeric_limits<double>::infinity();
    for (const Vec3f& q : b.mesh.positions) nearest = std::min<double>(nearest, (p - q).norm());
    worst = std::max(worst, nearest);
  }
  // Float rounding where the halving converted sums (2e-4 of a cell); 3 cells before.
  EXPECT_LT(worst, 1e-3 * stats.fine_cell_size);
}

TEST(Cluster, BorderPlanesRideInTheQuadricsOnRequest) {
  IndexedMesh square = test::grid_square(120);
  const Eigen::Matrix3f spin = Eigen::AngleAxisf(0.35f, Vec3f::UnitZ()).toRotationMatrix();
  for (Vec3f& p : square.positions) p = spin * p;
  // Distance from a point of the plane to the square's border.
  auto border_gap = [&](const Vec3d& p) {
    const Vec3d q = spin.cast<double>().transpose() * p;
    return std::min({std::abs(q.x()), std::abs(q.x() - 1), std::abs(q.y()), std::abs(q.y() - 1)});
  };
  for (int octree = 0; octree < 2; ++octree) {
    ClusterOptions options = octree == 1 ? octree_options(60) : grid_options(12);
    const QuadricMesh plain = run(square, options);
    options.border_in_quadrics = true;
    const QuadricMesh carried = run(square, options);
    // Same cells and vertices; only the quadrics differ.
    ASSERT_EQ(plain.mesh.positions, carried.mesh.positions);
    ASSERT_EQ(plain.quadrics.size(), carried.quadrics.size());
    // Each vertex says how much of its quadric is surface: the weight the plain quadric has.
    EXPECT_TRUE(plain.areas.empty());
    ASSERT_EQ(carried.areas.size(), carried.quadrics.size());
    for (std::size_t v = 0; v < carried.quadrics.size(); ++v)
      EXPECT_EQ(carried.areas[v], surface_area(plain, v)) << v;
    std::size_t border_outputs = 0, interior_outputs = 0;
    for (std::size_t v = 0; v < carried.quadrics.size(); ++v) {
      const Vec3d p = carried.mesh.positions[v].cast<double>();
      // Sliding within the plane, across the border's direction whatever it is, costs nothing with the
      // surface planes alone.
      for (const Vec3d& step : {Vec3d(0.03, 0.0, 0.0), Vec3d(0.0, 0.03, 0.0)}) {
        EXPECT_NEAR(plain.quadrics[v].evaluate(p + step), plain.quadrics[v].evaluate(p), 1e-9);
      }
      // A vertex on the border now resists leaving it; one far inside still slides freely.
      const double rise = std::max(carried.quadrics[v].evaluate(p + Vec3d(0.03, 0, 0)),
                                   carried.quadrics[v].evaluate(p + Vec3d(0, 0.03, 0))) -
                          carried.quadrics[v].evaluate(p);
      const double gap = border_gap(p);
      if (gap < 1e-3) {
        ++border_outputs;
        EXPECT_GT(rise, 1e-7) << v;
      } else if (gap > 0.25) {
        ++interior_outputs;
        EXPECT_NEAR(rise, 0.0, 1e-7) << v;
      }
    }
    EXPECT_GT(border_outputs, 12u);
    EXPECT_GT(interior_outputs, 0u);
  }
}

TEST(Cluster, CarriedPlanesAreBordersNotCreases) {
  // A closed cube has no border, only creases, whose two faces' planes the surface quadrics already hold: the
  // carried planes must add little there, while the open square above gets its border.
  const IndexedMesh cube = tilted(test::cube(30));
  for (int octree = 0; octree < 2; ++octree) {
    ClusterOptions options = octree == 1 ? octree_options(80) : grid_options(9);
    const QuadricMesh plain = run(cube, options);
    options.border_in_quadrics = true;
    const QuadricMesh carried = run(cube, options);
    ASSERT_EQ(plain.quadrics.size(), carried.quadrics.size());
    double surface = 0, added = 0;
    for (std::size_t v = 0; v < plain.quadrics.size(); ++v) {
      const Quadric& a = plain.quadrics[v];
      const Quadric& b = carried.quadrics[v];
      surface += a.a00 + a.a11 + a.a22;
      added += (b.a00 + b.a11 + b.a22) - (a.a00 + a.a11 + a.a22);
    }
    EXPECT_GE(added, 0.0);
    // 3 % here (cells on the cube's edges and corners hold two or three faces, so their dominant plane can
    // leave part of a crease's residue along the surface); 30 % when creases are carried like borders.
    EXPECT_LT(added, 0.05 * surface) << "octree " << octree;
  }
}

TEST(Cluster, OutputQuadricsSumTheInputSurfaceQuadrics) {
  const IndexedMesh mesh = tilted(lumpy_sphere_with_holes());
  Quadric expected;
  for (const Quadric& q : face_quadrics_per_vertex(mesh)) expected += q;
  for (int mode = 0; mode < 2; ++mode) {
    ClusterOptions options = grid_options(15);
    if (mode == 1) {
      options.octree = true;
      options.target_vertices = 300;
    }
    const QuadricMesh out = run(mesh, options);
    Quadric total;
    for (const Quadric& q : out.quadrics) total += q;
    const double scale = std::abs(expected.c) + std::abs(expected.a00);
    for (double d :
         {total.a00 - expected.a00, total.a12 - expected.a12, total.b1 - expected.b1, total.c - expected.c}) {
      EXPECT_LT(std::abs(d), 1e-5 * scale);
    }
  }
}

TEST(Cluster, SoupAndIndexedInputAgree) {
  const IndexedMesh mesh = tilted(test::sphere(5));
  ClusterStats stats;
  const QuadricMesh indexed = run(mesh, grid_options(14), &stats);
  const QuadricMesh soup = run(mesh, grid_options(14), nullptr, true);
  ASSERT_EQ(indexed.mesh.vertex_count(), soup.mesh.vertex_count());
  EXPECT_EQ(indexed.mesh.triangles, soup.mesh.triangles);
  // The same quadrics; only the solve's starting point differs (a soup averages corners, not vertices).
  double worst = 0;
  for (std::size_t v = 0; v < indexed.mesh.vertex_count(); ++v) {
    worst = std::max<double>(worst, (indexed.mesh.positions[v] - soup.mesh.positions[v]).norm());
  }
  EXPECT_LT(worst, 0.05 * stats.output_cell_size);
}

// An indexed pass adds the triangles that cross cells from the quantized corners, after resolving each
// vertex's cell once, and those inside one cell in integer arithmetic of their own; a soup pass locates every
// corner as read. Every sum is the same up to the quantization (2^-21 of a cell), borders included: carried
// in the quadrics, they show in the output.
TEST(Cluster, IndexedAndSoupPassesAddCrossingTrianglesAlike) {
  const IndexedMesh mesh = tilted(lumpy_sphere_with_holes());
  for (int boundary = 0; boundary < 2; ++boundary) {
    ClusterOptions options = grid_options(14);
    options.preserve_boundary = boundary == 1;
    options.border_in_quadrics = boundary == 1;
    const QuadricMesh indexed = run(mesh, options);
    const QuadricMesh soup = run(mesh, options, nullptr, true);
    ASSERT_EQ(indexed.mesh.triangles, soup.mesh.triangles);
    ASSERT_EQ(indexed.quadrics.size(), soup.quadrics.size());
    options.border_in_quadrics = false;
    const QuadricMesh surface_only = run(mesh, options);
    std::size_t with_border = 0;
    for (std::size_t v = 0; v < indexed.quadrics.size(); ++v) {
      const auto coefficients = [](const Quadric& q) {
        return std::array<double, 10>{q.a00, q.a01, q.a02, q.a11, q.a12, q.a22, q.b0, q.b1, q.b2, q.c};
      };
      const std::array<double, 10> a = coefficients(indexed.quadrics[v]), b = coefficients(soup.quadrics[v]),
                                   plain = coefficients(surface_only.quadrics[v]);
      double scale = 0, gap = 0, border = 0;
      for (int k = 0; k < 10; ++k) {
        scale = std::max(scale, std::abs(a[k]));
        gap = std::max(gap, std::abs(a[k] - b[k]));
        border = std::max(border, std::abs(a[k] - plain[k]));
      }
      EXPECT_LE(gap, 1e-5 * scale) << v;
      if (border > 1e-2 * scale) ++with_border;
    }
    // The holes' borders run through many cells, whose quadrics the border planes change.
    if (boundary == 1) {
      EXPECT_GT(with_border, 20u);
    } else {
      EXPECT_EQ(with_border, 0u);
    }
  }
}

// A soup gives no vertex array to count cells on before the pass, so the pass starts from a guess (refined,
// never coarsened, on its first batch) and halves its grid while the cells outnumber twice the target: its
// memory follows the output, not the guess. Nested spheres occupy several times the cells the guess assumes
// (one surface spanning the box).
TEST(Cluster, SoupPassHalvesItsGridWhenCellsOutgrowTheTarget) {
  IndexedMesh mesh;
  for (float radius : {1.0f, 0.93f, 0.86f, 0.79f, 0.72f}) {
    const IndexedMesh shell = test::sphere(5, radius);
    const auto base = static_cast<Index>(mesh.positions.size());
    mesh.positions.insert(mesh.positions.end(), shell.positions.begin(), shell.positions.end());
    for (Triangle t : shell.triangles) mesh.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  mesh = tilted(mesh);
  ClusterOptions options;
  options.octree = true;
  options.target_vertices = 300;
  const double target_cells = options.fine_cells_per_target * 300;
  ClusterStats indexed_stats, soup_stats;
  const QuadricMesh indexed = run(mesh, options, &indexed_stats);
  const QuadricMesh soup = run(mesh, options, &soup_stats, true);
  EXPECT_LE(static_cast<double>(soup_stats.fine_cells), 2 * target_cells);
  EXPECT_EQ(soup_stats.fine_grid, indexed_stats.fine_grid);
  EXPECT_EQ(soup_stats.fine_cells, indexed_stats.fine_cells);
  EXPECT_EQ(soup.mesh.vertex_count(), 300u);
  // Halving sums what a pass on the coarser grid sums: the quadrics add up to the indexed pass's.
  Quadric soup_total, indexed_total;
  for (const Quadric& q : soup.quadrics) soup_total += q;
  for (const Quadric& q : indexed.quadrics) indexed_total += q;
  EXPECT_NEAR(soup_total.a00, indexed_total.a00, 1e-7 * indexed_total.a00);
  EXPECT_NEAR(soup_total.c, indexed_total.c, 1e-7 * indexed_total.c);
}

// Two spheres 400 radii apart fill a few cells of a grid sized for a surface spanning their box. An indexed
// pass counts its cells and refines; a soup pass refines by the same rule on its first batch's corners, here
// a patch of the first sphere. Both reach the target and stay as close to the spheres. (Without the
// refinement, the soup made under 1,000 faces.)
TEST(Cluster, SoupOfPartsFarApartMeetsAFaceTarget) {
  const Vec3f shift(400, 0, 0);
  const IndexedMesh mesh = with_moved_copy(test::sphere(5), shift, false);
  auto farthest_off_spheres = [&](const IndexedMesh& out) {
    double worst = 0;
    for (const Vec3f& p : out.positions) {
      const double d = std::min(p.norm(), (p - shift).norm());
      worst = std::max(worst, std::abs(d - 1.0));
    }
    return worst;
  };
  for (bool octree : {false, true}) {
    ClusterOptions options;
    options.octree = octree;
    options.target_faces = 2000;
    ClusterStats indexed_stats, soup_stats;
    const QuadricMesh indexed = run(mesh, options, &indexed_stats);
    const QuadricMesh soup = run(mesh, options, &soup_stats, true);
    EXPECT_TRUE(indexed_stats.target_met) << octree;
    EXPECT_TRUE(soup_stats.target_met) << octree;
    EXPECT_GE(indexed.mesh.face_count(), 1900u) << octree;
    EXPECT_GE(soup.mesh.face_count(), 1900u) << octree;
    EXPECT_LE(soup.mesh.face_count(), 2000u) << octree;
    // The batch here is 1,000 triangles, too small a share of the input to size the grid as closely as the
    // vertex array does (3,014 fine cells against 8,088), but enough to give the merges a choice: at least
    // twice the 1,000 vertices the target needs.
    EXPECT_GE(soup_stats.fine_cells, 2000u) << octree;
    EXPECT_LT(farthest_off_spheres(soup.mesh), 1.5 * farthest_off_spheres(indexed.mesh) + 1e-3) << octree;
  }
}

// A face target beyond what the finest grid can hold is missed, and said to be: the same faces eight times
// over weld into one copy, under half the target, indexed or soup, grid or octree.
TEST(Cluster, FaceTargetBeyondTheDistinctTrianglesSaysSo) {
  IndexedMesh mesh = test::sphere(3);
  const std::size_t distinct = mesh.face_count();
  for (std::size_t f = 0; f < 7 * distinct; ++f) mesh.triangles.push_back(mesh.triangles[f]);
  for (bool soup : {false, true}) {
    for (bool octree : {false, true}) {
      ClusterOptions options;
      options.octree = octree;
      options.target_faces = 4 * distinct;
      ClusterStats stats;
      const QuadricMesh out = run(mesh, options, &stats, soup);
      EXPECT_FALSE(stats.target_met) << soup << octree;
      EXPECT_LE(out.mesh.face_count(), distinct) << soup << octree;
      EXPECT_GE(out.mesh.face_count(), distinct * 9 / 10) << soup << octree;
    }
  }
}

TEST(Cluster, AttributesAreAveragedPerCell) {
  IndexedMesh mesh = test::grid_square(40);
  mesh.colors.assign(mesh.positions.size(), {10, 200, 30, 255});
  mesh.uvs.resize(mesh.positions.size());
  mesh.normals.assign(mesh.positions.size(), Vec3f(0, 0, 1));
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) mesh.uvs[i] = mesh.positions[i].head<2>();
  const QuadricMesh out = run(mesh, grid_options(5));
  ASSERT_EQ(out.mesh.colors.size(), out.mesh.vertex_count());
  ASSERT_EQ(out.mesh.uvs.size(), out.mesh.vertex_count());
  ASSERT_EQ(out.mesh.normals.size(), out.mesh.vertex_count());
  for (std::size_t v = 0; v < out.mesh.vertex_count(); ++v) {
    EXPECT_EQ(out.mesh.colors[v], (Color{10, 200, 30, 255}));
    EXPECT_NEAR((out.mesh.normals[v] - Vec3f(0, 0, 1)).norm(), 0.0, 1e-6);
    // uv = xy on the input, so the averaged uv is the mean of the cell's vertices: inside the cell.
    const Vec2f uv = out.mesh.uvs[v];
    const Vec2f cell = (uv * 5).array().floor();
    EXPECT_GE(uv.x(), cell.x() / 5 - 1e-6);
    EXPECT_LE(uv.x(), (cell.x() + 1) / 5 + 1e-6);
  }
}

// A soup's corners may carry attributes (a PLY dereferenced out of core): they are averaged over the cell's
// corners, as its positions are. With uv = xy and red = 200 x, a mean-placed vertex has both at its own
// position; the octree, which merges cells, too.
TEST(Cluster, ASoupsCornerAttributesAreAveragedWithItsCorners) {
  IndexedMesh mesh = test::grid_square(40);
  const std::size_t n = mesh.vertex_count();
  mesh.normals.assign(n, Vec3f(0, 0.6f, 0.8f));
  mesh.colors.resize(n);
  mesh.uvs.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f& p = mesh.positions[i];
    mesh.uvs[i] = p.head<2>();
    mesh.colors[i] = {static_cast<std::uint8_t>(std::lround(200 * p.x())), 7, 99, 255};
  }
  ClusterOptions octree = octree_options(30);
  octree.representative = Representative::mean;
  for (const ClusterOptions& options : {grid_options(7, Representative::mean), octree}) {
    SCOPED_TRACE(options.octree ? "octree" : "grid");
    const QuadricMesh soup = run(mesh, options, nullptr, true);
    const QuadricMesh indexed = run(mesh, options);
    ASSERT_EQ(soup.mesh.normals.size(), soup.mesh.vertex_count());
    ASSERT_EQ(soup.mesh.colors.size(), soup.mesh.vertex_count());
    ASSERT_EQ(soup.mesh.uvs.size(), soup.mesh.vertex_count());
    EXPECT_EQ(soup.mesh.vertex_count(), indexed.mesh.vertex_count());
    for (std::size_t v = 0; v < soup.mesh.vertex_count(); ++v) {
      const Vec3f& p = soup.mesh.positions[v];
      EXPECT_NEAR((soup.mesh.normals[v] - Vec3f(0, 0.6f, 0.8f)).norm(), 0.0, 1e-5) << v;  // float sums
      EXPECT_NEAR((soup.mesh.uvs[v] - p.head<2>()).norm(), 0.0, 1e-5) << v;
      // Rounded input reds (half a unit) and a rounded mean (another half).
      EXPECT_NEAR(soup.mesh.colors[v][0], 200 * p.x(), 1.0) << v;
      EXPECT_EQ(soup.mesh.colors[v][1], 7);
      EXPECT_EQ(soup.mesh.colors[v][2], 99);
    }
  }
}

TEST(Cluster, UnreferencedVerticesChangeNothing) {
  // Points no triangle uses (a scan's outliers, left in the vertex list) are not surface: they used to be
  // averaged into their cells' means and attributes, moving mean representatives off the plane.
  IndexedMesh plane = test::grid_square(40);
  plane.normals.assign(plane.vertex_count(), Vec3f(0, 0, 1));
  IndexedMesh strays = plane;
  std::mt19937 random(3);
  std::uniform_real_distribution<float> inside(0.0f, 1.0f);
  for (int i = 0; i < 200; ++i) {
    strays.positions.emplace_back(inside(random), inside(random), 0.3f * inside(random));
    strays.normals.emplace_back(1, 0, 0);
  }
  for (Representative r : {Representative::mean, Representative::quadric, Representative::constrained}) {
    const QuadricMesh a = run(plane, grid_options(12, r)), b = run(strays, grid_options(12, r));
    ASSERT_EQ(a.mesh.vertex_count(), b.mesh.vertex_count()) << representative_name(r);
    EXPECT_EQ(a.mesh.triangles, b.mesh.triangles) << representative_name(r);
    EXPECT_EQ(a.mesh.positions, b.mesh.positions) << representative_name(r);
    EXPECT_EQ(a.mesh.normals, b.mesh.normals) << representative_name(r);
  }
}

TEST(Cluster, DropsCollapsedAndRepeatedTriangles) {
  const IndexedMesh mesh = test::sphere(5);
  ClusterStats stats;
  const QuadricMesh out = run(mesh, grid_options(8), &stats);
  EXPECT_EQ(stats.input_triangles, mesh.face_count());
  EXPECT_EQ(stats.collapsed_triangles + stats.duplicate_triangles + stats.output_faces, mesh.face_count());
  const MeshTopology topology = analyze_topology(out.mesh);
  EXPECT_EQ(topology.degenerate_faces, 0u);
  EXPECT_EQ(topology.duplicate_faces, 0u);
}

// A sheet with a patch that the input also shows in the opposite turn (a two-sided decal on it, or the two
// sides of a thin part closer than a cell): the patch's clustered faces are seen in both turns and the cells'
// order says nothing of which to keep. Each takes the turn of the faces around it, so the output has the
// faces of the sheet alone, each in the same turn: in the cells' order 33 to 122 edges were crossed twice
// the same way.
TEST(Cluster, FacesSeenInBothTurnsFollowTheirNeighbours) {
  IndexedMesh sheet = test::grid_square(48);
  for (Vec3f& p : sheet.positions) p.z() = 0.05f * std::sin(4 * p.x()) * std::cos(3 * p.y());
  sheet = tilted(std::move(sheet));
  IndexedMesh patched = sheet;
  for (const Triangle& t : sheet.triangles) {
    const Vec3f centroid = (sheet.positions[t[0]] + sheet.positions[t[1]] + sheet.positions[t[2]]) / 3;
    if ((centroid - sheet.positions[sheet.vertex_count() / 2]).norm() < 0.3f)
      patched.triangles.push_back({t[0], t[2], t[1]});
  }
  ASSERT_GT(patched.face_count(), sheet.face_count() + 1000);
  // Each face as its corners from the lowest, so that equal faces in equal turns compare equal.
  auto turns = [](const IndexedMesh& mesh) {
    std::vector<Triangle> out;
    for (Triangle t : mesh.triangles) {
      std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
      out.push_back(t);
    }
    std::sort(out.begin(), out.end());
    return out;
  };
  for (std::uint32_t grid : {8u, 11u, 16u}) {
    const QuadricMesh alone = run(sheet, grid_options(grid)), out = run(patched, grid_options(grid));
    ASSERT_GT(out.mesh.face_count(), 50u) << grid;
    EXPECT_EQ(analyze_topology(alone.mesh).inconsistent_edges, 0u) << grid;
    EXPECT_EQ(analyze_topology(out.mesh).inconsistent_edges, 0u) << grid;
    EXPECT_EQ(turns(out.mesh), turns(alone.mesh)) << grid;
  }
}

// The pipeline asks the pass for its fine cells before it reads a face, and may then read the stream whole
// instead: a refusal must leave the stream as it was.
TEST(Cluster, ARefusedGridLeavesTheStreamWhole) {
  const IndexedMesh mesh = tilted(test::sphere(4));
  ClusterOptions options = octree_options(200);
  std::uint64_t offered = 0;
  options.accept_fine_cells = [&](std::uint64_t cells) {
    offered = cells;
    return false;
  };
  auto stream = make_mesh_stream(mesh, false, 100);
  ClusterStats stats;
  const QuadricMesh refused = cluster(*stream, options, &stats);
  EXPECT_TRUE(stats.declined);
  EXPECT_GE(offered, 200u);
  EXPECT_EQ(stats.fine_cells, offered);
  EXPECT_EQ(refused.mesh.face_count(), 0u);
  const IndexedMesh read = read_mesh(*stream);
  EXPECT_EQ(read.positions, mesh.positions);
  EXPECT_EQ(read.triangles, mesh.triangles);
  // Accepted, the same cells are clustered.
  options.accept_fine_cells = [&](std::uint64_t cells) { return cells == offered; };
  ClusterStats accepted;
  EXPECT_EQ(run(mesh, options, &accepted).mesh.vertex_count(), 200u);
  EXPECT_FALSE(accepted.declined);
  EXPECT_EQ(accepted.fine_cells, offered);
}

// A cell whose every triangle collapsed (a corner of an open sheet, with both its triangles reaching into
// one neighbour) used to be written as a vertex no face uses.
TEST(Cluster, NoOutputVertexIsLeftWithoutAFace) {
  IndexedMesh sheet = test::grid_square(10);
  for (Vec3f& p : sheet.positions) p.z() = 0.1f * std::sin(7 * p.x()) * std::cos(5 * p.y());
  std::uint64_t dropped = 0;
  auto check = [&](const ClusterOptions& options, const std::string& what) {
    ClusterStats stats;
    const QuadricMesh out = run(sheet, options, &stats);
    ASSERT_GT(out.mesh.face_count(), 0u) << what;
    EXPECT_EQ(analyze_topology(out.mesh).unreferenced_vertices, 0u) << what;
    EXPECT_EQ(out.quadrics.size(), out.mesh.vertex_count()) << what;
    EXPECT_EQ(stats.output_vertices, out.mesh.vertex_count()) << what;
    dropped += stats.isolated_vertices;
  };
  for (std::uint32_t grid = 3; grid <= 12; ++grid)
    check(grid_options(grid), "--grid " + std::to_string(grid));
  for (std::uint64_t faces : {20u, 40u, 80u}) {
    ClusterOptions by_faces;
    by_faces.target_faces = faces;
    check(by_faces, "--faces " + std::to_string(faces));
    by_faces.octree = true;
    check(by_faces, "--octree --faces " + std::to_string(faces));
  }
  EXPECT_GT(dropped, 0u);  // some run had such a cell (--grid 9 has one)
}

TEST(Cluster, EmptyAndDegenerateInputs) {
  EXPECT_EQ(run(IndexedMesh{}, grid_options(10)).mesh.vertex_count(), 0u);
  IndexedMesh point;
  point.positions = {{1, 2, 3}, {1, 2, 3}, {1, 2, 3}};
  point.triangles = {{0, 1, 2}};
  const QuadricMesh out = run(point, grid_options(10));
  EXPECT_EQ(out.mesh.vertex_count(), 1u);
  EXPECT_EQ(out.mesh.face_count(), 0u);
  EXPECT_EQ(out.mesh.positions[0], Vec3f(1, 2, 3));
}

TEST(Cluster, RejectsBadInputAndImpossibleOptions) {
  IndexedMesh bad = test::grid_square(4);
  bad.triangles.push_back({0, 1, 999});
  EXPECT_THROW(run(bad, grid_options(4)), Error);
  IndexedMesh nan = test::grid_square(4);
  nan.positions[3].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(run(nan, grid_options(4)), Error);
  ClusterOptions octree;
  octree.octree = true;
  EXPECT_THROW(run(test::grid_square(4), octree), Error);
  ClusterOptions tiny;
  tiny.cell_size = 1e-9;
  EXPECT_THROW(run(test::grid_square(4), tiny), Error);
  ClusterOptions odd = grid_options(4);  // a value outside the enum placed like some default
  odd.representative = static_cast<Representative>(7);
  EXPECT_THROW(run(test::grid_square(4), odd), Error);
  IndexedMesh lost = test::grid_square(4);
  lost.origin.y() = std::numeric_limits<double>::infinity();
  EXPECT_THROW(run(lost, grid_options(4)), Error);
  for (double size : {-0.1, std::numeric_limits<double>::quiet_NaN()}) {
    ClusterOptions odd;  // fell back to the grid resolution without a word
    odd.cell_size = size;
    EXPECT_THROW(run(test::grid_square(4), odd), Error) << size;
  }
  // The message gives the size asked for and the smallest allowed, not six fixed decimals ("0.000000").
  std::string message;
  try {
    run(test::grid_square(4), tiny);
  } catch (const Error& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("cell size 1e-09 "), std::string::npos) << message;
  // 1 / 2^21 = 4.76837158e-07, rounded up so that the size shown is allowed and differs from a refused one.
  EXPECT_NE(message.find("the smallest is 4.77e-07"), std::string::npos) << message;
  tiny.cell_size = 4.76837e-07;
  try {
    run(test::grid_square(4), tiny);
    ADD_FAILURE() << "a cell size under 1 / 2^21 of the box was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cell size 4.76837e-07 "), std::string::npos) << e.what();
  }
  tiny.cell_size = 4.77e-07;
  EXPECT_EQ(run(test::grid_square(4), tiny).mesh.face_count(), test::grid_square(4).face_count());
  ClusterOptions zero;
  zero.grid = 0;
  EXPECT_THROW(run(test::grid_square(4), zero), Error);
}

TEST(Cluster, ClustersASharedMeshFromDisk) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "bunny.ply");
  auto stream = open_triangle_stream(path);
  const std::uint64_t faces = stream->triangles_hint();
  ClusterStats stats;
  const QuadricMesh out = cluster(*stream, grid_options(64), &stats);
  EXPECT_EQ(stats.input_triangles, faces);
  EXPECT_GT(out.mesh.face_count(), 1000u);
  EXPECT_LT(out.mesh.face_count(), faces);
  EXPECT_EQ(analyze_topology(out.mesh).degenerate_faces, 0u);
}

// The cluster stage packs each vertex's cell into its position's bytes before the faces come, and a reader
// splits a polygon by its corners' positions: it read the packed bytes, so a concave polygon was cut
// across its outside (a star's output covered 2.5 times its area) and a quad along either diagonal.
TEST(Cluster, PolygonsAreSplitAsTheReaderSplitsThem) {
  test::TempDir dir;
  // A comb of two notches (concave, area 17) in the plane z = 0, then a ring of bent quads.
  std::string obj =
      "v 0 0 0\nv 7 0 0\nv 7 3 0\nv 6 3 0\nv 6 1 0\nv 5 1 0\nv 5 3 0\nv 4 3 0\nv 4 1 0\n"
      "v 3 1 0\nv 3 3 0\nv 0 3 0\nf 1 2 3 4 5 6 7 8 9 10 11 12\n";
  const int ring = 12;
  for (int i = 0; i < ring; ++i) {
    const double a = 2 * M_PI * i / ring;
    char line[128];
    std::snprintf(line, sizeof line, "v %.9f %.9f %.9f\nv %.9f %.9f %.9f\n", 10 * std::cos(a),
                  10 * std::sin(a), 5 + 0.3 * (i % 2), 11 * std::cos(a), 11 * std::sin(a), 5.0);
    obj += line;
  }
  for (int i = 0; i < ring; ++i) {
    const int a = 13 + 2 * i, b = 13 + 2 * ((i + 1) % ring);
    obj += "f " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(b + 1) + " " +
           std::to_string(a + 1) + "\n";
  }
  std::ofstream(dir / "polygons.obj") << obj;
  const IndexedMesh expected = read_mesh(dir / "polygons.obj");
  ASSERT_EQ(expected.face_count(), 10u + 2 * ring);
  write_mesh(dir / "polygons.ply", expected);  // triangles: the same split, as a reference
  std::ofstream(dir / "polygons_ascii.ply") << [&] {
    // The same polygons as a PLY's faces.
    std::string ply = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(expected.vertex_count()) +
                      "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                      std::to_string(1 + ring) + "\nproperty list uchar int vertex_indices\nend_header\n";
    for (const Vec3f& p : expected.positions) {
      char line[96];
      std::snprintf(line, sizeof line, "%.9g %.9g %.9g\n", p.x(), p.y(), p.z());
      ply += line;
    }
    ply += "12 0 1 2 3 4 5 6 7 8 9 10 11\n";
    for (int i = 0; i < ring; ++i) {
      const int a = 12 + 2 * i, b = 12 + 2 * ((i + 1) % ring);
      ply += "4 " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(b + 1) + " " +
             std::to_string(a + 1) + "\n";
    }
    return ply;
  }();
  using Corners = std::array<std::array<float, 3>, 3>;
  auto triangles = [](const IndexedMesh& m) {
    std::set<Corners> out;
    for (const Triangle& t : m.triangles) {
      Corners c;
      for (int k = 0; k < 3; ++k)
        c[k] = {m.positions[t[k]].x(), m.positions[t[k]].y(), m.positions[t[k]].z()};
      std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
      out.insert(c);
    }
    return out;
  };
  double comb_area = 0;
  for (const Triangle& t : expected.triangles) {
    const Vec3d a = expected.positions[t[0]].cast<double>(), b = expected.positions[t[1]].cast<double>(),
                c = expected.positions[t[2]].cast<double>();
    if (a.z() == 0 && b.z() == 0 && c.z() == 0) comb_area += (b - a).cross(c - a).norm() / 2;
  }
  EXPECT_NEAR(comb_area, 17.0, 1e-9);  // the reader's own split stays inside the outline
  // Cells far smaller than the edges, and mean placement: every vertex is its own cell, in place.
  for (const std::string name : {"polygons.obj", "polygons_ascii.ply"}) {
    for (std::uint64_t budget : {std::uint64_t{0}, std::uint64_t{1} << 30}) {
      ReadOptions read;
      read.memory_budget = budget;  // as the command opens it: an OBJ's vertices pass a spool first
      auto stream = open_triangle_stream(dir / name, read);
      const QuadricMesh out = cluster(*stream, grid_options(4096, Representative::mean));
      EXPECT_EQ(triangles(out.mesh), triangles(expected)) << name << " " << budget;
    }
  }
}

}  // namespace
}  // namespace ocsimp
