// Indexed triangle meshes, with optional per-vertex attributes, and the mesh-with-quadrics that the
// cluster stage hands to the decimator.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/core/quadric.h"
#include "ocsimp/core/types.h"

namespace ocsimp {

// Attribute arrays are either empty or hold exactly one entry per position.
//
// Positions are 32-bit floats relative to `origin`: vertex i lies at origin + positions[i], summed in double.
// Float spacing grows with distance from zero (about 0.008 at 10^5, 0.5 at 10^7), so a scan stored in
// georeferenced double coordinates would lose its detail to rounding if held in floats as it stands: the
// readers take such a file relative to a point of its own instead (see far_origin), every stage keeps that
// origin, and the writers add it back. Everywhere else the origin is zero.
struct IndexedMesh {
  Vec3d origin = Vec3d::Zero();
  std::vector<Vec3f> positions;
  std::vector<Triangle> triangles;
  std::vector<Vec3f> normals;
  std::vector<Color> colors;
  std::vector<Vec2f> uvs;

  std::size_t vertex_count() const { return positions.size(); }
  std::size_t face_count() const { return triangles.size(); }
  bool has_normals() const { return !normals.empty(); }
  bool has_colors() const { return !colors.empty(); }
  bool has_uvs() const { return !uvs.empty(); }
  Box3 bounds() const;
};

// Bytes a vertex takes in memory: its position and each attribute it has (the memory budgets count them).
constexpr std::size_t vertex_bytes(bool normals, bool colors, bool uvs) {
  return sizeof(Vec3f) + (normals ? sizeof(Vec3f) : 0) + (colors ? sizeof(Color) : 0) +
         (uvs ? sizeof(Vec2f) : 0);
}

// Past this distance from zero on some axis, float spacing exceeds 2^-14 (6e-5): a reader of coordinates held
// more precisely than floats (double or 32-bit integer PLY properties, OBJ text) takes such a mesh relative
// to a point of its own.
inline constexpr double kFarFromOrigin = 1024.0;
// The vertices a reader of such coordinates holds in double until it has chosen the origin from them.
inline constexpr std::size_t kOriginSample = 1024;

// The origin for a mesh whose first vertices (up to kOriginSample, in file order) are `first`: their
// coordinate-wise median when it lies past kFarFromOrigin on some axis (and within float range), otherwise
// zero, so meshes near zero read exactly as floats. A median, not the first vertex, so that a stray point
// (a georeference marker, an outlier) cannot move every other vertex away from its float precision.
Vec3d far_origin(std::vector<Vec3d> first);

// A mesh whose vertices carry quadrics. `quadrics` is empty (the decimator then builds area-weighted plane
// quadrics from the faces) or holds one quadric per vertex, summed over the *original* surface, so that costs
// computed from it measure distance to the original and not to an intermediate (Garland & Shaffer 2002).
struct QuadricMesh {
  IndexedMesh mesh;
  std::vector<Quadric> quadrics;
  // Empty, or one per quadric: the weight of its surface planes alone, the area they stand for (the trace of
  // their A), where the quadrics also hold border planes (a clustering's or a decimation's carried borders).
  // A cost is a distance over that area (decimate.h's error_distance): over the whole trace, border planes
  // of a large weight made every distance along a border look smaller. Empty: the whole trace is surface.
  std::vector<double> areas = {};  // (an initializer: QuadricMesh{mesh, quadrics} leaves it empty)
};

// The area vertex v's quadric stands for (see QuadricMesh::areas).
inline double surface_area(const QuadricMesh& m, std::size_t v) {
  return m.areas.empty() ? m.quadrics[v].trace() : m.areas[v];
}

// Throws Error, its reason starting with `who` (as "decimate: "), unless every attribute array is empty or
// has one entry a vertex and every face corner is in the vertex array: what any code that indexes the
// arrays by the faces needs. Values are not looked at.
void check_indices(const IndexedMesh& mesh, const std::string& who);

// Area-weighted plane quadrics of the faces, summed at their corners. Throws Error as check_indices.
std::vector<Quadric> face_quadrics_per_vertex(const IndexedMesh& mesh);

// Connectivity facts for `ocsimp info` and for tests that assert manifoldness.
struct MeshTopology {
  std::size_t edges = 0;
  std::size_t boundary_edges = 0;      // used by exactly one face
  std::size_t non_manifold_edges = 0;  // used by three or more faces
  std::size_t inconsistent_edges = 0;  // two faces traverse the edge in the same direction (orientation flip)
  std::size_t components = 0;          // connected by shared vertices, counting only vertices that faces use
  std::size_t degenerate_faces = 0;    // a repeated corner index
  std::size_t duplicate_faces = 0;     // same corner set as an earlier face
  std::size_t unreferenced_vertices = 0;
  std::size_t non_manifold_vertices = 0;  // faces around the vertex form more than one fan
};
// Throws Error as check_indices.
MeshTopology analyze_topology(const IndexedMesh& mesh);

}  // namespace ocsimp
