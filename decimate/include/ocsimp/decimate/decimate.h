// Garland-Heckbert quadric edge-collapse decimation of a QuadricMesh to an exact face or vertex count, or to
// an error bound.
//
// Every edge (and, on request, every close vertex pair) is a candidate. A candidate's placement is its summed
// quadric's minimizer (explicit 3x3 solve in double around the edge midpoint) when the system is well
// conditioned and the minimizer lies within two edge lengths; otherwise the best point of the edge segment
// (which includes both endpoints and the midpoint, ties going to an endpoint), moved by a regularized Newton
// step toward the minimizer along the directions the quadric constrains. Its cost is the summed quadric Q
// at the placement; the queue is ordered by Q / sqrt(trace A) (see decimate.cpp for why) and kept exact:
// after every collapse all pairs around the new vertex are re-costed.
//
// Guards, checked when a pair reaches the top of the queue: no surrounding triangle may turn by 90 degrees or
// more in one collapse, or by more than 60 degrees from the input face it started as, or become degenerate
// (quality below 1e-3 and worse than before), nor end up on the same three vertices as another (a face
// doubled back on itself); locked borders do not move; with preserve_topology, the link condition holds. A
// rejected pair is retried when a collapse next to it changes its neighbourhood.
//
// Typical use:
//   ocsimp::ReadOptions read;
//   read.split_corner_attributes = true;  // as `ocsimp decimate` reads: each side of a seam keeps its own
//   ocsimp::QuadricMesh quadric_mesh{ocsimp::read_mesh(path, read), {}};
//   ocsimp::DecimateOptions options;
//   options.target_faces = 10000;
//   ocsimp::DecimateResult result = ocsimp::decimate(std::move(quadric_mesh), options);
//   // result.stats.target_reached, result.stats.reason, result.stats.max_error
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"

namespace ocsimp {

struct DecimateOptions {
  // Stopping criteria. A zero count/ratio is unset; max_error is unset when infinite. Any combination may be
  // given and decimation stops at whichever is reached first; at least one must be set.
  //
  // target_faces: stop at exactly this many faces, or as few fewer as the remaining candidates allow where
  // none removes few enough (one fewer on a closed manifold, where each removes two; up to three fewer
  // where each removes four, as on a surface joined to its reversed copy); never more, unless guards block
  // every collapse first.
  std::uint64_t target_faces = 0;
  // target_vertices: stop at exactly this many vertices (vertices that no face uses are not counted, and are
  // dropped from the output).
  std::uint64_t target_vertices = 0;
  // target_ratio in (0, 1]: a face target of round(ratio * input faces), input faces counted after removing
  // faces with a repeated corner. Combined with target_faces, the smaller target wins.
  double target_ratio = 0;
  // max_error: no collapse whose cost as a distance (see DecimateStats::max_error) exceeds this many model
  // units is applied: a candidate above it leaves the queue until a neighbouring collapse re-costs it, and
  // decimation ends when every remaining candidate exceeds it (or is blocked).
  double max_error = std::numeric_limits<double>::infinity();

  // Candidate pairs: every edge, plus (when > 0) vertex pairs closer than this distance in model units that
  // share no edge, so separate parts can join (Garland & Heckbert 1997): each vertex's 8 nearest (a few
  // more where it is also another's nearest). A border that such pairs will close (another border runs
  // between its ends' partners: a crack, a soup's shared edge) keeps only a trace of its border planes.
  double pair_distance = 0;

  // Boundary edges (used by one face) add to both endpoint quadrics a plane through the edge, perpendicular
  // to its face, with weight boundary_weight * |edge|^2 (the units of an area-weighted face plane), so
  // borders keep their shape; so do folds (two faces on an edge turned more than 120 degrees back on each
  // other), whose nearly parallel face planes cannot hold a flap in place; and so do the edges of an
  // attribute seam that welding joined (see weld), on each side, but for a hard edge whose sides differ
  // only by normals within 30 degrees (flat shading). 0 lets borders and seams move freely. The
  // default, 10, gave the lowest Hausdorff distance on the open shared scan (bunny) among 0.3, 1, 3, 10 and
  // 100.
  double boundary_weight = 10.0;
  // Boundary vertices never move: a border vertex only absorbs interior neighbours, and no collapse joins two
  // border vertices.
  bool lock_boundary = false;
  // Enforce the link condition: a manifold stays manifold, no non-manifold edge appears, no component
  // vanishes and no hole closes.
  bool preserve_topology = false;

