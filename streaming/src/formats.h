// The per-format readers and writers behind io.h. Each reader is a TriangleStream; read_mesh() drains it.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
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

// Per-corner attributes onto vertices, which hold one each: vertex v takes the value of the first corner that
// references it. `state` (one entry per vertex, 0 at first) records that it has one (1) and whether a later
// corner disagreed (2); each vertex that disagrees adds one to `disagreeing`, once. A reader may mark a
// vertex kCornerWithout while only corners without the attribute reference it.
constexpr std::uint8_t kCornerWithout = 3;
template <class T>
void take_first_corner(std::vector<std::uint8_t>& state, std::vector<T>& values, std::size_t v,
                       const T& value, std::uint64_t& disagreeing) {
  if (state[v] == 0 || state[v] == kCornerWithout) {
    state[v] = 1;
    values[v] = value;
  } else if (state[v] == 1 && values[v] != value) {
    state[v] = 2;
    ++disagreeing;
  }
}

// What ReadOptions::warn is told when `vertices` of them had a color channel outside its span, clamped:
// [0, 1] for floating point, where some writers put 0..255 and every such color came out white without a
// word; 0..255 for a PLY's `integer` types but ushort.
inline std::string clamped_colors_note(std::uint64_t vertices, bool integer = false) {
  return std::to_string(vertices) + (vertices == 1 ? " vertex has" : " vertices have") +
         (integer ? " an integer color channel outside 0..255, clamped to it"
                  : " a floating-point color channel outside 0..1, clamped to it (are the colors on a 0..255 "
                    "scale?)");
}

// What ReadOptions::warn is told when face corners gave vertices different texture coordinates
// (`uv_seam_vertices` of them) or normals (`hard_edge_vertices`); empty when neither.
inline std::string merged_corners_note(std::uint64_t uv_seam_vertices, std::uint64_t hard_edge_vertices) {
  auto vertices = [](std::uint64_t n, const char* where) {
    return std::to_string(n) + (n == 1 ? " vertex " : " vertices ") + where +
           (n == 1 ? " keeps its" : " keep their");
  };
  std::string note;
  if (uv_seam_vertices > 0) {
    note =
        vertices(uv_seam_vertices, "on texture seams (face corners giving different texture coordinates)") +
        " first corner's in this command (convert keeps a vertex per side, as decimate, simplify and lod do "
        "without --no-weld)";
  }
  if (hard_edge_vertices > 0) {
    note += (note.empty() ? "" : "; ") +
            vertices(hard_edge_vertices, "on hard edges (face corners giving different normals)") +
            " first corner's normal";
  }
  return note;
}

// One kind of data a reader passed over: what it is ("vertex property", "vertex properties") and the names
// found, each once, in the order found. It keeps one more name than unread_note shows, to say there are more:
// a header may declare thousands, and an OBJ may name a material on every other line.
struct UnreadData {
  static constexpr std::size_t kShown = 6;
  std::string kind, kinds;  // singular and plural
  std::vector<std::string> names;
  void add(std::string_view name) {
    if (names.size() <= kShown && std::find(names.begin(), names.end(), name) == names.end())
      names.emplace_back(name);
  }
};

// What ReadOptions::warn is told of data in the file that no output keeps (a scan's confidence values, a
// PLY's face colors or texture file, an OBJ's materials and polylines), so that losing them is not silent;
// empty when there is none.
inline std::string unread_note(const std::vector<UnreadData>& unread) {
  std::string note;
  for (const UnreadData& data : unread) {
    if (data.names.empty()) continue;
    note += note.empty() ? "" : "; ";
    note += (data.names.size() == 1 ? data.kind : data.kinds) + " ";
    for (std::size_t i = 0; i < data.names.size() && i < UnreadData::kShown; ++i)
      note += (i == 0 ? "" : ", ") + data.names[i];
    if (data.names.size() > UnreadData::kShown) note += " and more";
  }
  if (note.empty()) return note;
  return "not read, so no output keeps them (ocsimp reads triangles and their vertices' positions, normals, "
         "colors and texture coordinates): " +
         note;
}

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
