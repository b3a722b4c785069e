#include "place.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

namespace ocsimp::cluster_detail {
namespace {

// Relative eigenvalue scale below which a direction counts as unconstrained (as in ocsimp::minimize()).
constexpr double kTruncation = 1e-3;

// Offset y minimizing y^T M y + 2 g^T y along the directions M constrains: a pseudo-inverse whose cutoff at
// eigenvalue `tau` is smooth (Tikhonov damping, lambda / (lambda^2 + tau^2) in place of 1 / lambda). Away
// from the cutoff it is Lindstrom's truncated solve; near it, unlike a hard cutoff, it varies continuously
// with the quadric, so sums taken in another order (a shuffled input) cannot flip a direction in or out and
// move the vertex by a visible step.
Vec3d damped_step(const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>& solver, const Vec3d& g, double tau) {
  const Vec3d values = solver.eigenvalues();
  const Eigen::Matrix3d vectors = solver.eigenvectors();
  Vec3d step = Vec3d::Zero();
  for (int i = 0; i < 3; ++i) {
    const double l = values(i);
    if (!(l > 0.0)) continue;
    const Vec3d v = vectors.col(i);
    step -= v * (v.dot(g) * l / (l * l + tau * tau));
  }
  return step;
}
Vec3d damped_step(const Eigen::Matrix3d& m, const Vec3d& g, double tau) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(m);
  return damped_step(solver, g, tau);
}

double largest_eigenvalue(const Eigen::Matrix3d& a) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(a, Eigen::EigenvaluesOnly);
  return solver.eigenvalues().cwiseAbs().maxCoeff();
}

bool inside(const Vec3d& p, const Box3& box) {
  for (int a = 0; a < 3; ++a) {
    if (!(p[a] >= box.lo[a] && p[a] <= box.hi[a])) return false;
  }
  return true;
}

// The power of a border slot's along-surface fraction that its carried plane is weighted by. The carried
// planes are to be the original's borders alone. The sums also hold what creases leave (interior edges whose
// two planes do not cancel), which placing a cluster's vertex wants, but the decimator's face quadrics
// already hold both sides of a crease, and the pure decimator adds no crease planes of its own. A border's
// summed normal lies in the surface, a crease's along its normal, so the fraction along the surface tells
// them apart; a high power of it is a switch without a threshold to flip. Measured two-stage RMS over pure
// decimation's at 0.1 % (horse, rocker-arm, bunny): 1.109, 1.163, 0.953 with crease planes carried; power 4:
// 0.994, 1.162, 0.951; 8: 1.022, 0.926, 0.908; 16: 0.968, 1.150, 0.941 (rocker-arm at 20 faces swings with
// any change); at 1 % about 1 % better (horse, bunny) and 6 % (rocker-arm).
constexpr double kCarriedTangentPower = 8.0;

// Triangles around a vertex of a closed mesh, on average (Euler: E = 3V, F = 2V).
constexpr double kCornersPerVertex = 6.0;

}  // namespace

Vec3d minimize_damped(const Quadric& q, const Vec3d& origin) {
  const Eigen::Matrix3d a = q.a();
  // One decomposition serves the cutoff and the step: the octree places a cluster per candidate merge.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(a);
  const double tau = kTruncation * solver.eigenvalues().cwiseAbs().maxCoeff();
  if (!(tau > 0.0) || !std::isfinite(tau)) return origin;
  return origin + damped_step(solver, a * origin + q.b(), tau);
}

BorderQuadrics border_quadrics(const BorderSums& border, const Grid& grid, CellKey key,
                               const Quadric& surface, double weight, double carried_weight) {
  BorderQuadrics q;
  // The cell's dominant surface normal. What interior edges leave behind is exactly along their two
  // triangles' mean normal (for unit normals n1, n2 both perpendicular to the edge e, e x (n1 - n2) is
  // parallel to n1 + n2), so along the surface normal, be it curvature or scanner noise; a border's plane
  // normal lies in the surface. Only the part of a slot's normal along the surface counts.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(surface.a());
  if (!(solver.eigenvalues()(2) > 0.0)) return q;
  const Vec3d normal = solver.eigenvectors().col(2);
  const Vec3d origin = grid.cell_origin(key);
  for (const auto& s : border.slot) {
    const Vec3d m(s[0], s[1], s[2]);
    const double length = m.norm();
    if (!(length > 0.0)) continue;
    const Vec3d n = m / length;
    const double along_surface = (m - m.dot(normal) * normal).squaredNorm();
    // n . (x - origin) / cell + w / length = 0, in world units. The weight grows with the square of what is
    // left: one border crossing leaves 1, the cancellation of interior edges ~1e-6 of float residue. No
    // threshold, so nothing flips when sums are taken in another order.
    const double d = grid.cell * s[3] / length - n.dot(origin);
    q.placement += Quadric::plane(n, d, weight * along_surface * grid.cell * grid.cell);
    if (carried_weight > 0) {
      const double tangent = std::pow(along_surface / (length * length), kCarriedTangentPower);
      q.carried += Quadric::plane(n, d, carried_weight * along_surface * tangent * grid.cell * grid.cell);
    }
  }
  return q;
}

