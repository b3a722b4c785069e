#include "ocsimp/tools/compare.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include "ocsimp/core/error.h"
#include "test_support.h"

namespace ocsimp {
namespace {

IndexedMesh translated(IndexedMesh mesh, const Vec3f& offset) {
  for (Vec3f& p : mesh.positions) p += offset;
  return mesh;
}

// The unit square [lo, hi]^2 at z = 0, as a grid of n x n quads.
IndexedMesh square(int n, float lo, float hi) {
  IndexedMesh mesh = test::grid_square(n);
  for (Vec3f& p : mesh.positions) p.head<2>() = Vec2f::Constant(lo) + (hi - lo) * p.head<2>();
  return mesh;
}

// The regular icosahedron inscribed in the unit sphere, faces found as the triples of mutually adjacent
// corners and turned outward.
IndexedMesh icosahedron() {
  const float phi = (1.0f + std::sqrt(5.0f)) / 2.0f;
  IndexedMesh mesh;
  for (float s : {-1.0f, 1.0f})
    for (float t : {-1.0f, 1.0f}) {
      mesh.positions.push_back(Vec3f(0, s, t * phi).normalized());
      mesh.positions.push_back(Vec3f(s, t * phi, 0).normalized());
      mesh.positions.push_back(Vec3f(t * phi, 0, s).normalized());
    }
  float shortest = std::numeric_limits<float>::infinity();
  for (Index i = 0; i < 12; ++i)
    for (Index j = i + 1; j < 12; ++j)
      shortest = std::min(shortest, (mesh.positions[i] - mesh.positions[j]).norm());
  auto adjacent = [&](Index i, Index j) {
    return (mesh.positions[i] - mesh.positions[j]).norm() < shortest * 1.01f;
  };
  for (Index i = 0; i < 12; ++i)
    for (Index j = i + 1; j < 12; ++j)
      for (Index k = j + 1; k < 12; ++k) {
        if (!adjacent(i, j) || !adjacent(j, k) || !adjacent(i, k)) continue;
        const Vec3f& a = mesh.positions[i];
        const Vec3f n = (mesh.positions[j] - a).cross(mesh.positions[k] - a);
        if (n.dot(a) > 0)
          mesh.triangles.push_back({i, j, k});
        else
          mesh.triangles.push_back({i, k, j});
      }
  return mesh;
}

double brute_force_distance_squared(const IndexedMesh& mesh, const Vec3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const Triangle& t : mesh.triangles) {
    const Vec3d q =
        closest_point_on_triangle(p, mesh.positions[t[0]].cast<double>(), mesh.positions[t[1]].cast<double>(),
                                  mesh.positions[t[2]].cast<double>());
    best = std::min(best, (q - p).squaredNorm());
  }
  return best;
}

void expect_identical(const OneSidedDistance& a, const OneSidedDistance& b) {
  EXPECT_EQ(a.hausdorff, b.hausdorff);
  EXPECT_EQ(a.mean, b.mean);
  EXPECT_EQ(a.rms, b.rms);
  EXPECT_EQ(a.samples, b.samples);
  EXPECT_EQ(a.vertex_samples, b.vertex_samples);
  EXPECT_EQ(a.farthest, b.farthest);
  EXPECT_EQ(a.hausdorff_bound, b.hausdorff_bound);
}

TEST(ClosestPointOnTriangle, RegionsOfARightTriangle) {
  const Vec3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  // Above the interior: the foot of the perpendicular.
  EXPECT_TRUE(closest_point_on_triangle({0.25, 0.25, 2}, a, b, c).isApprox(Vec3d(0.25, 0.25, 0)));
  // Beyond each corner.
  EXPECT_EQ(closest_point_on_triangle({-1, -1, 0.5}, a, b, c), a);
  EXPECT_EQ(closest_point_on_triangle({3, -1, 0}, a, b, c), b);
  EXPECT_EQ(closest_point_on_triangle({-0.5, 4, 0}, a, b, c), c);
  // Beyond each edge.
  EXPECT_TRUE(closest_point_on_triangle({0.5, -2, 1}, a, b, c).isApprox(Vec3d(0.5, 0, 0)));
  EXPECT_TRUE(closest_point_on_triangle({-3, 0.5, -1}, a, b, c).isApprox(Vec3d(0, 0.5, 0)));
  EXPECT_TRUE(closest_point_on_triangle({1, 1, 0}, a, b, c).isApprox(Vec3d(0.5, 0.5, 0)));
}

TEST(ClosestPointOnTriangle, DegenerateTrianglesAreTheirEdges) {
  const Vec3d p(0.5, 1, 0);
  // A point.
  EXPECT_EQ(closest_point_on_triangle(p, Vec3d(2, 0, 0), Vec3d(2, 0, 0), Vec3d(2, 0, 0)), Vec3d(2, 0, 0));
  // Collinear corners, in every order: the segment [0, 2] on the x axis.
  for (const auto& [a, b, c] : {std::array<Vec3d, 3>{Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(2, 0, 0)},
                                std::array<Vec3d, 3>{Vec3d(1, 0, 0), Vec3d(2, 0, 0), Vec3d(0, 0, 0)},
                                std::array<Vec3d, 3>{Vec3d(2, 0, 0), Vec3d(0, 0, 0), Vec3d(2, 0, 0)}}) {
    const Vec3d q = closest_point_on_triangle(p, a, b, c);
    EXPECT_TRUE(q.allFinite());
    EXPECT_NEAR((q - Vec3d(0.5, 0, 0)).norm(), 0, 1e-15);
  }
  EXPECT_TRUE(closest_point_on_triangle({5, 1, 0}, Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(2, 0, 0))
                  .isApprox(Vec3d(2, 0, 0)));
}

// Against a dense search over the triangle: never farther than the densest sample, never nearer than the
// search's resolution allows, and always on the triangle.
TEST(ClosestPointOnTriangle, MatchesDenseSearchOnRandomTriangles) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> coordinate(-1, 1);
  auto random_point = [&] { return Vec3d(coordinate(rng), coordinate(rng), coordinate(rng)); };
  constexpr int n = 150;
  for (int trial = 0; trial < 300; ++trial) {
    const Vec3d a = random_point();
    Vec3d b = random_point(), c = random_point();
    if (trial % 10 == 0) c = a + 1e-9 * (b - a) + Vec3d(0, 0, 1e-12);  // slivers
    if (trial % 10 == 1) c = 0.3 * a + 0.7 * b;                        // collinear
    const Vec3d p = 2 * random_point();
    const Vec3d q = closest_point_on_triangle(p, a, b, c);
    double dense = std::numeric_limits<double>::infinity();
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const Vec3d x = a + (double(i) / n) * (b - a) + (double(j) / n) * (c - a);
        dense = std::min(dense, (x - p).norm());
      }
    const double spacing = std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()}) / n;
    const double d = (q - p).norm();
    EXPECT_LE(d, dense + 1e-12) << "trial " << trial;
    EXPECT_GE(d, dense - spacing) << "trial " << trial;
    // q lies on the triangle: its distance to the triangle (via a dense search around it) is tiny.
    double on = std::numeric_limits<double>::infinity();
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const Vec3d x = a + (double(i) / n) * (b - a) + (double(j) / n) * (c - a);
        on = std::min(on, (x - q).norm());
      }
    EXPECT_LE(on, spacing) << "trial " << trial;
  }
}

