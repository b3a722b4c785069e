// A generator of scan-like test meshes of any size: closed blobby surfaces with displacement at several
// frequencies and fine scanner-like noise, optionally with holes and several components. Every vertex and
// face is a pure function of (options, index), so a mesh of 10^9 triangles streams to disk in constant memory
// and the same seed gives the same bytes.
#pragma once

#include <cstdint>
#include <string>

#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"

namespace ocsimp {

inline constexpr double kMostOffset = 1e9;  // GenerateOptions::offset's limit, see generate.cpp

struct GenerateOptions {
  std::uint64_t triangles =
      2'000'000;  // requested; the mesh has the nearest count its lattice reaches (below)
  std::uint64_t seed = 1;
  int components = 1;    // separate blobs side by side
  int holes = 0;         // round holes cut in each component (their borders are open boundaries)
  double noise = 0.15;   // scanner noise amplitude along the normal, in units of the mean edge length
  bool normals = false;  // write per-vertex normals (of the smooth surface)
  bool colors = false;   // write per-vertex colors (a function of position)
  bool ascii = false;    // ascii PLY instead of binary
  // Where the mesh is placed: about a unit blob around this point, each coordinate within kMostOffset of
  // zero. Unless it is zero the PLY holds double coordinates, as georeferenced scans do
  // (IndexedMesh::origin).
  Vec3d offset = Vec3d::Zero();
  int threads = 0;      // 0: all cores; output does not depend on it
  ProgressFn progress;  // "generate" phase, in faces written
};

// What a generator run produces: each component is the surface of a cube lattice of n x n quads a side,
// projected onto a displaced sphere, so it has 6 n^2 + 2 vertices and 12 n^2 triangles before holes remove
// some.
struct GeneratedCounts {
  std::uint64_t lattice = 0;  // n
  std::uint64_t vertices = 0;
  std::uint64_t faces = 0;
};
GeneratedCounts generated_counts(const GenerateOptions& options);

// Streams the mesh to a PLY file (written atomically). Returns the counts written. Throws Error for a path
// not named .ply.
GeneratedCounts generate_scan_ply(const std::string& path, const GenerateOptions& options);

// The same mesh in memory, for tests and benchmarks of moderate size.
IndexedMesh generate_scan_mesh(const GenerateOptions& options);

}  // namespace ocsimp
