// Where a cluster of cells puts its vertex, and what that costs.
#pragma once

#include <cmath>

#include "cells.h"
#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/quadric.h"

namespace ocsimp::cluster_detail {

// The edge of an equilateral triangle of this area: a mesh's typical edge length from its mean triangle area.
inline double equilateral_edge(double area) {
  return std::sqrt(4.0 / std::sqrt(3.0) * area);
}

// What placement needs of a cluster; sums over its cells.
struct PlacementSums {
  Quadric quadric;  // the surface quadric plus the border planes
  Vec3d point_sum = Vec3d::Zero();
  double points = 0;
  Box3 box;  // union of the cells' boxes
  // The surface quadric's trace: the area of each triangle touching the cluster, once per corner in it; and
  // how many corners that is. Their ratio is the mean area of those triangles.
  double corner_area = 0;
  double corners = 0;

  void add(const PlacementSums& o) {
    quadric += o.quadric;
    point_sum += o.point_sum;
    points += o.points;
    box.add(o.box);
    corner_area += o.corner_area;
    corners += o.corners;
  }
  Vec3d mean() const { return points > 0 ? Vec3d(point_sum / points) : box.center(); }
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

// Where the quadric representative may go: the cluster's box grown on each side by the edge length of its
// triangles (at most the box's own size on that axis). The quadric sums the planes of triangles with a corner
// in the cluster, so it describes the surface no farther than that; beyond, its minimizer is an
// extrapolation of nearly parallel planes.
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