// A closed cone of `segments` sides, with fan caps, tilted off the axes: every triangle a long sliver lying
// across them, the mesh whose BVH is built with spatial splits.
IndexedMesh tilted_cone(int segments) {
  IndexedMesh mesh;
  const Eigen::Matrix3f turn =
      (Eigen::AngleAxisf(0.7f, Vec3f::UnitX()) * Eigen::AngleAxisf(0.4f, Vec3f::UnitY())).toRotationMatrix();
  for (int ring = 0; ring < 2; ++ring) {
    const float radius = ring == 0 ? 1.0f : 0.05f, z = ring == 0 ? -1.0f : 1.0f;
    for (int i = 0; i < segments; ++i) {
      const float angle = 2 * std::numbers::pi_v<float> * float(i) / float(segments);
      mesh.positions.push_back(turn * Vec3f(radius * std::cos(angle), radius * std::sin(angle), z));
    }
  }
  const Index bottom = static_cast<Index>(mesh.positions.size()), top = bottom + 1;
  mesh.positions.push_back(turn * Vec3f(0, 0, -1));
  mesh.positions.push_back(turn * Vec3f(0, 0, 1));
  const Index n = static_cast<Index>(segments);
  for (Index i = 0; i < n; ++i) {
    const Index j = (i + 1) % n;
    mesh.triangles.push_back({i, j, n + j});
    mesh.triangles.push_back({i, n + j, n + i});
    mesh.triangles.push_back({bottom, j, i});
    mesh.triangles.push_back({top, n + i, n + j});
  }
  return mesh;
}

// Bounded and unbounded queries at random points against a brute-force minimum over every triangle.
void expect_exact_closest_points(const IndexedMesh& mesh, std::uint64_t seed) {
  const DistanceIndex index(mesh);
  EXPECT_EQ(index.triangle_count(), mesh.face_count());
  EXPECT_EQ(index.referenced_vertex_count(), mesh.vertex_count());
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> coordinate(-2, 2);
  for (int i = 0; i < 500; ++i) {
    const Vec3d p(coordinate(rng), coordinate(rng), coordinate(rng));
    const ClosestPoint closest = index.closest_point(p);
    const double expected = brute_force_distance_squared(mesh, p);
    // Same triangles, same arithmetic: bit-identical, not merely close.
    EXPECT_EQ(closest.distance_squared, expected);
    EXPECT_EQ((closest.point - p).squaredNorm(), expected);
    ASSERT_LT(closest.triangle, mesh.face_count());
    // A bound at or above the answer changes nothing; one well below it finds nothing.
    EXPECT_EQ(index.closest_point(p, std::sqrt(expected) * 1.5 + 1e-3).distance_squared, expected);
    if (expected > 1e-4) {
      EXPECT_TRUE(std::isinf(index.closest_point(p, 0.5 * std::sqrt(expected)).distance_squared));
    }
  }
}

