// The quadric error metric of Garland & Heckbert (1997): the sum of squared distances to a set of planes,
// stored as a symmetric 4x4 matrix in 10 doubles. It is the currency between the cluster and decimate stages.
#pragma once

#include "ocsimp/core/types.h"

namespace ocsimp {

// Q(p) = p^T A p + 2 b^T p + c, with A symmetric 3x3 (a00 a01 a02 a11 a12 a22), b a 3-vector, c a scalar.
struct Quadric {
  double a00 = 0, a01 = 0, a02 = 0, a11 = 0, a12 = 0, a22 = 0;
  double b0 = 0, b1 = 0, b2 = 0;
  double c = 0;

  // weight * (n.p + d)^2 for a unit normal n.
  static Quadric plane(const Vec3d& n, double d, double weight);
  // The plane of a triangle weighted by its area; zero for a degenerate triangle.
  static Quadric triangle(const Vec3d& p0, const Vec3d& p1, const Vec3d& p2);

  // Inline: the cluster pass and the decimator's setup add one per triangle corner.
  Quadric& operator+=(const Quadric& q) {
    a00 += q.a00;
    a01 += q.a01;
    a02 += q.a02;
    a11 += q.a11;
    a12 += q.a12;
    a22 += q.a22;
    b0 += q.b0;
    b1 += q.b1;
    b2 += q.b2;
    c += q.c;
    return *this;
  }
  Quadric operator+(const Quadric& q) const {
    Quadric r = *this;
    r += q;
    return r;
  }
  Quadric& operator*=(double s);

  // Squared distance sum at p. Rounding can make it slightly negative; callers that need a distance clamp it.
  double evaluate(const Vec3d& p) const;

  Eigen::Matrix3d a() const;
  // The weight of its planes: each plane adds its weight to A's diagonal (its normal being a unit vector).
  double trace() const { return a00 + a11 + a22; }
  Vec3d b() const { return {b0, b1, b2}; }

  bool operator==(const Quadric&) const = default;
};

struct QuadricMinimum {
  Vec3d point;  // the minimizer nearest to the origin the solve was taken around
  int rank;     // 3: a unique point; 2: a line of minimizers (crease); 1: a plane (flat); 0: no constraint
};

// Minimizes q with a truncated eigen-decomposition of A around `origin` (Lindstrom 2000): directions whose
// eigenvalue is below `relative_tolerance` times the largest are left at the origin, so a flat or cylindrical
// region gets the point nearest the origin instead of an unstable one. Pass the cluster mean or edge
// midpoint. A tolerance of 0 (or below, or NaN, which count as 0) keeps every direction whose eigenvalue is
// positive: the exact solve where A is invertible, unstable where it nearly is not.
QuadricMinimum minimize(const Quadric& q, const Vec3d& origin, double relative_tolerance = 1e-3);

}  // namespace ocsimp
