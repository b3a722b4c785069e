// The per-format readers and writers behind io.h. Each reader is a TriangleStream; read_mesh() drains it.
#pragma once

#include <memory>
#include <string>

#include "ocsimp/core/mesh.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/triangle_stream.h"

namespace ocsimp::detail {

std::unique_ptr<TriangleStream> open_ply_stream(const std::string& path, const ReadOptions& options);
std::unique_ptr<TriangleStream> open_obj_stream(const std::string& path, const ReadOptions& options);
std::unique_ptr<TriangleStream> open_stl_stream(const std::string& path, const ReadOptions& options);
std::unique_ptr<TriangleStream> open_drc_stream(const std::string& path, const ReadOptions& options);

// The reader for `format` with its vertex array bounded by options.memory_budget (external_dereference.cpp),
// or nullptr when the file's vertices certainly fit (the caller opens the plain reader).
std::unique_ptr<TriangleStream> open_within_budget(const std::string& path, FileFormat format,
                                                   const ReadOptions& options);

void write_ply(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);
void write_obj(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);
void write_stl(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);
void write_drc(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);

}  // namespace ocsimp::detail
