// PLY output: PlyStreamWriter emits records as they come; write_ply() feeds it a whole mesh.
//
// The header is fixed by the layout (float positions, or double ones for a mesh with an origin; float
// normals, uchar RGBA colors, float u v, faces as `property list uchar int vertex_indices`, or uint indices
// past 2^31-1 vertices) and holds nothing variable, so identical meshes give identical files. Ascii numbers
// use std::to_chars' shortest form, which reads back to the same value.

#include "ocsimp/streaming/ply_writer.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>

#include "formats.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/atomic_file.h"
#include "text_io.h"

namespace ocsimp {
namespace {

// Room for the longest ascii vertex: 3 doubles of at most 24 characters, 5 floats of at most 15, 4 bytes of 3
// digits, separators.
constexpr std::size_t kMaxAsciiRecord = 256;

template <class T>
char* put_le(char* out, T value) {
  if constexpr (std::endian::native == std::endian::big && sizeof(T) == 4) {
    std::uint32_t bits;
    std::memcpy(&bits, &value, 4);
    bits = __builtin_bswap32(bits);
    std::memcpy(out, &bits, 4);
  } else if constexpr (std::endian::native == std::endian::big && sizeof(T) == 8) {
    std::uint64_t bits;
    std::memcpy(&bits, &value, 8);
    bits = __builtin_bswap64(bits);
    std::memcpy(out, &bits, 8);
  } else {
    std::memcpy(out, &value, sizeof(T));
  }
  return out + sizeof(T);
}

char* put_text(char* out, float value) {
  // Shortest form that reads back to the same float: at most 9 significant digits, so 15 characters
  // ("-1.17549435e-38").
  return std::to_chars(out, out + 16, value).ptr;
}

char* put_text(char* out, std::uint32_t value) {
  return std::to_chars(out, out + 10, value).ptr;
}

bool indices_need_uint(const PlyLayout& layout) {
  return layout.vertices > static_cast<std::uint64_t>(std::numeric_limits<std::int32_t>::max());
}

std::string make_header(const PlyLayout& layout) {
  std::string header = "ply\n";
  header += layout.ascii ? "format ascii 1.0\n" : "format binary_little_endian 1.0\n";
  header += "comment written by ocsimp\n";
  header += "element vertex " + std::to_string(layout.vertices) + "\n";
  header += layout.origin == Vec3d::Zero() ? "property float x\nproperty float y\nproperty float z\n"
                                           : "property double x\nproperty double y\nproperty double z\n";
  if (layout.normals) header += "property float nx\nproperty float ny\nproperty float nz\n";
  if (layout.colors) {
    header += "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n";
  }
  if (layout.uvs) header += "property float u\nproperty float v\n";
  header += "element face " + std::to_string(layout.faces) + "\n";
  header += indices_need_uint(layout) ? "property list uchar uint vertex_indices\n"
                                      : "property list uchar int vertex_indices\n";
  header += "end_header\n";
  return header;
}

}  // namespace

PlyStreamWriter::PlyStreamWriter(const std::string& path, const PlyLayout& layout)
    : file_(std::make_unique<AtomicFile>(path)), layout_(layout) {
  if (layout.vertices > std::numeric_limits<Index>::max()) {
    throw Error(path, {},
                "cannot write " + std::to_string(layout.vertices) + " vertices (the limit is 2^32-1)");
  }
  file_->write(make_header(layout));
}

PlyStreamWriter::~PlyStreamWriter() = default;

void PlyStreamWriter::add_vertex(const Vec3f& position, const Vec3f* normal, const Color* color,
                                 const Vec2f* uv) {
  add_vertices(&position, normal, color, uv, 1);
}

void PlyStreamWriter::add_face(const Triangle& face) {
  add_faces(&face, 1);
}

// Records are formatted straight into the file's buffer a block at a time: one buffer check per block instead
// of per record made write_mesh ~25% faster on a 10M-triangle binary file.
void PlyStreamWriter::add_vertices(const Vec3f* positions, const Vec3f* normals, const Color* colors,
                                   const Vec2f* uvs, std::size_t count) {
  if (count > layout_.vertices - vertices_written_) {
    throw Error(file_->path(), {},
                "more vertices than the " + std::to_string(layout_.vertices) + " declared");
  }
  if ((layout_.normals && normals == nullptr) || (layout_.colors && colors == nullptr) ||
      (layout_.uvs && uvs == nullptr)) {
    throw Error(file_->path(), {},
                "vertex " + std::to_string(vertices_written_) + " lacks an attribute of the layout");
  }
  const bool shifted = layout_.origin != Vec3d::Zero();
  const std::size_t record = layout_.ascii ? kMaxAsciiRecord
                                           : (shifted ? 24 : 12) + (layout_.normals ? 12 : 0) +
                                                 (layout_.colors ? 4 : 0) + (layout_.uvs ? 8 : 0);
  const std::size_t block = AtomicFile::buffer_capacity / record;
  for (std::size_t first = 0; first < count; first += block) {
    const std::size_t end = std::min(count, first + block);
    char* const begin = file_->reserve((end - first) * record);
    char* out = begin;
    for (std::size_t i = first; i < end; ++i) {
      const Vec3f& position = positions[i];
      if (!position.allFinite()) {
        throw Error(file_->path(), {}, "vertex " + std::to_string(vertices_written_ + i) + " is not finite");
      }
      if (layout_.ascii) {
        auto floats = [&out](const float* values, int n) {
          for (int k = 0; k < n; ++k) {
            out = put_text(out, values[k]);
            *out++ = ' ';
          }
        };
        if (shifted) {
          for (int k = 0; k < 3; ++k) {
            out = detail::print_double(out, layout_.origin[k] + double(position[k]));
            *out++ = ' ';
          }
        } else {
          floats(position.data(), 3);
        }
        if (layout_.normals) floats(normals[i].data(), 3);
        if (layout_.colors) {
          for (std::uint8_t channel : colors[i]) {
            out = put_text(out, std::uint32_t{channel});
            *out++ = ' ';
          }
        }
        if (layout_.uvs) floats(uvs[i].data(), 2);
        out[-1] = '\n';  // over the last separator
      } else {
        if (shifted) {
          for (int k = 0; k < 3; ++k) out = put_le(out, layout_.origin[k] + double(position[k]));
        } else {
          for (int k = 0; k < 3; ++k) out = put_le(out, position[k]);
        }
        if (layout_.normals) {
          for (int k = 0; k < 3; ++k) out = put_le(out, normals[i][k]);
        }
        if (layout_.colors) {
          std::memcpy(out, colors[i].data(), 4);
          out += 4;
        }
        if (layout_.uvs) {
          for (int k = 0; k < 2; ++k) out = put_le(out, uvs[i][k]);
        }
      }
    }
    file_->advance(static_cast<std::size_t>(out - begin));
  }
  vertices_written_ += count;
}

void PlyStreamWriter::add_faces(const Triangle* faces, std::size_t count) {
  if (vertices_written_ != layout_.vertices) {
    throw Error(file_->path(), {},
                "a face before all " + std::to_string(layout_.vertices) + " declared vertices were written");
  }
  if (count > layout_.faces - faces_written_) {
    throw Error(file_->path(), {}, "more faces than the " + std::to_string(layout_.faces) + " declared");
  }
  // "3 " and three indices of up to 10 digits with their separators.
  const std::size_t record = layout_.ascii ? 36 : 13;
  const std::size_t block = AtomicFile::buffer_capacity / record;
  for (std::size_t first = 0; first < count; first += block) {
    const std::size_t end = std::min(count, first + block);
    Index largest = 0;
    for (std::size_t i = first; i < end; ++i)
      largest = std::max({largest, faces[i][0], faces[i][1], faces[i][2]});
    if (largest >= layout_.vertices) {
      for (std::size_t i = first; i < end; ++i) {
        for (Index index : faces[i]) {
          if (index >= layout_.vertices) {
            throw Error(file_->path(), {},
                        "face " + std::to_string(faces_written_ + i) + " uses vertex " +
                            std::to_string(index) + " of " + std::to_string(layout_.vertices));
          }
        }
      }
    }
    char* const begin = file_->reserve((end - first) * record);
    char* out = begin;
    if (layout_.ascii) {
      for (std::size_t i = first; i < end; ++i) {
        *out++ = '3';
        for (Index index : faces[i]) {
          *out++ = ' ';
          out = put_text(out, index);
        }
        *out++ = '\n';
      }
    } else {
      for (std::size_t i = first; i < end; ++i) {
        *out++ = 3;
        for (Index index : faces[i]) out = put_le(out, index);
      }
    }
    file_->advance(static_cast<std::size_t>(out - begin));
  }
  faces_written_ += count;
}

void PlyStreamWriter::finish() {
  if (vertices_written_ != layout_.vertices || faces_written_ != layout_.faces) {
    throw Error(file_->path(), {},
                "incomplete PLY: " + std::to_string(vertices_written_) + " of " +
                    std::to_string(layout_.vertices) + " vertices and " + std::to_string(faces_written_) +
                    " of " + std::to_string(layout_.faces) + " faces written");
  }
  file_->commit();
}

std::uint64_t PlyStreamWriter::bytes_written() const {
  return file_->bytes_written();
}

namespace detail {

void write_ply(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options) {
  const std::size_t n = mesh.positions.size();
  auto check = [&](std::size_t size, const char* what) {
    if (size != 0 && size != n) {
      throw Error(
          path, {},
          "the mesh has " + std::to_string(size) + " " + what + " for " + std::to_string(n) + " vertices");
    }
    return size != 0;
  };
  PlyLayout layout;
  layout.vertices = n;
  layout.faces = mesh.triangles.size();
  layout.normals = check(mesh.normals.size(), "normals");
  layout.colors = check(mesh.colors.size(), "colors");
  layout.uvs = check(mesh.uvs.size(), "uvs");
  layout.ascii = options.ascii;
  layout.origin = mesh.origin;

  PlyStreamWriter writer(path, layout);
  writer.add_vertices(mesh.positions.data(), layout.normals ? mesh.normals.data() : nullptr,
                      layout.colors ? mesh.colors.data() : nullptr, layout.uvs ? mesh.uvs.data() : nullptr,
                      n);
  constexpr std::size_t kProgressFaces = 1 << 20;
  for (std::size_t first = 0; first < mesh.triangles.size(); first += kProgressFaces) {
    const std::size_t count = std::min(kProgressFaces, mesh.triangles.size() - first);
    writer.add_faces(mesh.triangles.data() + first, count);
    if (first + count < layout.faces) report(options.progress, "write", first + count, layout.faces);
  }
  // Before the commit: a callback that throws (a cancel) must leave no file behind.
  report(options.progress, "write", layout.faces, layout.faces);
  writer.finish();
}

}  // namespace detail
}  // namespace ocsimp
