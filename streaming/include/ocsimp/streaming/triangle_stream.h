// TriangleStream: the pull interface through which the cluster stage reads a mesh of any size in one pass.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/types.h"

namespace ocsimp {

// One batch of triangles. An indexed stream fills `triangles` with indices into its vertex array; a triangle
// soup (STL, or faces dereferenced out of core) fills `corners` with positions. Exactly one of the two is
// used.
struct TriangleBatch {
  static constexpr std::size_t default_capacity = 1 << 16;

  std::vector<Triangle> triangles;
  std::vector<std::array<Vec3f, 3>> corners;
  // A soup's corner attributes, one entry per entry of `corners`, where the stream has them (faces
  // dereferenced out of core from a PLY with per-vertex normals, colors or texture coordinates); otherwise
  // empty. A stream fills the same ones in every batch.
  std::vector<std::array<Vec3f, 3>> corner_normals;
  std::vector<std::array<Color, 3>> corner_colors;
  std::vector<std::array<Vec2f, 3>> corner_uvs;

  std::size_t size() const { return triangles.size() + corners.size(); }
  void clear() {
    triangles.clear();
    corners.clear();
    corner_normals.clear();
    corner_colors.clear();
    corner_uvs.clear();
  }
};

class TriangleStream {
 public:
  virtual ~TriangleStream() = default;

  // Clears `batch` and fills it with up to the stream's batch capacity of triangles (polygons arrive split:
  // an OBJ's or PLY's concave ones in core by ear clipping in their plane, the rest as a fan). Returns false,
  // with an empty batch, once the input is exhausted. Throws Error on bad input.
  virtual bool next(TriangleBatch& batch) = 0;

  // Indexed streams: the vertex array, loaded once before the first batch, as a mesh without triangles
  // (positions plus whichever of normals, colors and uvs the file has). Soups: an empty mesh.
  virtual const IndexedMesh& vertices() const = 0;
  bool indexed() const { return !vertices().positions.empty(); }

  // The vertex array, writable, for the one consumer that makes its single pass over this stream and reuses
  // the array's memory as scratch (the cluster stage packs each vertex's cell into its 12 bytes, to stay
  // within 12 bytes a vertex). Afterwards vertices() holds that consumer's data, not positions. While batches
  // remain the array's sizes must be kept; once next() has returned false the consumer may release it.
  // A stream reads its positions back only to split the polygons still to come, through position(): a
  // consumer that overwrites them must first say where they are now (set_position_source), or a concave
  // polygon is cut by garbage.
  IndexedMesh& scratch_vertices() { return const_cast<IndexedMesh&>(vertices()); }
  // Where vertex v's position is read from, in place of the vertex array, until set again (empty: the
  // array). Set it between calls to next(), which calls it (on its own thread); it must not throw.
  void set_position_source(std::function<Vec3f(Index)> source) { position_source_ = std::move(source); }

  // Bounding box of every vertex. Known up front for indexed streams; a soup may scan its input once for it.
  virtual Box3 bounds() = 0;

  // Triangles promised by the header (OBJ: face statements counted by its vertex pass), or 0 when the format
  // does not say (ASCII STL). Polygons may make it an underestimate: for progress only, never for allocation.
  virtual std::uint64_t triangles_hint() const = 0;

  // Progress in bytes of the input file.
  virtual std::uint64_t bytes_read() const = 0;
  virtual std::uint64_t bytes_total() const = 0;

  virtual const std::string& path() const = 0;

  // Vertex attributes the file has that this stream does not deliver, as a list ("normals and colors"): an
  // OBJ dereferenced out of core delivers its corners' positions and vertex colors only. Empty when nothing
  // is left out.
  virtual std::string attributes_left_out() const { return {}; }

 protected:
  // What a reader splitting a polygon by its corners' positions may rely on: a source was set, or the
  // vertex array holds positions (a reader handing its vertices to a sink keeps none, and fans).
  bool positions_known() const { return position_source_ || !vertices().positions.empty(); }
  Vec3f position(Index v) const { return position_source_ ? position_source_(v) : vertices().positions[v]; }
  // Whether two vertices are one point: the same index, or, where positions are at hand, the same position
  // (the copies a uv seam splits a vertex into).
  bool same_point(Index a, Index b) const {
    return a == b || (positions_known() && position(a) == position(b));
  }

 private:
  std::function<Vec3f(Index)> position_source_;
};

}  // namespace ocsimp
