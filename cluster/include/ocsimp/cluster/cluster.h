// Streaming vertex clustering: one sequential pass over a TriangleStream of any size, memory bounded by the
// number of occupied cells (the output), never by the input.
//
// Every input vertex falls in a cell of a grid laid over the bounding box. Each cell sums the area-weighted
// plane quadrics of the triangles touching it (once per corner, like face_quadrics_per_vertex()) and becomes
// one output vertex. A triangle whose corners fall in three distinct cells survives, re-indexed; one that
// collapses, or repeats the same three cells, is dropped. Normals, colors and texture coordinates are
// averaged per cell when the input has them.
//
// Two ways of laying the cells:
//  - a uniform grid (`grid` cells along the longest axis, or cubes of `cell_size`), or, with `target_faces`,
//    a resolution chosen by re-clustering a fine grid's cells (never by another pass over the input);
//  - an adaptive octree: a fine power-of-two grid whose sibling cells are merged bottom-up, one pair at a
//    time, least increase of quadric error first (clusters no input triangle joins pay 64x), until
//    `target_vertices` (exactly) or `target_faces` (the largest count not above it) is met. A cluster whose
//    triangles have all collapsed would be a vertex of no face: it joins a neighbouring cluster instead, and
//    the vertex target counts only vertices with faces.
//
// Determinism: the output is the same bytes for any thread count. The cells are split among owners (runs of
// the Morton-ordered cells); each batch of triangles is listed for the owners of their corners' cells, and
// each owner adds its triangles in input order, so every cell's sums run in input order whatever the thread
// count (a triangle spanning two owners has its quadric computed by both, identically). Cells, and so
// output vertices, are numbered in Morton order of their grid coordinates, and triangles are sorted, so
// shuffling the input's triangles changes the output only by the rounding of sums taken in another order.
// Sums are gathered chunk by chunk within each batch the stream delivers, so a stream that cuts its batches
// elsewhere (another ReadOptions::batch_capacity, a TriangleStream of one's own) changes that rounding too
// (bunny: the last bits of half the quadrics), not the triangles; the readers' cuts depend on the file
// alone.
//
// Memory (indexed inputs): the reader's 12 bytes a vertex, which the pass reuses in place to hold each
// vertex's cell and its position inside the cell (see TriangleStream::scratch_vertices()) and releases once
// the stream is exhausted, plus per occupied cell during the pass its quadric and crease sums (104 bytes),
// its key and its share of the surviving triangles (the exact border sums are kept only where they do not
// cancel, which is along the open borders), and 16 more after it (the vertex sums, gathered only once the
// vertex array is being released). On the 100 M-triangle benchmark the peak is 15.4 bytes per input vertex
// all told: 12 per vertex and about 170 per occupied cell. The octree and `target_faces` modes hold
// `fine_cells_per_target` times more cells than they output while they merge.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"
#include "ocsimp/streaming/triangle_stream.h"

namespace ocsimp {

// Where a cell puts its vertex.
enum class Representative {
  // The minimizer of the cell's quadric, solved around the mean of the cell's vertices as a truncated
  // pseudo-inverse (Lindstrom 2000): directions the quadric does not constrain (along a flat cell, along a
  // cylinder's axis) stay at the mean instead of running off. The cutoff, at 1e-3 of the quadric's trace (the
  // sum of its eigenvalues), is smooth (Tikhonov damping) so that the point varies continuously with the
  // sums. The quadric only knows the triangles touching the cell, so a solution farther than their mean
  // edge (at most the cell's size) outside the box of the cell's vertices is replaced by the quadric's best
  // point within that grown box: the tangent planes of a horn's tip cross above the tip.
  quadric,
  // The minimizer of the quadric over the cell's box (Lindstrom & Silva 2001): never leaves the cell.
  constrained,
  // The average of the cell's input vertices (Rossignac & Borrel 1993); corners, for triangle soups.
  mean,
};

// "quadric", "constrained", "mean".
const char* representative_name(Representative representative);

struct ClusterOptions {
  // Uniform grid resolution: `grid` cells along the longest bounding-box axis (1 .. 2^21), unless
  // `cell_size` > 0 gives the cells' edge length instead. Ignored by the octree and when `target_faces` > 0.
  std::uint32_t grid = 256;
  double cell_size = 0;

  // Adaptive octree instead of the uniform grid. Needs exactly one of `target_vertices`, `target_faces`.
  bool octree = false;
  // Octree only: exactly this many output vertices (fewer only when the finest grid the input allows has
  // fewer occupied cells; ClusterStats::target_met then says so), each a corner of an output face except
  // where every triangle of a cluster collapsed: a part of the input, or a thin piece of one (a leg, an ear
  // at a few dozen vertices), within a cluster's width. Such a vertex of no face counts too
  // (ClusterStats::isolated_vertices).
  std::uint64_t target_vertices = 0;
  // Never exceeded. Octree: the largest face count not above this that merging reaches. Uniform grid: the
  // re-clustering of the fine grid's cells whose face count a search over resolutions finds closest below
  // this (the count does not grow strictly with the resolution, so a finer one may still give fewer).
  std::uint64_t target_faces = 0;
  // Target-driven modes accumulate on a fine power-of-two grid of about this many occupied cells per
  // targeted output vertex (a face target counts as target_faces / 2 vertices), then merge.
  double fine_cells_per_target = 8;
  // Target-driven modes: refine the fine grid until it holds at least this many cells (or one per distinct
  // point), so that thin shells, far-apart parts and far stray points reach the target too; 0 means as many
  // as the target has vertices, or, for a face target, faces (a thin strip whose width fit in one cell had
  // more cells than vertices asked for, and no face survived). The pipeline asks for fewer: its intermediate
  // need not be exact, and refining up to it would undo the cap that keeps the octree fast (a 10 M scan's
  // two-stage run to 1 %: 2.3 s and 174 MB capped, 4.9 s and 562 MB refined, same result).
  std::uint64_t refine_until_cells = 0;

