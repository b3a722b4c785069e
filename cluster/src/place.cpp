#include "place.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>

namespace ocsimp::cluster_detail {
namespace {

// Eigenvalue, relative to the quadric's trace, below which a direction counts as unconstrained
// (ocsimp::minimize() takes the same tolerance relative to the largest eigenvalue).
constexpr double kTruncation = 1e-3;

// Offset y minimizing y^T M y + 2 g^T y along the directions M constrains: a pseudo-inverse whose cutoff at
// eigenvalue `tau` is smooth (Tikhonov damping, lambda / (lambda^2 + tau^2) in place of 1 / lambda). Away
// from the cutoff it is Lindstrom's truncated solve; near it, unlike a hard cutoff, it varies continuously
// with the quadric, so sums taken in another order (a shuffled input) cannot flip a direction in or out and
// move the vertex by a visible step. With M = V diag(lambda) V^T that is -M (M^2 + tau^2 I)^-1 g, a
// positive definite 3x3 solve: no eigenvectors needed (their decomposition was a sixth of an octree run's
// instructions).
Vec3d damped_step(const Eigen::Matrix3d& m, const Vec3d& g, double tau) {
  // In units of tau: n = m / tau, and the step is -(n^2 + I)^-1 n g / tau, with n^2 + I symmetric positive
  // definite, its determinant at least 1 (in the quadric's own units it could underflow for a tiny model)
  // and its condition number at most (lambda_max / tau)^2 + 1. Its adjugate solves it as accurately as a
  // factorization, in fewer operations.
  const Eigen::Matrix3d n = m * (1.0 / tau);
  const Eigen::Matrix3d s = n * n + Eigen::Matrix3d::Identity();
  const Vec3d r = n * g;
  const double c00 = s(1, 1) * s(2, 2) - s(1, 2) * s(1, 2), c01 = s(0, 2) * s(1, 2) - s(0, 1) * s(2, 2),
               c02 = s(0, 1) * s(1, 2) - s(0, 2) * s(1, 1), c11 = s(0, 0) * s(2, 2) - s(0, 2) * s(0, 2),
               c12 = s(0, 1) * s(0, 2) - s(0, 0) * s(1, 2), c22 = s(0, 0) * s(1, 1) - s(0, 1) * s(0, 1);
  const double det = s(0, 0) * c00 + s(0, 1) * c01 + s(0, 2) * c02;
  if (!(det > 0.0) || !std::isfinite(det)) return Vec3d::Zero();
  const double scale = -1.0 / (det * tau);
  return scale * Vec3d(c00 * r.x() + c01 * r.y() + c02 * r.z(), c01 * r.x() + c11 * r.y() + c12 * r.z(),
                       c02 * r.x() + c12 * r.y() + c22 * r.z());
}

// The scale the cutoff is relative to: the trace, the sum of the eigenvalues of a positive semi-definite
// quadric, between its largest eigenvalue and three times that. The largest eigenvalue itself took a cubic's
// roots, nearly all that a full decomposition costs.
double eigenvalue_scale(const Eigen::Matrix3d& a) {
  return std::abs(a.trace());
}

bool inside(const Vec3d& p, const Box3& box) {
  for (int a = 0; a < 3; ++a) {
    if (!(p[a] >= box.lo[a] && p[a] <= box.hi[a])) return false;
  }
  return true;
}

// Power-iteration steps for a cell's normal: the other eigenvectors' share of the start falls by (l2 / l1)^5,
// to 3 % where l2 = l1 / 2.
constexpr int kPowerSteps = 4;

// How fast a slot's crease plane fades once a border crosses the slot: the factor is 1 / (1 + k c), with c
// the squared length of the exact border normal (about 1 per crossing, exactly 0 where interior edges
// cancel). A switch scale, not a fitted value: any k from 1e2 to 1e8 does the same.
constexpr double kCrossingFade = 100.0;

// The unit eigenvector of the largest eigenvalue of a positive semi-definite a (zero if a is zero), by power
// iteration from a's column of largest diagonal: for the near rank-one quadric of a flat cell that column is
// already along the normal, and each step shrinks the rest by the ratio of the two largest eigenvalues. A
// tenth of what a full eigen-decomposition costs.
Vec3d dominant_direction(const Eigen::Matrix3d& a) {
  int j = 0;
  if (a(1, 1) > a(j, j)) j = 1;
  if (a(2, 2) > a(j, j)) j = 2;
  if (!(a(j, j) > 0.0) || !std::isfinite(a(j, j))) return Vec3d::Zero();
  const Eigen::Matrix3d unit = a * (1.0 / a(j, j));  // entries at most 1: the powers stay in range
  Vec3d v = unit.col(j);
  for (int step = 0; step < kPowerSteps; ++step) v = unit * v;
  const double length = v.norm();
  return length > 0.0 ? Vec3d(v / length) : Vec3d::Zero();
}

// Triangles around a vertex of a closed mesh, on average (Euler: E = 3V, F = 2V).
constexpr double kCornersPerVertex = 6.0;

}  // namespace

Vec3d minimize_damped(const Quadric& q, const Vec3d& origin) {
  const Eigen::Matrix3d a = q.a();
  const double tau = kTruncation * eigenvalue_scale(a);
  if (!(tau > 0.0) || !std::isfinite(tau)) return origin;
  return origin + damped_step(a, a * origin + q.b(), tau);
}

BorderQuadrics border_quadrics(const BorderSums& border, const Grid& grid, CellKey key,
                               const Quadric& surface, double weight, double carried_weight) {
  BorderQuadrics q;
  // The cell's dominant surface normal. What interior edges leave behind is exactly along their two
  // triangles' mean normal (for unit normals n1, n2 both perpendicular to the edge e, e x (n1 - n2) is
  // parallel to n1 + n2), so along the surface normal, be it curvature or scanner noise; a border's plane
  // normal lies in the surface. Only the part of a slot's normal along the surface counts.
  const Vec3d normal = dominant_direction(surface.a());
  if (!(normal.squaredNorm() > 0.0)) return q;
  const Vec3d origin = grid.cell_origin(key);
  // The plane n . (x - origin) / cell + w / |m| = 0 of slot sums (m, w) taken in the cell's frame.
  auto plane = [&](const Vec3d& m, double w, double length) {
    const Vec3d n = m / length;
    return std::pair<Vec3d, double>(n, grid.cell * w / length - n.dot(origin));
  };
  const double area = weight * grid.cell * grid.cell;
  for (int k = 0; k < 3; ++k) {
    const auto& x = border.exact[k];
    const auto& c = border.crease[k];
    // The exact border: interior edges cancelled, so this is the original's open border alone (none in
    // most slots, exactly).
    double length = 0;
    Vec3d m = Vec3d::Zero();
    if ((x[0] | x[1] | x[2]) != 0) {
      m = (Vec3d(x[0], x[1], x[2]) * (1.0 / kExactScale)).cross(normal);
      length = m.norm();
    }
    // What interior edges leave in the crease sums (creases, and noise), where no border crosses the slot.
    if ((c[0] | c[1] | c[2]) != 0) {
      const Vec3d mr = Vec3d(c[0], c[1], c[2]) * (1.0 / kCreaseScale);
      const double lr = mr.norm();
      const auto [n, d] = plane(mr, c[3] * (1.0 / kCreaseScale), lr);
      const double along = (mr - mr.dot(normal) * normal).squaredNorm();
      const double fade = length > 0 ? 1.0 / (1.0 + kCrossingFade * length * length) : 1.0;
      q.placement += Quadric::plane(n, d, area * along * fade);
    }
    if (!(length > 0.0)) continue;
    const Vec3d sw = Vec3d(x[3], x[4], x[5]) * (1.0 / kExactScale);
    const auto [n, d] = plane(m, -normal.dot(sw), length);
    q.placement += Quadric::plane(n, d, area * length * length);
    if (carried_weight > 0)
      q.carried += Quadric::plane(n, d, carried_weight * length * length * grid.cell * grid.cell);
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
  s.corner_area = surface.trace();
  // Soups count corners as points; an indexed input counts vertices, each the corner of about six triangles.
  s.corners = cells.input_vertices > 0 ? kCornersPerVertex * s.points : s.points;
  s.point_sum =
      s.points * cells.grid.cell_origin(key) + cells.grid.cell * cells.point_sum[cell].cast<double>();
  const Box3 cell_box = cells.grid.cell_box(key);
  s.box = Box3f::around(cell_box);
  Box3 point_box = cell_box;
  // Every touched cell has a point; the cell's box stands in should one have none.
  if (!box_empty(cells.point_box[cell])) {
    const PointBox& b = cells.point_box[cell];
    const double bin = cells.grid.cell / kPointBoxBins;
    for (int a = 0; a < 3; ++a) {
      point_box.lo[a] = cell_box.lo[a] + bin * (255 - b[a]);
      point_box.hi[a] = cell_box.lo[a] + bin * (b[a + 3] + 1);
    }
  }
  s.point_box = Box3f::around(point_box);
  return s;
}

Vec3d minimize_in_box(const Quadric& q, const Box3& box, const Vec3d& start) {
  const Eigen::Matrix3d a = q.a();
  const double floor = kTruncation * eigenvalue_scale(a);
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
  Box3 reach = sums.point_box.to_double();
  const Vec3d size = sums.box.to_double().extent();
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
      point = minimize_in_box(sums.quadric, sums.box.to_double(), mean);
      break;
  }
  return {point, std::max(0.0, sums.quadric.evaluate(point))};
}

}  // namespace ocsimp::cluster_detail
