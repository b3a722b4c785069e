// A TriangleStream over a mesh already in memory: lets the cluster stage, tests and benchmarks run on
// generated or loaded meshes through the same interface as files.
#pragma once

#include <memory>
#include <string>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/streaming/triangle_stream.h"

namespace ocsimp {

// `as_soup` streams corner positions instead of indices, as an STL reader would, with the mesh's normals,
// colors and texture coordinates on the corners, as the out-of-core reading of a PLY delivers them.
// The mesh is copied when passed by value; move it in to avoid the copy. Throws Error as check_indices
// (core/mesh.h) for a face corner past the vertex array or an attribute array of another length.
std::unique_ptr<TriangleStream> make_mesh_stream(
    IndexedMesh mesh, bool as_soup = false, std::size_t batch_capacity = TriangleBatch::default_capacity);

}  // namespace ocsimp
