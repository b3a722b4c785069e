// The PLY header: its property types, its elements, and the parser that reads it. Shared by the PLY reader
// and its tests; the writer emits fixed headers and does not need it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "byte_reader.h"

namespace ocsimp::detail {

// The eight numeric types of PLY 1.0. Both spellings are accepted ("uchar" and "uint8", "float" and
// "float32"...).
enum class PlyType : std::uint8_t { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

std::size_t ply_type_size(PlyType type);
const char* ply_type_name(PlyType type);
inline bool ply_type_is_integer(PlyType type) {
  return type < PlyType::float32;
}
inline bool ply_type_is_signed(PlyType type) {
  return type == PlyType::int8 || type == PlyType::int16 || type == PlyType::int32;
}
std::optional<PlyType> parse_ply_type(std::string_view name);

enum class PlyEncoding { ascii, binary_little_endian, binary_big_endian };

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::float32;  // the scalar's type, or the type of a list's items
  bool is_list = false;
  PlyType count_type = PlyType::uint8;  // lists only: the type of the leading item count
  std::uint64_t header_line = 0;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  std::uint64_t header_line = 0;

  // Index of the property called `name`, if any.
  std::optional<std::size_t> find(std::string_view property_name) const;
  bool has_lists() const;
  // Bytes per record in a binary file: exact without lists, a lower bound with them (lists counted empty).
  std::size_t min_binary_size() const;
};

struct PlyHeader {
  PlyEncoding encoding = PlyEncoding::ascii;
  std::vector<PlyElement> elements;
  std::uint64_t data_offset = 0;  // byte just past the end_header line
  std::uint64_t data_line = 0;    // number of the first line after end_header (ascii)
  // The images named by "comment TextureFile NAME" lines (MeshLab's and VCG's convention).
  std::vector<std::string> texture_files;
};

// Reads the header from the start of `reader` and leaves the reader at data_offset. Throws Error naming the
// header line on anything malformed: wrong magic, unknown format or type, a negative or non-numeric count,
// a property outside an element, a duplicate property, a missing end_header. Lines may end in CRLF; comment
// and obj_info lines are skipped.
PlyHeader parse_ply_header(ByteReader& reader);

}  // namespace ocsimp::detail
