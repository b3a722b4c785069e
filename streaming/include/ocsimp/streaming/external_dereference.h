// Out-of-core dereferencing of indexed meshes whose vertex array does not fit the memory budget (after
// Lindstrom & Silva 2001, with the sort by vertex id replaced by a partition of the vertex ids).
//
// The reader hands its vertices to a spool instead of keeping them: they stay in memory while they fit the
// budget (the stream is then an ordinary indexed stream of positions), otherwise they go to a temporary file.
// In the second case the faces are drained once to a file of indices, and the vertex ids are cut into
// partitions that each fit the budget: for each partition its vertices are loaded and the index file is
// scanned, writing the record of every corner that falls in it, in face order, to that partition's region
// of a corner file. next() then reads the index file once more and takes each corner's record from the
// next unread one of its partition's region, so it delivers the faces in file order as triangle soups.
//
// A record is a vertex's position and the attributes its reader delivers: a PLY's normals, colors and
// texture coordinates (R = 12 bytes, + 12, + 4, + 8), which reach the soup's corners. An OBJ's records are
// its positions and their colors (when a vertex of its first 65,536 has them); it indexes normals and
// texture coordinates per corner, separately from its positions, and the stream names them as left out
// (TriangleStream::attributes_left_out).
//
// Memory: the budget (one partition, or the read buffers of every partition) plus a few buffers; at most 64
// partitions, as each costs a scan of the index file, so below a 64th of the vertex array the budget is
// exceeded rather than the time growing without bound. Disk under TMPDIR: R bytes a vertex + up to 12 bytes
// a triangle (indices, coded) + 3R bytes a triangle (corners). The temporary files are unlinked as soon as
// they are created, so nothing is left behind however the process ends.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/triangle_stream.h"

namespace ocsimp {

// Opens `path` (PLY or OBJ; other formats are opened as usual) with its vertex array bounded by
// `options.memory_budget` bytes (at least 12), dereferencing on disk when it is exceeded.
// open_triangle_stream calls this when the file's vertices may exceed a budget; tests call it to force the
// path with a tiny one.
std::unique_ptr<TriangleStream> open_dereferenced_stream(const std::string& path, const ReadOptions& options);

}  // namespace ocsimp