PlacementSums cell_placement_sums(const FineCells& cells, std::size_t cell, double boundary_weight,
                                  double carried_weight, Quadric* carried) {
  PlacementSums s;
  const CellKey key = cells.keys[cell];
  s.quadric = cells.quadrics[cell];
  if (cells.has_border()) {
    const BorderQuadrics border = border_quadrics(cells.border[cell], cells.grid, key, cells.quadrics[cell],
                                                  boundary_weight, carried ? carried_weight : 0.0);
    s.quadric += border.placement;
    if (carried) *carried = border.carried;
  }
  s.points = cells.points[cell];
  const Quadric& surface = cells.quadrics[cell];
  s.corner_area = surface.a00 + surface.a11 + surface.a22;
  // Soups count corners as points; an indexed input counts vertices, each the corner of about six triangles.
  s.corners = cells.input_vertices > 0 ? kCornersPerVertex * s.points : s.points;
  s.point_sum =
      s.points * cells.grid.cell_origin(key) + cells.grid.cell * cells.point_sum[cell].cast<double>();
  s.box = cells.grid.cell_box(key);
  return s;
}

Vec3d minimize_in_box(const Quadric& q, const Box3& box, const Vec3d& start) {
  const Eigen::Matrix3d a = q.a();
  const double floor = kTruncation * largest_eigenvalue(a);
  const Vec3d inside = start.cwiseMax(box.lo).cwiseMin(box.hi);
  if (!(floor > 0.0) || !std::isfinite(floor)) return inside;
  const Vec3d slack = 1e-9 * (box.extent() + Vec3d::Constant(1e-300));
  Vec3d best = inside;
  double best_value = std::numeric_limits<double>::infinity();
  // Each axis free (0), at its low side (1) or at its high side (2): 27 sub-problems, the unconstrained
  // one first; it usually lands inside and ends the search.
  for (int code = 0; code < 27; ++code) {
    int mode[3] = {code % 3, (code / 3) % 3, code / 9};
    Vec3d x = inside;
    Eigen::Matrix3d m = a;
    for (int k = 0; k < 3; ++k) {
      if (mode[k] == 0) continue;
      x[k] = mode[k] == 1 ? box.lo[k] : box.hi[k];
      m.row(k).setZero();
      m.col(k).setZero();
    }
    Vec3d g = a * x + q.b();
    for (int k = 0; k < 3; ++k)
      if (mode[k] != 0) g[k] = 0;
    x += damped_step(m, g, floor);
    bool feasible = true;
    for (int k = 0; k < 3 && feasible; ++k) {
      if (mode[k] == 0) feasible = x[k] >= box.lo[k] - slack[k] && x[k] <= box.hi[k] + slack[k];
    }
    if (!feasible) continue;
    x = x.cwiseMax(box.lo).cwiseMin(box.hi);
    const double value = q.evaluate(x);
    if (value < best_value) {
      best_value = value;
      best = x;
    }
    if (code == 0) break;  // the unconstrained minimizer is inside: nothing on the boundary is lower
  }
  return best;
}

Box3 quadric_reach(const PlacementSums& sums) {
  Box3 reach = sums.box;
  const Vec3d size = sums.box.extent();
  const double edge = sums.edge_length();
  for (int a = 0; a < 3; ++a) {
    const double margin = std::min(edge, size[a]);
    reach.lo[a] -= margin;
    reach.hi[a] += margin;
  }
  return reach;
}

Placement place(const PlacementSums& sums, Representative representative) {
  const Vec3d mean = sums.mean();
  Vec3d point = mean;
  switch (representative) {
    case Representative::mean:
      break;
    case Representative::quadric: {
      point = minimize_damped(sums.quadric, mean);
      const Box3 reach = quadric_reach(sums);
      if (!point.allFinite() || !inside(point, reach)) point = minimize_in_box(sums.quadric, reach, mean);
      break;
    }
    case Representative::constrained:
      point = minimize_in_box(sums.quadric, sums.box, mean);
      break;
  }
  return {point, std::max(0.0, sums.quadric.evaluate(point))};
}

}  // namespace ocsimp::cluster_detail
