// Where a collapsed pair goes and what it costs: the quadric's minimizer from an explicit 3x3 solve around
// the edge midpoint when the system is well conditioned, else the best point of the edge segment.
#pragma once

#include <algorithm>
#include <cmath>

#include "ocsimp/core/quadric.h"

namespace ocsimp::decimate_detail {

struct Placement {
  Vec3d point;   // relative to the decimator's local origin, like the quadric
  double error;  // Q(point), clamped at 0
};

inline void add_to(Quadric& sum, const Quadric& q) {
  sum.a00 += q.a00;
  sum.a01 += q.a01;
  sum.a02 += q.a02;
  sum.a11 += q.a11;
  sum.a12 += q.a12;
  sum.a22 += q.a22;
  sum.b0 += q.b0;
  sum.b1 += q.b1;
  sum.b2 += q.b2;
  sum.c += q.c;
}

inline double evaluate(const Quadric& q, const Vec3d& p) {
  const double x = p.x(), y = p.y(), z = p.z();
  return x * (q.a00 * x + 2 * (q.a01 * y + q.a02 * z + q.b0)) + y * (q.a11 * y + 2 * (q.a12 * z + q.b1)) +
         z * (q.a22 * z + 2 * q.b2) + q.c;
}

// Minimizes q over the segment [pa, pb], or over all of space when the 3x3 system is well conditioned and its
// solution lies within `reach` edge lengths of the midpoint. Ties on the segment go to an endpoint, so
// original samples (which lie on the original surface) survive where the quadric cannot tell positions apart.
inline Placement place_pair(const Quadric& q, const Vec3d& pa, const Vec3d& pb, double reach) {
  const Vec3d m = 0.5 * (pa + pb);
  const Vec3d g(q.a00 * m.x() + q.a01 * m.y() + q.a02 * m.z() + q.b0,
                q.a01 * m.x() + q.a11 * m.y() + q.a12 * m.z() + q.b1,
                q.a02 * m.x() + q.a12 * m.y() + q.a22 * m.z() + q.b2);
  const double q_m = m.dot(g) + q.b0 * m.x() + q.b1 * m.y() + q.b2 * m.z() + q.c;  // m.A.m + 2 b.m + c
  const Vec3d d = pb - pa;
  const double length2 = d.squaredNorm();

  // Adjugate of the symmetric A; det from the first row.
  const double c00 = q.a11 * q.a22 - q.a12 * q.a12;
  const double c01 = q.a02 * q.a12 - q.a01 * q.a22;
  const double c02 = q.a01 * q.a12 - q.a02 * q.a11;
  const double c11 = q.a00 * q.a22 - q.a02 * q.a02;
  const double c12 = q.a01 * q.a02 - q.a00 * q.a12;
  const double c22 = q.a00 * q.a11 - q.a01 * q.a01;
  const double det = q.a00 * c00 + q.a01 * c01 + q.a02 * c02;
  const double trace = q.a00 + q.a11 + q.a22;
  // det / trace^3 is 1/27 for an isotropic A and about lambda_min / (8 lambda_max) when one direction is
  // weak: below 1e-4 the minimizer moves a lot for a small change of the planes (a flat or cylindrical
  // region).
  if (trace > 0 && det > 1e-4 * trace * trace * trace) {
    const double s = -1.0 / det;
    const Vec3d y(s * (c00 * g.x() + c01 * g.y() + c02 * g.z()),
                  s * (c01 * g.x() + c11 * g.y() + c12 * g.z()),
                  s * (c02 * g.x() + c12 * g.y() + c22 * g.z()));
    if (y.squaredNorm() <= reach * reach * length2) {
      return {m + y,
              std::max(0.0, q_m + g.dot(y))};  // A y = -g, so Q(m + y) = q_m + 2 g.y + y.A.y = q_m + g.y
    }
  }
  // On the segment m + t d, t in [-1/2, 1/2]: f(t) = q_m + 2 t g.d + t^2 d.A.d, convex.
  const Vec3d ad(q.a00 * d.x() + q.a01 * d.y() + q.a02 * d.z(), q.a01 * d.x() + q.a11 * d.y() + q.a12 * d.z(),
                 q.a02 * d.x() + q.a12 * d.y() + q.a22 * d.z());
  const double curvature = d.dot(ad);
  const double slope = g.dot(d);
  const double f_a = q_m - slope + 0.25 * curvature;
  const double f_b = q_m + slope + 0.25 * curvature;
  Placement best = f_a <= f_b ? Placement{pa, f_a} : Placement{pb, f_b};
  if (curvature > 0) {
    const double t = -slope / curvature;
    if (t > -0.5 && t < 0.5) {
      const double f_t = q_m + t * slope;  // f at its stationary point: q_m + 2 t slope + t^2 curvature
      // Only leave the endpoint for a real gain: rounding must not move an original sample.
      if (f_t < best.error - 1e-9 * std::abs(best.error) - 1e-12 * trace * length2) best = {m + t * d, f_t};
    }
  }
  best.error = std::max(0.0, best.error);
  return best;
}

}  // namespace ocsimp::decimate_detail
