// Attribute seams: an input that stores a vertex once per side of a texture seam or a hard normal edge
// (vertices at one position, each with its own uv or normal) is decimated welded, so both sides of the seam
// move together and the surface cannot crack open along it, and the sides are told apart again on output.
//
// The decimator only knows one attribute value per position. On output, each face corner takes the
// attribute its own side of the seam has at the new vertex's position: a walk over the original faces,
// starting at those around the corner's original vertex and moving to any face sharing a vertex with the
// current one that lies nearer the position, ends at the nearest point of that side, and the attributes are
// interpolated there. The walk crosses faces through the input's own vertices, never through the weld, so it
// stays on its side. The corners of an output vertex whose attributes then agree share one output vertex;
// those that differ (the two sides of a seam) get one each, at the same position. An input without seams
// takes its attributes the same way, one walk a vertex: interpolated along the collapsed edges instead, a
// vertex that ended where a removed one had been got its neighbours' blend.
#pragma once

#include <cstdint>
#include <vector>

#include "ocsimp/core/mesh.h"
#include "ocsimp/core/quadric.h"

namespace ocsimp::decimate_detail {

// The input as it was before welding, its copies of a vertex with equal attributes merged
// (same_attribute_targets): what the output's attributes are interpolated from.
struct SeamSource {
  std::vector<Vec3f> positions;
  std::vector<Triangle> triangles;
  std::vector<Vec3f> normals;
  std::vector<Color> colors;
  std::vector<Vec2f> uvs;
};

// For each vertex, the lowest index of a vertex at the same position (`position_target`, as welding found
// it) with the same attributes: the copies a file stores of one vertex (a triangle soup's corners) are one
// vertex on their side, and only copies that differ are the sides of a seam.
std::vector<Index> same_attribute_targets(const IndexedMesh& mesh, const std::vector<Index>& position_target);

// Gives every corner of `out` its side's attributes and, with `split_seams`, splits the vertices where sides
// differ; without (an input without seams), each vertex has one side, and takes the attributes where a walk
// from its first corner ends. `face_origin[f]` is the index in source.triangles of the input face output face
// f descends from; `out` holds positions and triangles (its attribute arrays are replaced) and `quadrics`,
// and `areas`, when not null, one quadric and its area per vertex, which a split vertex shares out evenly
// among its copies, so that welding them again (the next level of an LOD chain) adds them back up to the
// whole. Returns the vertices added.
std::uint64_t restore_attributes(const SeamSource& source, const std::vector<Index>& face_origin,
                                 IndexedMesh& out, std::vector<Quadric>* quadrics, std::vector<double>* areas,
                                 bool split_seams);

}  // namespace ocsimp::decimate_detail