  // Face planes weigh by triangle area (on by default). Off: every face plane has weight 1. Only used when
  // the input carries no quadrics.
  bool area_weighting = true;
  // Triangle-shape penalty: a collapse whose worst resulting triangle has quality q = 2 sqrt(3) area / (sum
  // of squared edges) below 0.2 (1: equilateral, 0: degenerate) costs this much more, times (1 - q / 0.2),
  // times the pair's quadric area and its longest resulting edge squared. Keeps slivers out where the quadric
  // cannot tell placements apart (flat and gently curved regions); 0 turns it off. The penalty only has to
  // tip near-ties, and it is capped so that it does no more: it never puts a pair further back than about
  // three times the largest cost applied so far, or a distance of a thousandth of the pair's own size where
  // that is larger, so a long strip whose every collapse along it leaves a sliver still decimates along it
  // rather than across. The cap spares a vertex of more than 64 faces, whose move would make slivers of its
  // whole fan. A small weight does it: over 8 shared meshes at 10, 3, 1 and 0.5 % (32 cases), 0.01 left no
  // triangle below 0.2 in 26 cases (0.05 % of the faces on average, against 2.1 % without the penalty), at
  // 1.6 % more RMS and 4 % more Hausdorff distance than none (geometric means; measured before the cap,
  // which then changed them by -0.8 % and -4.2 %, with 0.4 % more slivers). 0.1 kept out barely more and
  // cost 5.9 % and 12 %; on CAD parts it forced geometry errors to avoid slivers the shape needs (teapot at
  // 1 %: RMS 2.2 times that without the penalty).
  double shape_weight = 0.01;
  // Attribute penalty: a collapse costs this much more, times the pair's quadric area, the squared edge
  // length and the squared attribute difference across the edge (normals: unit-vector distance; colors: per
  // channel in [0,1]; uvs: uv distance). 0 (default): geometry alone decides; attributes are still
  // interpolated along each collapse at the placement's parameter on the edge. The penalty charges a
  // difference across an edge, not a departure from what interpolation reproduces, so it suits sharp
  // attribute boundaries (a two-colored sphere's boundary smears over half the area) and not smooth fields:
  // a sphere of 20 k faces with a sine color pattern, to 1,000 faces, had twice the color error and 3.5 times
  // the Hausdorff distance at weight 1 as at 0. Attribute quadrics (Garland & Heckbert 1998, Hoppe 1999)
  // would measure the latter; they are not implemented.
  double attribute_weight = 0;

  // Merge vertices at exactly equal positions before decimating (their quadrics add), so that what a file
  // stores twice - both sides of a texture seam or a hard normal edge, the corners of a triangle soup, the
  // rims of patches meeting - moves as one and cannot crack open. Where the merged vertices carried
  // different attributes (a seam), each output corner takes its own side's attributes at the new position,
  // and an output vertex where the sides still differ is written once per side (DecimateStats::
  // seam_copies); the vertex counts and targets count positions. Off: such vertices are separate, and each
  // copy is a border.
  bool weld = true;

  // Also return each output vertex's quadric (DecimateResult::quadrics): the sum of everything its input
  // vertices carried, plus the border and fold planes this run added, so a further decimation of the result
  // (an LOD chain) still measures distance to the original surface.
  bool output_quadrics = false;