TEST(DistanceIndex, ClosestPointIsTheExactMinimumOverAllTriangles) {
  expect_exact_closest_points(test::sphere(3), 3);
}

TEST(DistanceIndex, ClosestPointIsExactAmongSliversAcrossTheAxes) {
  expect_exact_closest_points(tilted_cone(400), 4);
}

TEST(DistanceIndex, RejectsMeshesItCannotMeasure) {
  EXPECT_THROW(DistanceIndex(IndexedMesh{}), Error);
  IndexedMesh bad_index = test::grid_square(1);
  bad_index.triangles.push_back({0, 1, 7});
  try {
    DistanceIndex index(bad_index, "bad.ply");
    FAIL() << "a triangle referring to a missing vertex was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), "bad.ply");
    EXPECT_NE(e.reason().find("vertex 7"), std::string::npos) << e.what();
  }
  IndexedMesh not_finite = test::grid_square(1);
  not_finite.positions[2].y() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(DistanceIndex{not_finite}, Error);
  IndexedMesh lost = test::grid_square(1);
  lost.origin.z() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(DistanceIndex{lost}, Error);
  // A NaN point was called "too far from this mesh".
  try {
    DistanceIndex(test::grid_square(1)).closest_point(Vec3d(std::nan(""), 0, 0));
    FAIL() << "a NaN point was measured";
  } catch (const Error& e) {
    EXPECT_NE(e.reason().find("not finite"), std::string::npos) << e.what();
  }
  // A mesh 1e30 across is measured (see TinyAndHugeMeshesMeasureLikeTheirUnitSizedCopies), but a point 1e30
  // away from a unit-sized one is too far for its float index.
  IndexedMesh huge = test::grid_square(1);
  huge.positions[1].x() = 1e30f;
  EXPECT_THROW(measure_distance(test::grid_square(2), huge), Error);
  // A mesh whose coordinates are all subnormal floats is refused as too small (every query had missed it,
  // and the message blamed a point "too far from this mesh").
  IndexedMesh subnormal = test::grid_square(1);
  for (Vec3f& p : subnormal.positions) p *= 1e-40f;
  try {
    measure_distance(subnormal, subnormal);
    FAIL() << "a mesh of subnormal coordinates was measured";
  } catch (const Error& e) {
    EXPECT_NE(e.reason().find("too small to measure"), std::string::npos) << e.what();
  }
  EXPECT_THROW(measure_distance(IndexedMesh{}, test::grid_square(2)), Error);
  EXPECT_THROW(measure_distance(test::grid_square(2), IndexedMesh{}), Error);
  CompareOptions nothing;
  nothing.samples = 0;
  nothing.include_vertices = false;
  EXPECT_THROW(measure_distance(test::grid_square(2), test::grid_square(2), nothing), Error);
}

TEST(DistanceIndex, SamplesAreUniformByArea) {
  const DistanceIndex index(test::grid_square(16));
  constexpr std::size_t count = 20000;
  const std::vector<Vec3d> samples = index.sample_surface(count, 5);
  ASSERT_EQ(samples.size(), count);
  std::size_t left = 0, low = 0;
  for (const Vec3d& p : samples) {
    EXPECT_GE(p.x(), 0);
    EXPECT_LE(p.x(), 1);
    EXPECT_GE(p.y(), 0);
    EXPECT_LE(p.y(), 1);
    EXPECT_EQ(p.z(), 0);
    left += p.x() < 0.5;
    low += p.y() < 0.5;
  }
  // Triangles run row by row, so stratification along the cumulative area splits rows exactly.
  EXPECT_NEAR(double(low) / count, 0.5, 2.0 / count);
  EXPECT_NEAR(double(left) / count, 0.5, 0.01);
  // Two triangles of areas 1 and 3: a quarter of the samples in the first.
  IndexedMesh pair;
  pair.positions = {{0, 0, 0}, {2, 0, 0}, {0, 1, 0}, {10, 0, 0}, {13, 0, 0}, {10, 2, 0}};
  pair.triangles = {{0, 1, 2}, {3, 4, 5}};
  const std::vector<Vec3d> split = DistanceIndex(pair).sample_surface(count, 1);
  std::size_t first = 0;
  for (const Vec3d& p : split) first += p.x() < 5;
  EXPECT_NEAR(double(first) / count, 0.25, 2.0 / count);
}

