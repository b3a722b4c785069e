#include "ocsimp/streaming/io.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string_view>
#include <unordered_map>

#include "byte_reader.h"
#include "formats.h"
#include "ocsimp/core/error.h"

namespace ocsimp {
namespace {

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

std::optional<FileFormat> format_of_extension(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".ply") return FileFormat::ply;
  if (ext == ".obj") return FileFormat::obj;
  if (ext == ".stl") return FileFormat::stl;
  if (ext == ".drc") return FileFormat::drc;
  return std::nullopt;
}

bool starts_with(std::string_view text, std::string_view prefix) {
  return text.size() >= prefix.size() && text.substr(0, prefix.size()) == prefix;
}

}  // namespace

const char* format_name(FileFormat format) {
  switch (format) {
    case FileFormat::ply:
      return "PLY";
    case FileFormat::obj:
      return "OBJ";
    case FileFormat::stl:
      return "STL";
    case FileFormat::drc:
      return "Draco";
  }
  return "unknown";
}

FileFormat format_from_extension(const std::string& path) {
  if (auto format = format_of_extension(path)) return *format;
  throw Error(path, {}, "unknown output format (use a .ply, .obj, .stl or .drc extension)");
}

FileFormat detect_format(const std::string& path) {
  detail::ByteReader reader(path, 1 << 16);
  const std::size_t n = reader.fill(512);
  const std::string_view head(reader.data(), n);
  if (n == 0) throw Error(path, FilePosition::byte(0), "empty file");
  // Binary STL: an 80-byte header, a triangle count, then exactly 50 bytes a triangle. Checked before the
  // text forms because binary headers often begin with "solid" too, and, for a .stl, before the magic
  // words: the header is free text, and one that began "DRACO" or "ply" (an exporter's name) was refused.
  bool binary_stl = false;
  if (reader.file_size() >= 84 && n >= 84) {
    std::uint32_t count;
    std::memcpy(&count, reader.data() + 80, 4);
    binary_stl = 84 + 50 * static_cast<std::uint64_t>(count) == reader.file_size();
  }
  if (binary_stl && format_of_extension(path) == FileFormat::stl) return FileFormat::stl;
  if (starts_with(head, "ply\n") || starts_with(head, "ply\r\n")) return FileFormat::ply;
  if (starts_with(head, "DRACO")) return FileFormat::drc;
  if (binary_stl) return FileFormat::stl;
  // Text formats are recognized by content whatever the extension says; only bytes that are neither (a
  // damaged binary file) fall back on the extension.
  bool text = true;
  for (char c : head) {
    const auto u = static_cast<unsigned char>(c);
    if ((u < 0x20 && !std::isspace(u)) || u == 0x7f) text = false;
  }
  std::size_t first = starts_with(head, "\xEF\xBB\xBF") ? 3 : 0;  // UTF-8 byte order mark
  while (first < head.size() && std::isspace(static_cast<unsigned char>(head[first]))) ++first;
  const std::string_view rest = head.substr(first);
  std::string lowered(rest.substr(0, 5));
  std::transform(lowered.begin(), lowered.end(), lowered.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (lowered == "solid") {
    // ASCII STL; or a binary STL with a "solid" header whose count is off, which its reader will report.
    const auto by_name = format_of_extension(path);
    if (text || !by_name || *by_name == FileFormat::stl) return FileFormat::stl;
  }
  // A malformed PLY too: let its parser say what is wrong. (A text editor may have put a byte order mark
  // before an ASCII one.)
  if (starts_with(head.substr(starts_with(head, "\xEF\xBB\xBF") ? 3 : 0), "ply")) return FileFormat::ply;
  // OBJ has no magic: accept text that starts with an OBJ statement or a comment.
  if (text) {
    for (std::string_view keyword : {"v ", "v\t", "vn ", "vn\t", "vt ", "vt\t", "vp ", "f ", "f\t", "#", "o ",
                                     "g ", "s ", "l ", "p ", "mtllib", "usemtl"}) {
      if (starts_with(rest, keyword)) return FileFormat::obj;
    }
  }
  if (auto by_name = format_of_extension(path)) return *by_name;
  throw Error(path, FilePosition::byte(0), "unrecognized file format (not PLY, OBJ, STL or Draco)");
}

std::uint64_t triangles_hint(const std::string& path) {
  try {
    switch (detect_format(path)) {
      case FileFormat::ply:
        return detail::ply_triangles_hint(path);
      case FileFormat::obj:
        return detail::ByteReader(path, 1 << 12).file_size() / 40;
      case FileFormat::stl:
      case FileFormat::drc:
        return 0;
    }
  } catch (const Error&) {
    // The reader says what is wrong when the file is opened.
  }
  return 0;
}

std::unique_ptr<TriangleStream> open_triangle_stream(const std::string& path, const ReadOptions& options) {
  const FileFormat format = detect_format(path);
  if (options.memory_budget > 0 && !options.vertex_sink) {
    if (auto stream = detail::open_within_budget(path, format, options)) return stream;
  }
  switch (format) {
    case FileFormat::ply:
      return detail::open_ply_stream(path, options);
    case FileFormat::obj:
      return detail::open_obj_stream(path, options);
    case FileFormat::stl:
      return detail::open_stl_stream(path, options);
    case FileFormat::drc:
      return detail::open_drc_stream(path, options);
  }
  throw Error(path, {}, "unsupported format");
}

namespace {

IndexedMesh drain(TriangleStream& source) {
  TriangleStream* stream = &source;
  const std::string& path = source.path();
  IndexedMesh mesh;
  TriangleBatch batch;
  if (stream->indexed()) {
    // The header's count is only a hint: reserve no more than the file's size could hold (8 bytes is the
    // shortest face record of any format), and grow past it only as the data proves itself.
    std::vector<Triangle> triangles;
    triangles.reserve(std::min<std::uint64_t>(stream->triangles_hint(), stream->bytes_total() / 8));
    while (stream->next(batch))
      triangles.insert(triangles.end(), batch.triangles.begin(), batch.triangles.end());
    // The stream is exhausted, so its vertex array can be taken rather than copied.
    mesh = std::move(stream->scratch_vertices());
    mesh.triangles = std::move(triangles);
  } else {
    mesh.origin = stream->vertices().origin;  // a soup's corners are relative to it too
    std::unordered_map<PositionKey, Index, PositionKeyHash> index_of;
    while (stream->next(batch)) {
      for (std::size_t i = 0; i < batch.corners.size(); ++i) {
        Triangle t;
        for (int k = 0; k < 3; ++k) {
          const Vec3f& p = batch.corners[i][k];
          const PositionKey key(p);
          auto [it, inserted] = index_of.try_emplace(key, static_cast<Index>(mesh.positions.size()));
          if (inserted) {
            if (mesh.positions.size() >= std::numeric_limits<Index>::max()) {
              throw Error(path, {}, "more than 2^32-1 distinct vertices");
            }
            // A welded vertex takes the attributes of its first corner.
            mesh.positions.push_back(p);
            if (!batch.corner_normals.empty()) mesh.normals.push_back(batch.corner_normals[i][k]);
            if (!batch.corner_colors.empty()) mesh.colors.push_back(batch.corner_colors[i][k]);
            if (!batch.corner_uvs.empty()) mesh.uvs.push_back(batch.corner_uvs[i][k]);
          }
          t[k] = it->second;
        }
        mesh.triangles.push_back(t);
      }
    }
  }
  return mesh;
}

}  // namespace

IndexedMesh read_mesh(const std::string& path, const ReadOptions& options) {
  std::unique_ptr<TriangleStream> stream = open_triangle_stream(path, options);
  IndexedMesh mesh = drain(*stream);
  if (options.faces_required && mesh.triangles.empty()) throw Error(path, {}, "the mesh has no faces");
  return mesh;
}

IndexedMesh read_mesh(TriangleStream& stream) {
  IndexedMesh mesh = drain(stream);
  if (mesh.triangles.empty()) throw Error(stream.path(), {}, "the mesh has no faces");
  return mesh;
}

bool holds_origin(FileFormat format) {
  return format == FileFormat::ply || format == FileFormat::obj;
}

void write_mesh(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options) {
  const FileFormat format = options.format ? *options.format : format_from_extension(path);
  // PLY and OBJ wrote it into every coordinate, which the readers then refused.
  if (!mesh.origin.allFinite()) throw Error(path, {}, "the mesh's origin is not a finite point");
  if (!holds_origin(format) && mesh.origin != Vec3d::Zero()) {
    // STL and Draco hold float coordinates only: they get the nearest floats to the true positions.
    IndexedMesh placed = mesh;
    for (Vec3f& p : placed.positions) p = nearest_float(mesh.origin + p.cast<double>());
    placed.origin = Vec3d::Zero();
    return write_mesh(path, placed, options);
  }
  switch (format) {
    case FileFormat::ply:
      return detail::write_ply(path, mesh, options);
    case FileFormat::obj:
      return detail::write_obj(path, mesh, options);
    case FileFormat::stl:
      return detail::write_stl(path, mesh, options);
    case FileFormat::drc:
      return detail::write_drc(path, mesh, options);
  }
  // A value outside the enum (a cast): nothing was written, which must not pass for success.
  throw Error(path, {}, "unknown output format " + std::to_string(static_cast<int>(format)));
}

}  // namespace ocsimp
