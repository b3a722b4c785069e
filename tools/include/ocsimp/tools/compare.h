// How far apart two triangle surfaces are, measured the way Metro does (Cignoni, Rocchini & Scopigno 1998):
// sample one surface uniformly by area, find each sample's exact closest point on the other surface, and
// summarize the distances. `ocsimp compare` prints what measure_distance() returns.
//
// Definitions (one-sided, from surface X to surface Y; d(p) = distance from p to the closest point of Y):
//   hausdorff = max d(p) over all of X: the largest over the area samples and the vertices of X, refined by
//               branch and bound over X's triangles until the true maximum lies within 0.01 % above it
//               (`hausdorff_bound` says where it ended, should its query budget, an eighth of the queries
//               the samples took but from 2^16 to 2^19, run out first). Samples alone fall short where a
//               large triangle bridges a gap away from its vertices. Refinement starts from the vertices:
//               without them (include_vertices off) hausdorff is the area samples' largest alone;
//   mean      = average d(p) over the area samples;
//   rms       = sqrt(average d(p)^2) over the area samples.
// Vertices only feed the maximum: they are not spread by area, so counting them in the averages would weight
// finely tessellated regions more (a 10 M-triangle scan has 5 M vertices against 1 M area samples).
// A surface of zero total area (every triangle degenerate), or one sampled with samples = 0, is measured at
// its vertices alone: the averages are then over its vertices.
// Symmetric figures combine the two directions:
//   hausdorff = max(forward, backward), mean = (forward + backward) / 2,
//   rms = sqrt((forward_rms^2 + backward_rms^2) / 2)   (the definition /work/shared/BASELINES.md uses).
//
// Sampling is stratified along the cumulative triangle area: sample i of N lands at area position
// (i + u_i) / N of the total, u_i uniform in [0, 1), then uniformly inside the triangle found there. Every
// random number is a hash of (seed, sample index), work is cut into fixed chunks of samples and merged in
// chunk order, and each closest-point search returns the exact minimum over all triangles, so the same inputs
// and seed give bit-identical numbers for any thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"
#include "ocsimp/core/types.h"

namespace ocsimp {

// The point of triangle (a, b, c) nearest to p. Exact up to rounding for proper triangles; a triangle whose
// corner angle has sine below 1e-6 (a sliver, a segment or a point) is treated as its three edges, which
// moves the answer by at most that sliver's width.
Vec3d closest_point_on_triangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c);

struct ClosestPoint {
  Vec3d point = Vec3d::Zero();
  double distance_squared = std::numeric_limits<double>::infinity();
  Index triangle = std::numeric_limits<Index>::max();  // of the mesh the index was built over
};

// A bounding-volume hierarchy over one mesh's triangles (an Embree 3 BVH, queried with rtcPointQuery and an
// exact closest-point-on-triangle callback), plus the cumulative areas its samples are drawn from. Build it
// once and measure it against many other meshes. It copies what it needs, so the mesh may go away.
// Queries are thread-safe; the index is movable, not copyable.
class DistanceIndex {
 public:
  // `name` labels errors (usually the file the mesh came from). Throws Error when the mesh has no triangles,
  // a triangle refers to a vertex that does not exist, or a position or the origin is not finite.
  explicit DistanceIndex(const IndexedMesh& mesh, std::string name = {});
  DistanceIndex(DistanceIndex&&) noexcept;
  DistanceIndex& operator=(DistanceIndex&&) noexcept;
  ~DistanceIndex();

  // The exact closest point of the surface to p, searched within `upper_bound` of p: pass the distance to any
  // point known to lie on the surface to prune the search (the answer is the same). When nothing lies within
  // the bound, returns a ClosestPoint whose distance_squared is infinite. Throws Error for a point that is
  // not finite, or so far from the mesh (about 1e18 of its sizes) that the float index cannot hold it.
  ClosestPoint closest_point(const Vec3d& p,
                             double upper_bound = std::numeric_limits<double>::infinity()) const;

