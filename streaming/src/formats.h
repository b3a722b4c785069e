// The per-format readers and writers behind io.h. Each reader is a TriangleStream; read_mesh() drains it.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ocsimp/core/mesh.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/triangle_stream.h"

namespace ocsimp::detail {

std::unique_ptr<TriangleStream> open_ply_stream(const std::string& path, const ReadOptions& options);
std::unique_ptr<TriangleStream> open_obj_stream(const std::string& path, const ReadOptions& options);
std::unique_ptr<TriangleStream> open_stl_stream(const std::string& path, const ReadOptions& options);
std::unique_ptr<TriangleStream> open_drc_stream(const std::string& path, const ReadOptions& options);

struct PlyElement;
// The bytes a PLY reader keeps per vertex of `element`: the position and the attributes it reads (the
// memory budget counts them). Throws Error where the element has no position.
std::uint64_t ply_vertex_bytes(const std::string& path, const PlyElement& element);

// The triangles a PLY's header announces (its face element's count, bounded by what the file could hold),
// without reading its data; 0 for triangle strips. Throws Error where the header does not parse.
std::uint64_t ply_triangles_hint(const std::string& path);

// The reader for `format` with its vertex array bounded by options.memory_budget (external_dereference.cpp),
// or nullptr when the file's vertices certainly fit (the caller opens the plain reader).
std::unique_ptr<TriangleStream> open_within_budget(const std::string& path, FileFormat format,
                                                   const ReadOptions& options);

// "normals, colors and texture coordinates", or the part of it that is true (see
// TriangleStream::attributes_left_out).
inline std::string attribute_list(bool normals, bool colors, bool uvs) {
  std::vector<const char*> names;
  if (normals) names.push_back("normals");
  if (colors) names.push_back("colors");
  if (uvs) names.push_back("texture coordinates");
  std::string list;
  for (std::size_t i = 0; i < names.size(); ++i)
    list.append(i == 0 ? "" : i + 1 == names.size() ? " and " : ", ").append(names[i]);
  return list;
}

void write_ply(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);
void write_obj(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);
void write_stl(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);
void write_drc(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);

}  // namespace ocsimp::detail
