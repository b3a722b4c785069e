// Writing a PLY file vertex by vertex and face by face, for producers that never hold the whole mesh
// (the scan generator writes 10^9-triangle files through it). write_mesh() uses it too.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "ocsimp/core/types.h"

namespace ocsimp {

class AtomicFile;

struct PlyLayout {
  std::uint64_t vertices = 0;
  std::uint64_t faces = 0;  // triangles
  bool normals = false;     // nx ny nz float
  bool colors = false;      // red green blue alpha uchar
  bool uvs = false;         // u v float
  bool ascii = false;       // default binary_little_endian
  // Positions are offsets from this point (IndexedMesh::origin). Unless it is zero, x y z are written as
  // doubles, origin + offset, so the file keeps the precision the coordinates were read with.
  Vec3d origin = Vec3d::Zero();
};

// Declares the counts up front (PLY's header needs them), then takes exactly that many vertices followed by
// exactly that many faces; finish() checks the counts and renames the file into place. Pass nullptr for
// attributes the layout does not have. Destroying an unfinished writer leaves no file.
class PlyStreamWriter {
 public:
  PlyStreamWriter(const std::string& path, const PlyLayout& layout);
  ~PlyStreamWriter();
  PlyStreamWriter(const PlyStreamWriter&) = delete;
  PlyStreamWriter& operator=(const PlyStreamWriter&) = delete;

  void add_vertex(const Vec3f& position, const Vec3f* normal = nullptr, const Color* color = nullptr,
                  const Vec2f* uv = nullptr);
  void add_face(const Triangle& face);
  // The same for `count` records at once: arrays of `count` entries (nullptr for attributes the layout does
  // not have). Checks each block of records once rather than each record; write_mesh() uses these.
  void add_vertices(const Vec3f* positions, const Vec3f* normals, const Color* colors, const Vec2f* uvs,
                    std::size_t count);
  void add_faces(const Triangle* faces, std::size_t count);
  void finish();

  std::uint64_t bytes_written() const;

 private:
  std::unique_ptr<AtomicFile> file_;
  PlyLayout layout_;
  std::uint64_t vertices_written_ = 0;
  std::uint64_t faces_written_ = 0;
};

}  // namespace ocsimp