// A triangle stored many times (here 3,000 times, once through vertices of its own, corners turned) is
// indexed once: queries find the same points at the same distances, name its first copy, and samples are
// still drawn on every copy, as on the mesh the file holds.
TEST(DistanceIndex, RepeatedTrianglesMeasureAsOnce) {
  const IndexedMesh once = test::sphere(2);
  IndexedMesh repeated = once;
  const Triangle t = once.triangles[7];
  const Vec3d a0 = once.positions[t[0]].cast<double>(), a1 = once.positions[t[1]].cast<double>(),
              a2 = once.positions[t[2]].cast<double>();
  const double t_area = 0.5 * (a1 - a0).cross(a2 - a0).norm();
  for (int i = 0; i < 1000; ++i) {
    repeated.triangles.push_back(t);
    repeated.triangles.push_back({t[1], t[2], t[0]});
  }
  const Index own = static_cast<Index>(repeated.positions.size());
  for (int k = 0; k < 3; ++k) repeated.positions.push_back(once.positions[t[k]]);
  for (int i = 0; i < 1000; ++i) repeated.triangles.push_back({own + 2, own, own + 1});
  const DistanceIndex a(once), b(repeated);
  EXPECT_NEAR(b.area(), a.area() + 3000 * t_area, 1e-9 * b.area());
  std::mt19937 random(5);
  std::uniform_real_distribution<double> coordinate(-2, 2);
  for (int i = 0; i < 2000; ++i) {
    const Vec3d p(coordinate(random), coordinate(random), coordinate(random));
    const ClosestPoint x = a.closest_point(p), y = b.closest_point(p);
    ASSERT_EQ(x.distance_squared, y.distance_squared) << p.transpose();
    EXPECT_EQ(x.point, y.point);
    EXPECT_EQ(x.triangle, y.triangle);  // the copies come after the original, which wins the tie
  }
  // Samples on the copies: the triangle holds 3001 / (3000 + sphere area / its area) of them.
  const double share = 3001 * t_area / b.area();
  std::size_t on_it = 0;
  const std::vector<Vec3d> samples = b.sample_surface(20000, 3);
  for (const Vec3d& p : samples) on_it += a.closest_point(p).triangle == 7;
  EXPECT_NEAR(double(on_it) / double(samples.size()), share, 0.02);
}

TEST(DistanceIndex, DegenerateTrianglesAreNeverSampledAndStillMeasured) {
  IndexedMesh mesh = test::grid_square(2);
  const Index far = static_cast<Index>(mesh.positions.size());
  mesh.positions.emplace_back(3, 3, 3);
  mesh.positions.emplace_back(4, 4, 4);
  mesh.positions.emplace_back(5, 5, 5);
  mesh.triangles.insert(mesh.triangles.begin(), {far, far, far});              // a point
  mesh.triangles.insert(mesh.triangles.begin() + 3, {far, far + 1, far + 2});  // collinear
  mesh.triangles.push_back({far + 2, far + 1, far + 2});                       // a repeated corner, last
  const DistanceIndex index(mesh);
  EXPECT_NEAR(index.area(), 1.0, 1e-12);
  for (const Vec3d& p : index.sample_surface(5000, 2)) {
    ASSERT_TRUE(p.allFinite());
    EXPECT_EQ(p.z(), 0);  // on the square, never on the degenerate triangles off to the side
  }
  // Queries still see the degenerate triangles: they are a segment from (3,3,3) to (5,5,5).
  const ClosestPoint closest = index.closest_point({6, 6, 6});
  EXPECT_NEAR(std::sqrt(closest.distance_squared), std::sqrt(3.0), 1e-12);

  // A mesh of only degenerate triangles is measured at its vertices.
  IndexedMesh segment;
  segment.positions = {{0, 0, 1}, {1, 0, 1}, {2, 0, 1}};
  segment.triangles = {{0, 1, 2}};
  CompareOptions options;
  options.samples = 10000;
  const SurfaceDistance d = measure_distance(segment, test::grid_square(2), options);
  EXPECT_EQ(d.forward.samples, 0u);
  EXPECT_EQ(d.forward.vertex_samples, 3u);
  // Vertices 0 and 1 sit 1 above the square; vertex 2 is 1 beyond its edge too.
  EXPECT_NEAR(d.forward.hausdorff, std::sqrt(2.0), 1e-7);
  EXPECT_NEAR(d.forward.mean, (2 + std::sqrt(2.0)) / 3, 1e-7);
}

