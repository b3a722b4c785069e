// Where a cluster of cells puts its vertex, and what that costs.
#pragma once

#include <cmath>
#include <limits>

#include "cells.h"
#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/quadric.h"

namespace ocsimp::cluster_detail {

// The edge of an equilateral triangle of this area: a mesh's typical edge length from its mean triangle area.
inline double equilateral_edge(double area) {
  return std::sqrt(4.0 / std::sqrt(3.0) * area);
}

// A box in floats, rounded outward from doubles: half the bytes of a Box3, for the octree's array of clusters
// (about a third of its memory). Vertices are floats in the end, so a float's rounding is no coarser than the
// output's.
struct Box3f {
  Vec3f lo = Vec3f::Constant(std::numeric_limits<float>::infinity());
  Vec3f hi = Vec3f::Constant(-std::numeric_limits<float>::infinity());

  static Box3f around(const Box3& b) {
    Box3f f;
    for (int a = 0; a < 3; ++a) {
      f.lo[a] = static_cast<float>(b.lo[a]);
      if (static_cast<double>(f.lo[a]) > b.lo[a]) f.lo[a] = std::nextafter(f.lo[a], -HUGE_VALF);
      f.hi[a] = static_cast<float>(b.hi[a]);
      if (static_cast<double>(f.hi[a]) < b.hi[a]) f.hi[a] = std::nextafter(f.hi[a], HUGE_VALF);
    }
    return f;
  }
  void add(const Box3f& o) {
    lo = lo.cwiseMin(o.lo);
    hi = hi.cwiseMax(o.hi);
  }
  Box3 to_double() const {
    Box3 b;
    b.lo = lo.cast<double>();
    b.hi = hi.cast<double>();
    return b;
  }
};

// What placement needs of a cluster; sums over its cells.
struct PlacementSums {
  Quadric quadric;  // the surface quadric plus the border planes
  Vec3d point_sum = Vec3d::Zero();
  double points = 0;
  Box3f box;        // union of the cells' boxes
  Box3f point_box;  // union of the boxes of the cells' points (PointBox)
  // The surface quadric's trace: the area of each triangle touching the cluster, once per corner in it; and
  // how many corners that is. Their ratio is the mean area of those triangles.
  double corner_area = 0;
  double corners = 0;

  void add(const PlacementSums& o) {
    quadric += o.quadric;
    point_sum += o.point_sum;
    points += o.points;
    box.add(o.box);
    point_box.add(o.point_box);
    corner_area += o.corner_area;
    corners += o.corners;
  }
  Vec3d mean() const { return points > 0 ? Vec3d(point_sum / points) : box.to_double().center(); }
  // The edge of a triangle of the mean area: how far past the cluster's cells the triangles whose planes
  // make up its quadric reach.
  double edge_length() const { return corners > 0 ? equilateral_edge(corner_area / corners) : 0; }
};

// The border planes of a cell as quadrics (see BorderSums), for placing the cell's vertex, times `weight`: in
// each slot the exact border plane, weighted by cell_size^2 x the squared length of its normal, and the
// crease plane of the crease sums, weighted by cell_size^2 x the squared length of its normal's component
// along the surface and faded where a border crosses the slot (`surface`: the cell's quadric, whose dominant
// eigenvector is taken as the surface normal). With `carried_weight` > 0 also the planes the output quadric
// carries into a decimator: the exact border planes alone, weighted as above but by `carried_weight`.
struct BorderQuadrics {
  Quadric placement;
  Quadric carried;
};
BorderQuadrics border_quadrics(const BorderSums& border, const Grid& grid, CellKey key,
                               const Quadric& surface, double weight, double carried_weight = 0);

// A cell's placement sums; with `carried` (and `carried_weight` > 0), also its carried border planes.
PlacementSums cell_placement_sums(const FineCells& cells, std::size_t cell, double boundary_weight,
                                  double carried_weight = 0, Quadric* carried = nullptr);

// Where the quadric representative may go: the box of the cluster's points grown on each side by the edge
// length of its triangles (at most the cells' box's size on that axis). The quadric sums the planes of
// triangles with a corner in the cluster, so it describes the surface no farther than that; beyond, its
// minimizer is an extrapolation: of nearly parallel planes, or of the tangent planes of a tip, which cross
// above it (spot.obj's horns at 10 %, where the cells' box let the vertex stand 0.8 cells off the surface). A
// sharp corner or edge is a point of the input, so it lies inside. On the shared meshes, against the cells'
// box: Hausdorff distance 4 % lower and RMS 0.5 % lower (geometric means over 24 cases), with no change
// beyond 1 % RMS in any; grown by less than an edge, it cut into convex bulges (RMS up to 4 % higher).
Box3 quadric_reach(const PlacementSums& sums);

struct Placement {
  Vec3d point;
  double error;  // the placement quadric at `point`, clamped to >= 0
};
Placement place(const PlacementSums& sums, Representative representative);

// The minimizer of q nearest `origin` along the directions q leaves free: a pseudo-inverse solve with a
// smooth cutoff at 1e-3 of q's trace (see place.cpp).
Vec3d minimize_damped(const Quadric& q, const Vec3d& origin);

// The minimizer of q over `box`: the best of the unconstrained solve and the solves restricted to each face,
// edge and corner of the box (each a damped solve around `start` clamped into the box).
Vec3d minimize_in_box(const Quadric& q, const Box3& box, const Vec3d& start);

}  // namespace ocsimp::cluster_detail
