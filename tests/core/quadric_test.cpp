#include "ocsimp/core/quadric.h"

#include <gtest/gtest.h>

#include <cmath>

namespace ocsimp {
namespace {

TEST(Quadric, TriangleQuadricMeasuresSquaredDistanceTimesArea) {
  // Unit right triangle in z = 0, area 0.5.
  const Quadric q = Quadric::triangle({0, 0, 0}, {1, 0, 0}, {0, 1, 0});
  EXPECT_NEAR(q.evaluate({0.3, 0.3, 0.0}), 0.0, 1e-15);
  EXPECT_NEAR(q.evaluate({5.0, -2.0, 2.0}), 0.5 * 4.0, 1e-12);
}

TEST(Quadric, DegenerateTriangleGivesZeroQuadric) {
  EXPECT_EQ(Quadric::triangle({0, 0, 0}, {1, 1, 1}, {2, 2, 2}), Quadric{});
}

TEST(Quadric, ThreePlanesMinimizeAtTheirCorner) {
  Quadric q = Quadric::plane({1, 0, 0}, -1.0, 1.0);
  q += Quadric::plane({0, 1, 0}, -2.0, 1.0);
  q += Quadric::plane({0, 0, 1}, -3.0, 1.0);
  const QuadricMinimum m = minimize(q, {10, 10, 10});
  EXPECT_EQ(m.rank, 3);
  EXPECT_NEAR((m.point - Vec3d(1, 2, 3)).norm(), 0.0, 1e-12);
}

TEST(Quadric, FlatQuadricProjectsTheOriginOntoThePlane) {
  const Quadric q = Quadric::plane(Vec3d(1, 1, 0).normalized(), 0.0, 2.0);
  const QuadricMinimum m = minimize(q, {3, 1, 7});
  EXPECT_EQ(m.rank, 1);
  // Nearest point of the plane x + y = 0 to (3, 1, 7) is (1, -1, 7).
  EXPECT_NEAR((m.point - Vec3d(1, -1, 7)).norm(), 0.0, 1e-12);
}

TEST(Quadric, CreaseQuadricProjectsOntoTheLine) {
  Quadric q = Quadric::plane({1, 0, 0}, 0.0, 1.0);
  q += Quadric::plane({0, 1, 0}, 0.0, 1.0);
  const QuadricMinimum m = minimize(q, {2, 3, 4});
  EXPECT_EQ(m.rank, 2);
  EXPECT_NEAR((m.point - Vec3d(0, 0, 4)).norm(), 0.0, 1e-12);
}

TEST(Quadric, NearlyParallelPlanesDoNotShootAway) {
  // Two planes 1e-6 rad apart meet far away; the truncated solve stays near the origin.
  Quadric q = Quadric::plane({0, 0, 1}, 0.0, 1.0);
  q += Quadric::plane(Vec3d(1e-6, 0, 1).normalized(), 0.0, 1.0);
  const QuadricMinimum m = minimize(q, {0.5, 0.5, 0.1});
  EXPECT_LT((m.point - Vec3d(0.5, 0.5, 0.0)).norm(), 1e-5);
}

TEST(Quadric, ToleranceBelowZeroCountsAsZero) {
  // A negative tolerance took in the eigenvalues at or below zero that rounding gives a flat quadric, and
  // divided by them.
  Quadric q = Quadric::plane(Vec3d(1, 1, 0).normalized(), 0.0, 2.0);
  for (double tolerance : {-1.0, std::nan("")}) {
    const QuadricMinimum m = minimize(q, {3, 1, 7}, tolerance);
    const QuadricMinimum zero = minimize(q, {3, 1, 7}, 0.0);
    EXPECT_EQ(m.rank, zero.rank) << tolerance;
    EXPECT_EQ(m.point, zero.point) << tolerance;
    EXPECT_TRUE(m.point.allFinite()) << tolerance;
  }
}

TEST(Quadric, ZeroQuadricReturnsOrigin) {
  const QuadricMinimum m = minimize(Quadric{}, {1, 2, 3});
  EXPECT_EQ(m.rank, 0);
  EXPECT_EQ(m.point, Vec3d(1, 2, 3));
}

}  // namespace
}  // namespace ocsimp