TEST(MeasureDistance, IdenticalMeshesAreZeroApart) {
  const IndexedMesh mesh = test::sphere(3);
  CompareOptions options;
  options.samples = 50000;
  const SurfaceDistance d = measure_distance(mesh, mesh, options);
  EXPECT_LT(d.hausdorff, 1e-12);
  EXPECT_LT(d.mean, 1e-12);
  EXPECT_LT(d.rms, 1e-12);
  EXPECT_EQ(d.forward.samples, 50000u);
  EXPECT_EQ(d.forward.vertex_samples, mesh.vertex_count());
  EXPECT_NEAR(d.diagonal, 2 * std::sqrt(3.0), 1e-6);
}

TEST(MeasureDistance, ShiftedPlaneIsItsShiftAway) {
  const float shift = 0.05f;
  const IndexedMesh plane = test::grid_square(8);
  const IndexedMesh lifted = translated(test::grid_square(3), {0, 0, shift});
  CompareOptions options;
  options.samples = 30000;
  const SurfaceDistance d = measure_distance(plane, lifted, options);
  for (const OneSidedDistance& side : {d.forward, d.backward}) {
    EXPECT_NEAR(side.hausdorff, shift, 1e-9);
    EXPECT_NEAR(side.mean, shift, 1e-9);
    EXPECT_NEAR(side.rms, shift, 1e-9);
  }
  EXPECT_NEAR(d.hausdorff, shift, 1e-9);
  EXPECT_NEAR(d.rms, shift, 1e-9);
  EXPECT_NEAR(d.mean, shift, 1e-9);
  EXPECT_NEAR(d.diagonal, std::sqrt(2.0), 1e-7);
  EXPECT_NEAR(d.percent(d.hausdorff), 100 * shift / std::sqrt(2.0), 1e-6);
}

// The percentages are of the surface's diagonal: a vertex no face uses, far out, is not part of it (it made
// the diagonal 173 instead of 1.41 and every percentage 120 times smaller).
TEST(MeasureDistance, AStrayVertexDoesNotChangeTheDiagonal) {
  const float shift = 0.05f;
  IndexedMesh plane = test::grid_square(8);
  plane.positions.push_back({100, 100, 100});
  const IndexedMesh lifted = translated(test::grid_square(3), {0, 0, shift});
  CompareOptions options;
  options.samples = 10000;
  const SurfaceDistance d = measure_distance(plane, lifted, options);
  EXPECT_NEAR(d.hausdorff, shift, 1e-9);
  EXPECT_NEAR(d.diagonal, std::sqrt(2.0), 1e-7);
  EXPECT_NEAR(d.percent(d.hausdorff), 100 * shift / std::sqrt(2.0), 1e-6);
}

// A float mesh far from zero for its size (no origin of its own, as an STL at UTM northings) is indexed
// about its centre: Embree's culling, widened by 1e-6 of the coordinates, took in every triangle there, and
// comparing such a scan with itself ran for hours. The distances are as exact as near zero.
TEST(MeasureDistance, AFloatMeshFarFromZeroIsIndexedAboutItsCentre) {
  const Vec3f far(500000.0f, 4000000.0f, 0.0f);
  const float shift = 0.25f;
  IndexedMesh plane = test::grid_square(8), lifted = test::grid_square(3);
  for (Vec3f& p : plane.positions) p = 16.0f * p + far;
  for (Vec3f& p : lifted.positions) p = 16.0f * p + far + Vec3f(0, 0, shift);
  const DistanceIndex index(plane, "far");
  EXPECT_LT((index.origin() - far.cast<double>()).norm(), 16.0);
  EXPECT_NEAR(index.bounds().diagonal(), 16.0 * std::sqrt(2.0), 1e-9);
  CompareOptions options;
  options.samples = 5000;
  const SurfaceDistance d = measure_distance(plane, lifted, options);
  EXPECT_NEAR(d.hausdorff, shift, 1e-9);
  EXPECT_NEAR(d.rms, shift, 1e-9);
}