  // `count` points spread uniformly by area over the surface (stratified, see the top of this file), in the
  // order measure_one_sided() visits them. Empty when the surface has no area.
  std::vector<Vec3d> sample_surface(std::size_t count, std::uint64_t seed) const;

  const std::string& name() const;
  std::size_t triangle_count() const;
  std::size_t referenced_vertex_count() const;  // vertices that some triangle uses: the vertex samples
  double area() const;
  Box3 bounds() const;  // of the positions some triangle uses (every one when none does), about origin()
  // The index's origin, the mesh's or a point near its centre when it lies far from zero for its size:
  // positions, samples and bounds are relative to it. Meshes with different origins are
  // measured in a common frame (each sample moved by the difference of the two origins, in double).
  Vec3d origin() const;

  struct Impl;  // defined in tools/src/compare_index.h, for the implementation only
  const Impl& impl() const { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

struct CompareOptions {
  std::size_t samples = 1'000'000;  // area samples per direction
  std::uint64_t seed = 1;
  // Also measure every referenced vertex, and refine the Hausdorff distance from them (see above).
  bool include_vertices = true;
  // Phases "index original", "index simplified" (done/total in triangles, reported at the end of the build),
  // then "forward" and "backward" in samples.
  ProgressFn progress;
};

struct OneSidedDistance {
  double hausdorff = 0;
  double mean = 0;
  double rms = 0;
  std::size_t samples = 0;         // area samples taken
  std::size_t vertex_samples = 0;  // vertices taken (Hausdorff only)
  // The point where the Hausdorff distance is reached (the first, on ties), in the file's coordinates (with
  // the origin added).
  Vec3d farthest = Vec3d::Zero();
  // An upper bound of the true Hausdorff distance, within 0.01 % of `hausdorff` when its refinement ran to
  // the end (see the top of this file); infinite when vertices were not measured, so nothing was refined.
  double hausdorff_bound = std::numeric_limits<double>::infinity();
  bool hausdorff_settled = false;  // the refinement ran to the end: hausdorff_bound is within the tolerance
};

struct SurfaceDistance {
  OneSidedDistance forward;                 // samples on the original, distances to the simplified surface
  OneSidedDistance backward;                // samples on the simplified surface, distances to the original
  double hausdorff = 0, mean = 0, rms = 0;  // symmetric, as defined at the top of this file
  double diagonal = 0;                      // of the original's bounding box (DistanceIndex::bounds)

  // Both directions' refinements settled: `hausdorff` is within the tolerance of the true one, not a lower
  // bound.
  bool hausdorff_settled() const { return forward.hausdorff_settled && backward.hausdorff_settled; }

  // `distance` as a percentage of the diagonal; NaN when the diagonal is 0 (the original is a point: there is
  // no share to take, and 0 read as a perfect match). JSON writes it as null.
  double percent(double distance) const {
    return diagonal > 0 ? 100.0 * distance / diagonal : std::numeric_limits<double>::quiet_NaN();
  }
};

// Distances from the surface of `from` to the surface of `to`. Throws Error when there is nothing to sample
// (options.samples == 0 and !options.include_vertices). `phase` names the progress phase.
OneSidedDistance measure_one_sided(const DistanceIndex& from, const DistanceIndex& to,
                                   const CompareOptions& options, const std::string& phase = "forward");

// Both directions and the symmetric figures.
SurfaceDistance measure_distance(const DistanceIndex& original, const DistanceIndex& simplified,
                                 const CompareOptions& options = {});
// Same, building both indices (errors name the meshes "original" and "simplified").
SurfaceDistance measure_distance(const IndexedMesh& original, const IndexedMesh& simplified,
                                 const CompareOptions& options = {});

// The symmetric figures from two one-sided ones.
SurfaceDistance combine_distances(const OneSidedDistance& forward, const OneSidedDistance& backward,
                                  double diagonal);

}  // namespace ocsimp
