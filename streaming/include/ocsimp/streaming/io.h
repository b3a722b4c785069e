// Reading and writing meshes: format detection, streaming reads, whole-mesh reads built on the same
// parsers, and writers that only ever leave complete files behind.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"
#include "ocsimp/streaming/triangle_stream.h"

namespace ocsimp {

enum class FileFormat { ply, obj, stl, drc };

const char* format_name(FileFormat format);
// From the file's first bytes (PLY and Draco magic, STL binary size rule, OBJ keywords); falls back on the
// extension only where the content is ambiguous. Throws Error when the file cannot be opened or recognized.
FileFormat detect_format(const std::string& path);
// From the extension alone (for writers): .ply .obj .stl .drc, case-insensitive. Throws Error otherwise.
FileFormat format_from_extension(const std::string& path);

// Consecutive vertices handed to ReadOptions::vertex_sink: their positions, and each attribute the reader
// delivers for them (the others empty).
struct VertexChunk {
  std::span<const Vec3f> positions;
  std::span<const Vec3f> normals;
  std::span<const Color> colors;
  std::span<const Vec2f> uvs;
};

struct ReadOptions {
  std::size_t batch_capacity = TriangleBatch::default_capacity;
  ProgressFn progress;  // bytes of input read ("read" phase)
  // Bound in bytes on the vertex array an indexed reader (PLY, OBJ) may hold, 0 for none: 12 bytes a
  // position, and for a PLY 12 more for normals, 4 for colors and 8 for texture coordinates where it has
  // them. Past it, open_triangle_stream dereferences the faces out of core (external_dereference.h): the
  // stream then delivers triangle soups in the file's face order, their corners carrying a PLY's per-vertex
  // normals, colors and texture coordinates, and an OBJ's vertex colors (its normals and texture
  // coordinates, which it indexes per corner, are dropped and named by TriangleStream::attributes_left_out).
  std::uint64_t memory_budget = 0;
  // For the out-of-core path: when set, an indexed reader hands its vertices to this sink in file order, a
  // chunk at a time, and keeps no vertex array; next() still yields indices into the file's vertices and
  // checks them against the file's vertex count. Other readers ignore it.
  std::function<void(const VertexChunk& chunk)> vertex_sink;
  // Told, once per file and without stopping the read, what the reader had to approximate: vertices whose
  // face corners give them different texture coordinates or normals (uv seams, hard edges) keep their first
  // corner's, as a mesh here holds one of each per vertex.
  std::function<void(const std::string& message)> warn;
  // A vertex whose face corners give it different texture coordinates or normals (an OBJ's vt and vn, a PLY
  // face's texcoord list: a uv seam, a hard edge) becomes one vertex per distinct value, at the same
  // position, instead of keeping its first corner's (and no warning is due). For the commands that
  // decimate, which weld such copies back for the collapses and keep each side's attributes
  // (DecimateOptions::weld). Off by default: a vertex of the file stays one vertex (what `info` counts).
  // Ignored out of core, where the corners' attributes are not read.
  bool split_corner_attributes = false;
  // Whether read_mesh refuses a file without faces (a PLY's empty face element says so at its header line).
  // `info` and `convert` read them: ocsimp writes one when every triangle of a clustering collapses.
  bool faces_required = true;
};

std::unique_ptr<TriangleStream> open_triangle_stream(const std::string& path,
                                                     const ReadOptions& options = {});
// The triangle count to plan for before opening `path` (which may read all of its vertices): a PLY's
// header count, bounded by what the file could hold; an estimate from an OBJ's size (a face line per 40
// bytes); 0 where that is unknown (triangle strips, STL, Draco, a file that does not parse, which the
// reader will report). Like TriangleStream::triangles_hint, only a hint.
std::uint64_t triangles_hint(const std::string& path);
// Whether `stream` dereferences its faces on disk (opened past ReadOptions::memory_budget).
bool dereferenced_out_of_core(const TriangleStream& stream);
// The vertices of the file such a stream dereferences (its triangles arrive as corners, so its vertex array
// is empty); 0 for any other stream.
std::uint64_t dereferenced_vertex_count(const TriangleStream& stream);
// The read buffers such a stream holds while it delivers its triangles (one per partition of the vertex
// ids), in bytes; 0 for any other stream.
std::uint64_t dereference_buffer_bytes(const TriangleStream& stream);

// The whole mesh in memory, built by draining the stream. Corners of a triangle soup (STL) that share a
// position exactly are welded into one vertex.
IndexedMesh read_mesh(const std::string& path, const ReadOptions& options = {});
// The same for a stream already open (for callers that looked at its header first); consumes the stream.
IndexedMesh read_mesh(TriangleStream& stream);

// The most Draco position bits taken. More add nothing to a float's 24-bit significand, and Draco's encoder
// sizes its entropy tables by the quantized range: 2^26 values took 300 MB on a 288-face sphere, 2^30 ran
// out of memory at 17 GB.
inline constexpr int kMaxDracoPositionBits = 24;

struct WriteOptions {
  std::optional<FileFormat> format;  // default: from the output path's extension
  bool ascii = false;                // PLY and STL: text instead of binary
  int draco_position_bits = 16;      // Draco position quantization (1..kMaxDracoPositionBits)
  int draco_compression_level = 7;   // Draco speed/size trade-off (0 fastest .. 10 smallest)
  ProgressFn progress;               // faces written ("write" phase)
};

// Whether the format keeps coordinates far from zero at their precision (PLY writes double coordinates for
// a mesh with an origin, OBJ writes them as decimal text); STL and Draco hold floats, so a mesh with an
// origin is written to them at float precision around zero (see IndexedMesh::origin).
bool holds_origin(FileFormat format);

// Writes atomically: to a temporary name beside `path`, renamed over it only when complete.
void write_mesh(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options = {});

}  // namespace ocsimp