// Two meshes read far from zero with different origins (IndexedMesh::origin): the same lifted plane as above,
// its positions relative to an origin 0.25 and 0.5 away from the plane's, is still 0.05 away.
TEST(MeasureDistance, MeshesWithDifferentOriginsMeetInOneFrame) {
  IndexedMesh plane = test::grid_square(8);
  plane.origin = Vec3d(652'113.25, 4'210'775.5, 312.125);
  IndexedMesh lifted = translated(test::grid_square(3), {-0.25f, 0.5f, 0.0f});
  lifted.origin = plane.origin + Vec3d(0.25, -0.5, 0.05);
  CompareOptions options;
  options.samples = 30000;
  const SurfaceDistance d = measure_distance(plane, lifted, options);
  for (const OneSidedDistance& side : {d.forward, d.backward}) {
    EXPECT_NEAR(side.hausdorff, 0.05, 1e-6);
    EXPECT_NEAR(side.rms, 0.05, 1e-6);
    // Where it was reached, in the files' coordinates: on the plane's square.
    const Vec3d at = side.farthest - plane.origin;
    EXPECT_TRUE(at.x() > -1e-6 && at.x() < 1 + 1e-6 && at.y() > -1e-6 && at.y() < 1 + 1e-6) << at.transpose();
  }
}

// A patch [0.4, 0.6]^2 in the plane of the unit square: every patch point lies on the square, while the
// square's corners are 0.4 sqrt(2) from the patch.
TEST(MeasureDistance, OneSidedDistancesDifferWhereTheyShould) {
  const IndexedMesh patch = square(2, 0.4f, 0.6f);
  const IndexedMesh plane = square(16, 0.0f, 1.0f);
  CompareOptions options;
  options.samples = 200000;
  const SurfaceDistance d = measure_distance(patch, plane, options);
  EXPECT_LT(d.forward.hausdorff, 1e-7);
  EXPECT_LT(d.forward.rms, 1e-7);
  EXPECT_NEAR(d.backward.hausdorff, 0.4 * std::sqrt(2.0), 1e-6);  // reached at a corner vertex
  EXPECT_TRUE(d.backward.farthest.head<2>().isApprox(Eigen::Vector2d(0, 0)) ||
              d.backward.farthest.head<2>().isApprox(Eigen::Vector2d(1, 0)) ||
              d.backward.farthest.head<2>().isApprox(Eigen::Vector2d(0, 1)) ||
              d.backward.farthest.head<2>().isApprox(Eigen::Vector2d(1, 1)));
  // For (x, y) uniform on the square the squared distance is dx^2 + dy^2 with dx = max(0.4 - x, 0, x - 0.6),
  // so rms^2 = 2 E[dx^2] = 2 * 2 * 0.4^3 / 3.
  EXPECT_NEAR(d.backward.rms, std::sqrt(4 * 0.064 / 3), 1e-3);
  double mean = 0;
  constexpr int n = 1000;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double x = (i + 0.5) / n, y = (j + 0.5) / n;
      mean += std::hypot(std::max({0.4 - x, 0.0, x - 0.6}), std::max({0.4 - y, 0.0, y - 0.6}));
    }
  mean /= double(n) * n;
  EXPECT_NEAR(d.backward.mean, mean, 1e-3);
  EXPECT_EQ(d.hausdorff, d.backward.hausdorff);
  EXPECT_NEAR(d.rms, std::sqrt((d.forward.rms * d.forward.rms + d.backward.rms * d.backward.rms) / 2), 1e-15);
  EXPECT_NEAR(d.mean, (d.forward.mean + d.backward.mean) / 2, 1e-15);
  EXPECT_NEAR(d.diagonal, 0.2 * std::sqrt(2.0), 1e-7);  // the original's
}

// A (tessellated) unit sphere against the icosahedron inscribed in it. The widest gap in both directions is
// over a face centre: 1 - r_in, r_in = sqrt((5 + 2 sqrt 5) / 15) the inradius. The sphere mesh sits between
// radius 1 - sag and 1, which bounds how far each figure may be off.
TEST(MeasureDistance, SphereAgainstInscribedIcosahedron) {
  const IndexedMesh sphere = test::sphere(6);
  const IndexedMesh ico = icosahedron();
  ASSERT_EQ(ico.face_count(), 20u);
  const double r_in = std::sqrt((5 + 2 * std::sqrt(5.0)) / 15);
  const double gap = 1 - r_in;
  double sag = 0;
  for (const Triangle& t : sphere.triangles)
    sag = std::max(sag, 1 - closest_point_on_triangle(Vec3d::Zero(), sphere.positions[t[0]].cast<double>(),
                                                      sphere.positions[t[1]].cast<double>(),
                                                      sphere.positions[t[2]].cast<double>())
                                .norm());
  ASSERT_LT(sag, 1e-3);
  CompareOptions options;
  options.samples = 50000;
  const SurfaceDistance d = measure_distance(sphere, ico, options);
  constexpr double float_slack = 1e-6;  // positions are float
  EXPECT_LE(d.forward.hausdorff, gap + float_slack);
  EXPECT_GE(d.forward.hausdorff, gap - sag - 1e-4);
  EXPECT_LE(d.backward.hausdorff, gap + float_slack);
  // The refined maximum finds the face centre itself, which the samples only come near.
  EXPECT_GE(d.backward.hausdorff, (gap - sag) * (1 - 1e-4) - float_slack);
  EXPECT_GT(gap, 0.2);

  // Backward mean and rms: the average of (1 - |q|) and its square over an icosahedron face, integrated by
  // the midpoint rule on 4^8 sub-triangles; the sphere mesh moves each distance by at most `sag`.
  const Vec3d a = ico.positions[ico.triangles[0][0]].cast<double>();
  const Vec3d b = ico.positions[ico.triangles[0][1]].cast<double>();
  const Vec3d c = ico.positions[ico.triangles[0][2]].cast<double>();
  constexpr int n = 256;
  double sum = 0, sum_squares = 0;
  int cells = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; i + j < n; ++j) {
      // The upright sub-triangle (i, j) and, unless on the diagonal, the inverted one beside it.
      for (int flip = 0; flip < (i + j + 1 < n ? 2 : 1); ++flip) {
        const double u = flip ? (i + 2.0 / 3) / n : (i + 1.0 / 3) / n;
        const double v = flip ? (j + 2.0 / 3) / n : (j + 1.0 / 3) / n;
        const double g = 1 - (a + u * (b - a) + v * (c - a)).norm();
        sum += g;
        sum_squares += g * g;
        ++cells;
      }
    }
  ASSERT_EQ(cells, n * n);
  const double mean = sum / cells, rms = std::sqrt(sum_squares / cells);
  EXPECT_GT(d.backward.mean, mean - sag - 2e-4);
  EXPECT_LT(d.backward.mean, mean + 2e-4);
  EXPECT_GT(d.backward.rms, rms - sag - 2e-4);
  EXPECT_LT(d.backward.rms, rms + 2e-4);
  // Forward has no closed form; it must at least lie well inside (0, gap).
  EXPECT_GT(d.forward.mean, 0.25 * mean);
  EXPECT_LT(d.forward.mean, gap);
}

