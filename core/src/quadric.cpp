#include "ocsimp/core/quadric.h"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace ocsimp {

Quadric Quadric::plane(const Vec3d& n, double d, double weight) {
  Quadric q;
  q.a00 = weight * n.x() * n.x();
  q.a01 = weight * n.x() * n.y();
  q.a02 = weight * n.x() * n.z();
  q.a11 = weight * n.y() * n.y();
  q.a12 = weight * n.y() * n.z();
  q.a22 = weight * n.z() * n.z();
  q.b0 = weight * d * n.x();
  q.b1 = weight * d * n.y();
  q.b2 = weight * d * n.z();
  q.c = weight * d * d;
  return q;
}

Quadric Quadric::triangle(const Vec3d& p0, const Vec3d& p1, const Vec3d& p2) {
  const Vec3d cross = (p1 - p0).cross(p2 - p0);
  const double length = cross.norm();
  if (!(length > 0.0)) return {};
  const Vec3d n = cross / length;
  return plane(n, -n.dot(p0), 0.5 * length);
}

Quadric& Quadric::operator*=(double s) {
  a00 *= s;
  a01 *= s;
  a02 *= s;
  a11 *= s;
  a12 *= s;
  a22 *= s;
  b0 *= s;
  b1 *= s;
  b2 *= s;
  c *= s;
  return *this;
}

double Quadric::evaluate(const Vec3d& p) const {
  const double x = p.x(), y = p.y(), z = p.z();
  return a00 * x * x + 2 * a01 * x * y + 2 * a02 * x * z + a11 * y * y + 2 * a12 * y * z + a22 * z * z +
         2 * (b0 * x + b1 * y + b2 * z) + c;
}

Eigen::Matrix3d Quadric::a() const {
  Eigen::Matrix3d m;
  m << a00, a01, a02, a01, a11, a12, a02, a12, a22;
  return m;
}

QuadricMinimum minimize(const Quadric& q, const Vec3d& origin, double relative_tolerance) {
  const Eigen::Matrix3d a = q.a();
  // Gradient of Q at the origin, halved: the minimizer solves A y = -g for the offset y = p - origin.
  const Vec3d g = a * origin + q.b();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(a);
  const Vec3d values = solver.eigenvalues();
  const Eigen::Matrix3d vectors = solver.eigenvectors();
  const double largest = std::max(std::abs(values(0)), std::max(std::abs(values(1)), std::abs(values(2))));
  QuadricMinimum result{origin, 0};
  if (!(largest > 0.0) || !std::isfinite(largest)) return result;
  // Never below 0: a negative tolerance took in the small negative eigenvalues rounding gives a flat
  // quadric, and divided by them.
  const double tolerance = relative_tolerance > 0 ? relative_tolerance : 0.0;
  Vec3d offset = Vec3d::Zero();
  for (int i = 0; i < 3; ++i) {
    if (values(i) > tolerance * largest) {
      const Vec3d v = vectors.col(i);
      offset -= v * (v.dot(g) / values(i));
      ++result.rank;
    }
  }
  result.point = origin + offset;
  return result;
}

}  // namespace ocsimp