  // Threads for the setup and for the first decimation phase over spatial regions, on meshes of 16 Ki faces
  // or more (0: all cores). The result does not depend on it.
  int threads = 0;
  // Collapses done out of collapses expected ("decimate" phase; total 0 while only max_error is given, done
  // out of done once the run ends). Phase "decimate: setup" reports the setup's steps first.
  ProgressFn progress;
};

enum class DecimateStop {
  target_reached,  // the face or vertex target was met exactly
  parity,          // a face target was met below (no remaining candidate removed few enough faces)
  max_error,       // every remaining candidate would exceed max_error
  blocked,         // every remaining candidate is rejected by a guard (see DecimateStats::reason)
  exhausted,       // a count target was not met and no candidate pair is left at all
};

struct DecimateStats {
  std::uint64_t input_faces = 0;     // after removing faces with a repeated corner, and repeated faces
  std::uint64_t input_vertices = 0;  // vertices used by those faces (after welding)
  std::uint64_t faces = 0;           // reached
  std::uint64_t vertices = 0;        // reached
  std::uint64_t collapses = 0;
  std::uint64_t target_faces = 0;     // effective face target (0: none)
  std::uint64_t target_vertices = 0;  // effective vertex target (0: none)
  std::uint64_t welded_vertices = 0;  // vertices merged into another by `weld`
  // Vertices the output holds beyond `vertices`: the extra copies of a position, one per side of an
  // attribute seam beyond the first (the output has vertices + seam_copies vertices).
  std::uint64_t seam_copies = 0;
  // Vertices only one face uses: nearly all of them in a triangle soup (each face its own three vertices,
  // as some exporters write), whose faces decimate as separate pieces (see separate_faces_note).
  std::uint64_t single_face_vertices = 0;
  std::uint64_t separate_faces = 0;  // faces that share no edge with another face
  std::uint64_t dropped_degenerate_faces = 0;
  // Faces dropped as repeats of an earlier face: the same corners in the same turn (after welding).
  std::uint64_t dropped_repeated_faces = 0;
  // Rejections of the candidate at the top of the queue, over the whole run.
  std::uint64_t rejected_flip = 0;      // would flip, degenerate or double a surrounding triangle
  std::uint64_t rejected_topology = 0;  // would break the link condition (preserve_topology)
  // The largest cost among the collapses applied, as a distance in model units: sqrt(Q(p) / S), where Q is
  // the pair's summed quadric, p the placement and S the weight of its surface planes alone (with area
  // weighting, the area of original surface the two vertices stand for; see QuadricMesh::areas). Border and
  // fold planes add to Q but not to S: they make moving a border cost more, and never make moving the
  // surface look cheaper (over the whole weight, --boundary-weight 1000 let --max-error 1e-3 move a wavy
  // grid's border 0.015 off). Without borders it is the area-weighted RMS distance from p to the planes of
  // that surface, so an LOD pipeline can use it as a switching distance. error_distance() below converts.
  double max_error = 0;
  // A count target was met (exactly, or below as DecimateStop::parity says); with max_error alone, always
  // true (decimation went as far as the bound allows).
  bool target_reached = false;
  DecimateStop stop = DecimateStop::exhausted;
  std::string reason;  // one line: why decimation stopped, with the counts reached
};

// A quadric error as the distance DecimateStats::max_error reports: sqrt(error / weight), with `weight` the
// area its surface planes stand for (surface_area in mesh.h; 0 for no weight; a rounding below 0 counts as
// 0).
inline double error_distance(double error, double weight) {
  return weight > 0 ? std::sqrt(std::max(0.0, error) / weight) : 0.0;
}

struct DecimateResult {
  IndexedMesh mesh;
  std::vector<Quadric> quadrics;  // per mesh vertex, when DecimateOptions::output_quadrics; else empty
  std::vector<double> areas;      // with quadrics: their surface areas (QuadricMesh::areas)
  DecimateStats stats;
};

// Decimates `input` (taken by value: move it in to let the decimator reuse its arrays). Quadrics carried by
// the input are used as they are; without them, the decimator builds face plane quadrics (area-weighted per
// options). Faces with a repeated corner are removed; non-manifold edges, several components and zero-area
// faces are handled. The output holds only vertices that faces use, in input order, and surviving faces in
// input order; normals, colors and uvs are carried and interpolated. Same input and options give the same
// output for any thread count.
//
// Throws Error for a face index out of range, a non-finite position, normal, uv, quadric or origin, attribute,
// quadric or area arrays whose size is neither 0 nor the vertex count (areas without quadrics too), no
// stopping criterion, a ratio outside (0, 1], a NaN or negative max_error (infinity: no bound), or a pair
// distance or weight that is negative or not finite.
DecimateResult decimate(QuadricMesh input, const DecimateOptions& options);

// The face target a ratio gives of `faces` faces, as DecimateOptions::target_ratio takes it: round(ratio *
// faces), at least 1. For callers that resolve a ratio themselves (a chain of levels, a clustering plan, a
// benchmark's targets). Throws Error for a ratio outside (0, 1].
std::uint64_t ratio_target(double ratio, std::uint64_t faces);

const char* stop_name(DecimateStop stop);

// A warning for a run on a mesh most of whose vertices belong to a single face (a triangle soup): such faces
// share no edge, so the decimator removes them whole and the result is scattered triangles, however small
// its collapse costs; empty otherwise. `welded`: the run had DecimateOptions::weld.
std::string separate_faces_note(const DecimateStats& stats, bool welded);

// Why a run had nothing to decimate although it was given faces (every one has a repeated corner, once
// vertices at equal positions are joined when `welded`), for the commands to refuse it with; empty
// otherwise. The result is then an empty mesh, which no command writes as if it were a simplification.
std::string nothing_to_decimate_reason(const DecimateStats& stats, bool welded);

// A warning for a run that left out faces with a repeated corner (DecimateStats::dropped_degenerate_faces) or
// repeating another face (dropped_repeated_faces); empty when there were none, or when no face was left
// (nothing_to_decimate_reason).
std::string dropped_faces_note(const DecimateStats& stats);

}  // namespace ocsimp