// The unit square, two triangles, against four small triangles at its corners: the square's widest gap is at
// its centre, far from any vertex, where a bridge of a coarse mesh would have it. Refinement finds it from
// the vertices alone (all on the corners, at distance 0) and with a few samples (which all fall short).
TEST(MeasureDistance, TheHausdorffDistanceIsRefinedToTheTrueMaximum) {
  const IndexedMesh plane = square(1, 0.0f, 1.0f);
  IndexedMesh corners;
  const float r = 0.01f;
  for (float x : {0.0f, 1.0f})
    for (float y : {0.0f, 1.0f}) {
      const Index first = static_cast<Index>(corners.positions.size());
      const float sx = x > 0 ? -r : r, sy = y > 0 ? -r : r;
      corners.positions.push_back(Vec3f(x, y, 0));
      corners.positions.push_back(Vec3f(x + sx, y, 0));
      corners.positions.push_back(Vec3f(x, y + sy, 0));
      corners.triangles.push_back({first, first + 1, first + 2});
    }
  // The centre's nearest points are the corner triangles' long edges' midpoints, (r/2, r/2) from a corner.
  const double truth = std::sqrt(2.0) * (0.5 - double(r) / 2);
  const DistanceIndex from(plane), to(corners);
  for (std::size_t samples : {std::size_t{0}, std::size_t{50}}) {
    CompareOptions options;
    options.samples = samples;
    const OneSidedDistance d = measure_one_sided(from, to, options);
    EXPECT_LE(d.hausdorff, truth * (1 + 1e-12)) << samples;
    EXPECT_GE(d.hausdorff, truth * (1 - 1e-4)) << samples;
    EXPECT_GE(d.hausdorff_bound, truth * (1 - 1e-12)) << samples;
    EXPECT_LE(d.hausdorff_bound, d.hausdorff * (1 + 1e-4) + 1e-12) << samples;
    EXPECT_TRUE(d.hausdorff_settled) << samples;
    EXPECT_NEAR(d.farthest.x(), 0.5, 0.01) << samples;
    EXPECT_NEAR(d.farthest.y(), 0.5, 0.01) << samples;
    if (samples == 0) continue;
    // What the samples and vertices alone give falls well short.
    options.include_vertices = false;
    const OneSidedDistance sampled = measure_one_sided(from, to, options);
    EXPECT_LT(sampled.hausdorff, truth * 0.99);
    EXPECT_FALSE(std::isfinite(sampled.hausdorff_bound));
  }
  // A larger budget never loosens the bound: a child's bound is capped by its parent's. A sphere against a
  // turned finer one does not settle within the smallest budget.
  IndexedMesh turned = test::sphere(5);
  const Eigen::Matrix3f turn = Eigen::AngleAxisf(0.3f, Vec3f(1, 2, 3).normalized()).toRotationMatrix();
  for (Vec3f& p : turned.positions) p = turn * p;
  const DistanceIndex sphere(test::sphere(4)), finer(turned);
  double previous = std::numeric_limits<double>::infinity();
  for (std::size_t samples : {std::size_t{0}, std::size_t{1'000'000}, std::size_t{2'000'000}}) {
    CompareOptions options;
    options.samples = samples;
    const OneSidedDistance d = measure_one_sided(sphere, finer, options);
    EXPECT_LE(d.hausdorff_bound, previous) << samples;
    previous = d.hausdorff_bound;
    if (samples == 0) {
      EXPECT_FALSE(d.hausdorff_settled);
    }
  }
  // A surface against itself (finely cut, so that corners sit on other triangles' edges) settles at 0: the
  // ties at its corners do not hold the bound up.
  const IndexedMesh fine = square(64, 0.0f, 1.0f);
  const DistanceIndex fine_index(fine);
  CompareOptions few;
  few.samples = 100;
  const OneSidedDistance self = measure_one_sided(fine_index, fine_index, few);
  EXPECT_TRUE(self.hausdorff_settled);
  EXPECT_LT(self.hausdorff_bound, 1e-8);
}

