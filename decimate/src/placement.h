// Where a collapsed pair goes and what it costs: the quadric's minimizer from an explicit 3x3 solve around
// the edge midpoint when the system is well conditioned, else the best point of the edge segment moved
// toward the minimizer by a regularized step.
#pragma once

#include <algorithm>
#include <cmath>

#include "ocsimp/core/quadric.h"

namespace ocsimp::decimate_detail {

struct Placement {
  Vec3d point;   // relative to the decimator's local origin, like the quadric
  double error;  // Q(point), clamped at 0
};

// `q`: a Quadric, or any record with the same ten coefficients (such as a face's plane term).
template <class Coefficients>
inline void add_to(Quadric& sum, const Coefficients& q) {
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

// A quadric's ten coefficients without Quadric's zero initializers, for records written in full before they
// are read: a face's plane in the array that a parallel loop fills (zeroing it first cost a serial pass and
// its page faults), and a pair's sum in every re-cost (the compiler kept the zeros as dead stores).
struct RawQuadric {
  double a00, a01, a02, a11, a12, a22, b0, b1, b2, c;
};

inline void add_pair(RawQuadric& sum, const Quadric& a, const Quadric& b) {
  sum.a00 = a.a00 + b.a00;
  sum.a01 = a.a01 + b.a01;
  sum.a02 = a.a02 + b.a02;
  sum.a11 = a.a11 + b.a11;
  sum.a12 = a.a12 + b.a12;
  sum.a22 = a.a22 + b.a22;
  sum.b0 = a.b0 + b.b0;
  sum.b1 = a.b1 + b.b1;
  sum.b2 = a.b2 + b.b2;
  sum.c = a.c + b.c;
}

template <class Coefficients>
inline double evaluate(const Coefficients& q, const Vec3d& p) {
  const double x = p.x(), y = p.y(), z = p.z();
  return x * (q.a00 * x + 2 * (q.a01 * y + q.a02 * z + q.b0)) + y * (q.a11 * y + 2 * (q.a12 * z + q.b1)) +
         z * (q.a22 * z + 2 * q.b2) + q.c;
}

// Ridge of the step taken where A is poorly conditioned (see place_pair), relative to trace(A). At 1e-3 a
// bumpy open square decimated to 7 faces stopped at 6, its last one-face collapses blocked; at 1e-5 and
// below the step went far enough along weak directions to turn a face against the original surface (bunny
// at 1 %). Between the two, RMS and Hausdorff distances on the shared meshes changed within noise.
constexpr double kRidge = 1e-4;

// Minimizes q over all of space when the 3x3 system is well conditioned and its solution lies within `reach`
// edge lengths of the midpoint. Otherwise it takes the best point s of the segment [pa, pb] and then a
// regularized Newton step from s toward the minimizer, (A + tau I) y = -gradient(s) with tau = kRidge *
// trace(A), kept when it stays within reach and lowers the error for real. Along the directions A
// constrains the step lands near the minimizer; along those it hardly constrains (flat and cylindrical
// regions) it barely moves, so the point stays where the segment put it. Ties keep an endpoint, so original
// samples (which lie on the original surface) survive where the quadric cannot tell positions apart.
//
// On scans about 85 % of the placements are poorly conditioned. With the segment alone there, the RMS
// distance was about a fifth higher (bunny, horse and igea at 10, 3, 1 and 0.5 %, geometric mean; bunny at
// 10 %: 0.0321 % of the diagonal against 0.0250 %), at the same Hausdorff distance within noise. A step
// anchored at the midpoint, as Lindstrom's truncated solve is, moved vertices along free directions to
// midpoints: on a fan around one edge its end climbed the spine until every collapse was blocked.
//
// Always inlined: called out of line, the summed quadric went through memory and the call cost about 5 % of
// a 70 k-triangle decimation's instructions.
[[gnu::always_inline]] inline Placement place_pair(const RawQuadric& q, const Vec3d& pa, const Vec3d& pb,
                                                   double reach) {
  // Scalar code throughout: this runs for every candidate at setup and about seven times per collapse, and
  // Eigen's small temporaries cost about a third more instructions here.
  const double mx = 0.5 * (pa.x() + pb.x()), my = 0.5 * (pa.y() + pb.y()), mz = 0.5 * (pa.z() + pb.z());
  const double gx = q.a00 * mx + q.a01 * my + q.a02 * mz + q.b0;
  const double gy = q.a01 * mx + q.a11 * my + q.a12 * mz + q.b1;
  const double gz = q.a02 * mx + q.a12 * my + q.a22 * mz + q.b2;
  const double q_m = mx * (gx + q.b0) + my * (gy + q.b1) + mz * (gz + q.b2) + q.c;  // m.A.m + 2 b.m + c
  const double dx = pb.x() - pa.x(), dy = pb.y() - pa.y(), dz = pb.z() - pa.z();
  const double length2 = dx * dx + dy * dy + dz * dz;
  const double reach2 = reach * reach * length2;

  // Adjugate of the symmetric A; det from the first row.
  const double c00 = q.a11 * q.a22 - q.a12 * q.a12;
  const double c01 = q.a02 * q.a12 - q.a01 * q.a22;
  const double c02 = q.a01 * q.a12 - q.a02 * q.a11;
  const double det = q.a00 * c00 + q.a01 * c01 + q.a02 * c02;
  const double trace = q.a00 + q.a11 + q.a22;
  // det / trace^3 is 1/27 for an isotropic A and about lambda_min / (8 lambda_max) when one direction is
  // weak: below 1e-4 the minimizer moves a lot for a small change of the planes (a flat or cylindrical
  // region).
  if (trace > 0 && det > 1e-4 * trace * trace * trace) {
    const double c11 = q.a00 * q.a22 - q.a02 * q.a02;
    const double c12 = q.a01 * q.a02 - q.a00 * q.a12;
    const double c22 = q.a00 * q.a11 - q.a01 * q.a01;
    const double s = -1.0 / det;
    const double yx = s * (c00 * gx + c01 * gy + c02 * gz);
    const double yy = s * (c01 * gx + c11 * gy + c12 * gz);
    const double yz = s * (c02 * gx + c12 * gy + c22 * gz);
    if (yx * yx + yy * yy + yz * yz <= reach2) {
      // A y = -g, so Q(m + y) = q_m + 2 g.y + y.A.y = q_m + g.y
      return {Vec3d(mx + yx, my + yy, mz + yz), std::max(0.0, q_m + (gx * yx + gy * yy + gz * yz))};
    }
  }
  // Gains below this are rounding: they must not move an original sample.
  auto real_gain = [&](double from, double to) {
    return to < from - 1e-9 * std::abs(from) - 1e-12 * trace * length2;
  };

  // On the segment m + t d, t in [-1/2, 1/2]: f(t) = q_m + 2 t g.d + t^2 d.A.d, convex.
  const double adx = q.a00 * dx + q.a01 * dy + q.a02 * dz;
  const double ady = q.a01 * dx + q.a11 * dy + q.a12 * dz;
  const double adz = q.a02 * dx + q.a12 * dy + q.a22 * dz;
  const double curvature = dx * adx + dy * ady + dz * adz;
  const double slope = gx * dx + gy * dy + gz * dz;
  const double f_a = q_m - slope + 0.25 * curvature;
  const double f_b = q_m + slope + 0.25 * curvature;
  double t = f_a <= f_b ? -0.5 : 0.5;
  double error = std::min(f_a, f_b);
  if (curvature > 0) {
    const double stationary = -slope / curvature;
    // f at its stationary point: q_m + 2 t slope + t^2 curvature.
    const double f_t = q_m + stationary * slope;
    if (stationary > -0.5 && stationary < 0.5 && real_gain(error, f_t)) {
      t = stationary;
      error = f_t;
    }
  }
  Placement best{t == -0.5 ? pa : t == 0.5 ? pb : Vec3d(mx + t * dx, my + t * dy, mz + t * dz), error};

  // The step from s = m + t d, where the gradient is h = g + t A d: adjugate and determinant of A + tau I
  // (A with tau added to its diagonal).
  if (trace > 0) {
    const double tau = kRidge * trace;
    const double b00 = q.a00 + tau, b11 = q.a11 + tau, b22 = q.a22 + tau;
    const double r00 = b11 * b22 - q.a12 * q.a12;
    const double r01 = q.a02 * q.a12 - q.a01 * b22;
    const double r02 = q.a01 * q.a12 - q.a02 * b11;
    const double r11 = b00 * b22 - q.a02 * q.a02;
    const double r12 = q.a01 * q.a02 - b00 * q.a12;
    const double r22 = b00 * b11 - q.a01 * q.a01;
    const double ridge_det = b00 * r00 + q.a01 * r01 + q.a02 * r02;  // > 0: A + tau I is positive definite
    const double hx = gx + t * adx, hy = gy + t * ady, hz = gz + t * adz;
    const double s = -1.0 / ridge_det;
    const double yx = s * (r00 * hx + r01 * hy + r02 * hz);
    const double yy = s * (r01 * hx + r11 * hy + r12 * hz);
    const double yz = s * (r02 * hx + r12 * hy + r22 * hz);
    const double y2 = yx * yx + yy * yy + yz * yz;
    if (y2 <= reach2) {
      // Q(s + y) = Q(s) + 2 h.y + y.A.y, and A y = -h - tau y makes y.A.y = -h.y - tau |y|^2.
      const double f_y = error + (hx * yx + hy * yy + hz * yz) - tau * y2;
      if (real_gain(error, f_y)) {
        best = {Vec3d(best.point.x() + yx, best.point.y() + yy, best.point.z() + yz), f_y};
      }
    }
  }
  best.error = std::max(0.0, best.error);
  return best;
}

}  // namespace ocsimp::decimate_detail