  Representative representative = Representative::quadric;

  // Keep open borders from shrinking, without connectivity (Lindstrom & Silva 2001): every edge that crosses
  // between two cells adds the oriented plane through it perpendicular to its triangle to both cells, per
  // direction class. An interior edge is added twice with opposite orientations and cancels; what remains
  // at a cell are the planes of the border (and the bisecting planes of sharp creases) running through it,
  // which the representative is then also fitted to. Needs consistently oriented input: a flipped triangle
  // makes its edges look like borders. Unless border_in_quadrics is set, these planes only place vertices:
  // the output quadrics stay those of the original surface, so the decimator measures distance to the
  // surface alone.
  bool preserve_boundary = true;
  // Weight of a border crossing relative to a full cell of surface (cell_size^2 of area). A slot's plane
  // weighs the square of its summed normals' length, so cancelled interior edges weigh nothing.
  double boundary_weight = 1.0;
  // Also add those border (and crease) planes to the output quadrics. A decimator that takes them then knows
  // the original's borders and needs no border planes of its own: the clustered mesh has spurious borders,
  // folds and overlapping triangles (where both diagonals of four cells survive) that its own would pin.
  // The two-stage pipeline sets it and turns the decimator's border planes off. The output's areas then say
  // how much of each quadric is surface (QuadricMesh::areas).
  bool border_in_quadrics = false;
  // Weight of those carried planes, in the decimator's units (DecimateOptions::boundary_weight: a border edge
  // e weighs this times |e|^2, so a border weighs this times its length times the mesh's edge length). The
  // pass cannot see edges, so the input's mean edge length comes from its area and triangle count. Placing
  // vertices still uses boundary_weight: the carried weight must not depend on the fine cells' size, or a
  // finer first stage would carry weaker borders (bunny through a 100x intermediate: RMS 1.21x pure
  // decimation's with boundary_weight's scale, 1.01x with this one).
  double carried_border_weight = 10.0;

  unsigned threads = 0;  // 0: all cores. The output does not depend on it.

  // Indexed input: called once the pass has picked its fine grid, before it reads a face, with that grid's
  // occupied cells, which the rest of the run's memory grows with (a target-driven grid's level can hold up
  // to about 4 times the cells planned). Returning false ends cluster() there, with an empty mesh and
  // ClusterStats::declined set; it has then read no face and left the stream's vertex array as it was, so
  // the stream can still be read whole (the pipeline then decimates in core, where that takes less memory).
  std::function<bool(std::uint64_t fine_cells)> accept_fine_cells;

  // Phases "cluster: vertices" (vertices), "cluster: faces" (bytes of input), "cluster: merge" (merges),
  // "cluster: place" (cells).
  ProgressFn progress;
};

struct ClusterStats {
  std::uint64_t input_vertices = 0;   // of the stream's vertex array (0 for triangle soups)
  std::uint64_t input_triangles = 0;  // triangles read
  std::uint64_t fine_cells = 0;       // occupied cells of the grid the pass accumulated on
  std::uint32_t fine_grid = 0;        // that grid's cells along the longest axis
  // The occupied cells' extent, in cells, along the axis where it is largest: about fine_grid when the faces
  // span the bounding box; far less when vertices no face uses stretch it (the box is the vertex array's).
  std::uint32_t spanned_cells = 0;
  double fine_cell_size = 0;
  std::uint64_t output_vertices = 0;  // written: the clusters, less the isolated ones left out
  std::uint64_t output_faces = 0;
  // On the grid the pass accumulated on (the output's, for a plain uniform grid):
  std::uint64_t collapsed_triangles = 0;  // input triangles with two corners in one cell
  std::uint64_t duplicate_triangles = 0;  // input triangles whose three cells an earlier one had
  // Clusters no output face uses (every triangle collapsed): left out of the output, except as the octree's
  // vertex target counts them or where no face is left at all.
  std::uint64_t isolated_vertices = 0;
  // Uniform grid: the output cells' edge length and how many of them span the longest axis (rounded up:
  // with `target_faces` the resolution need not be whole).
  std::uint32_t output_grid = 0;
  double output_cell_size = 0;
  bool target_met = true;            // false when a vertex/face target could not be reached
  bool declined = false;             // accept_fine_cells returned false: nothing was clustered
  double seconds = 0;                // wall time of cluster()
  std::uint64_t peak_rss_bytes = 0;  // of the process, when cluster() returned
};

// The fine cells a target-driven run (a face target, or the octree) plans its single pass for; 0 for a grid
// given by --grid or --cell-size, whose cells only the pass finds.
std::uint64_t planned_fine_cells(const ClusterOptions& options);

// Clusters the stream in one pass and returns the mesh with one quadric per vertex (the sum of the plane
// quadrics of the original triangles that touched the cell). Consumes the stream; an indexed stream's vertex
// array is emptied (see the top of this file). Throws Error on bad input (non-finite
// coordinates or origin, indices past the vertex array) and on impossible options (a cell size giving more
// than 2^21 cells along an axis, an octree without a target, more than 2^31 occupied cells, an unknown
// representative). A stream's bounds() and attribute arrays are trusted as the readers make them: a point
// outside the bounds is clamped into the border cells.
QuadricMesh cluster(TriangleStream& stream, const ClusterOptions& options = {},
                    ClusterStats* stats = nullptr);

}  // namespace ocsimp