TEST(MeasureDistance, TinyAndHugeMeshesMeasureLikeTheirUnitSizedCopies) {
  // The index's float arithmetic underflowed on a mesh 1e-30 across (nothing was culled: minutes for a
  // small mesh) and Embree ignored coordinates beyond 1.8e18. Scaled by a power of two, every distance is
  // the unit-sized copy's, scaled exactly.
  const IndexedMesh sphere = test::sphere(4), ico = icosahedron();
  CompareOptions options;
  options.samples = 20000;
  const SurfaceDistance unit = measure_distance(sphere, ico, options);
  for (const int exponent : {-100, 100}) {
    SCOPED_TRACE(exponent);
    IndexedMesh a = sphere, b = ico;
    for (IndexedMesh* mesh : {&a, &b}) {
      for (Vec3f& p : mesh->positions) p *= std::ldexp(1.0f, exponent);
    }
    const SurfaceDistance d = measure_distance(a, b, options);
    for (const auto& [scaled, original] : {std::pair{d.forward, unit.forward}, {d.backward, unit.backward}}) {
      EXPECT_EQ(scaled.hausdorff, std::ldexp(original.hausdorff, exponent));
      EXPECT_EQ(scaled.mean, std::ldexp(original.mean, exponent));
      EXPECT_EQ(scaled.rms, std::ldexp(original.rms, exponent));
    }
    EXPECT_EQ(d.percent(d.rms), unit.percent(unit.rms));
  }
}

TEST(MeasureDistance, SameSeedSameNumbersAndSeedsDiffer) {
  const IndexedMesh original = test::sphere(4);
  const IndexedMesh simplified = test::sphere(2);
  CompareOptions options;
  options.samples = 40000;
  const SurfaceDistance first = measure_distance(original, simplified, options);
  const SurfaceDistance again = measure_distance(original, simplified, options);
  expect_identical(first.forward, again.forward);
  expect_identical(first.backward, again.backward);
  EXPECT_EQ(first.rms, again.rms);
  options.seed = 2;
  const SurfaceDistance other = measure_distance(original, simplified, options);
  EXPECT_NE(first.forward.mean, other.forward.mean);
  EXPECT_NEAR(first.forward.mean, other.forward.mean, 0.02 * first.forward.mean);
  EXPECT_NEAR(first.backward.rms, other.backward.rms, 0.02 * first.backward.rms);
}

TEST(MeasureDistance, ThreadCountDoesNotChangeTheNumbers) {
  const IndexedMesh original = test::sphere(5);
  const IndexedMesh simplified = translated(test::sphere(2), {0.01f, 0, 0});
  CompareOptions options;
  options.samples = 150000;  // enough chunks for more than one parallel round
  SurfaceDistance reference;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    reference = measure_distance(original, simplified, options);
  }
  for (int threads : {2, 3, 8}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const SurfaceDistance d = measure_distance(original, simplified, options);
    expect_identical(reference.forward, d.forward);
    expect_identical(reference.backward, d.backward);
    EXPECT_EQ(reference.hausdorff, d.hausdorff);
    EXPECT_EQ(reference.mean, d.mean);
    EXPECT_EQ(reference.rms, d.rms);
  }
}

TEST(MeasureDistance, ReusedIndicesGiveTheSameNumbers) {
  const IndexedMesh original = test::sphere(4);
  CompareOptions options;
  options.samples = 20000;
  const DistanceIndex original_index(original, "original");
  for (int level : {1, 2, 3}) {
    const IndexedMesh simplified = test::sphere(level);
    const SurfaceDistance direct = measure_distance(original, simplified, options);
    const SurfaceDistance reused = measure_distance(original_index, DistanceIndex(simplified), options);
    expect_identical(direct.forward, reused.forward);
    expect_identical(direct.backward, reused.backward);
  }
}

TEST(MeasureDistance, ReportsProgressToTheEnd) {
  CompareOptions options;
  options.samples = 10000;
  std::uint64_t forward_done = 0, forward_total = 0;
  options.progress = [&](std::string_view phase, std::uint64_t done, std::uint64_t total) {
    if (phase == "forward") forward_done = done, forward_total = total;
  };
  const IndexedMesh mesh = test::sphere(2);
  measure_distance(mesh, mesh, options);
  EXPECT_EQ(forward_total, 10000 + mesh.vertex_count());
  EXPECT_EQ(forward_done, forward_total);
}

}  // namespace
}  // namespace ocsimp
