// The PLY reader: a TriangleStream over ascii, binary_little_endian and binary_big_endian files of any
// element and property layout.
//
// The vertex element is decoded once, in the constructor, into an IndexedMesh; faces are then decoded batch
// by batch. Elements other than "vertex" and "face" (or "tristrips") are skipped. When the face element
// precedes the vertex element, a first pass walks past the faces (checking their structure) to reach the
// vertices, then seeks back, so memory never holds more than the vertices and one batch.
//
// Texture coordinates given per face corner (a face list "texcoord" of u v pairs, as MeshLab writes a
// textured mesh) take one more pass over the faces before the vertices are handed out: each vertex gets
// those of the first corner that references it, as OBJ's vt do, so a vertex on a uv seam keeps one side's.
//
// Common layouts take fast paths: vertex records of exactly float x,y,z are copied in bulk, binary face
// records that hold only an int/uint index list are decoded at fixed offsets while their count is 3, and
// ascii numbers are parsed in place (fast_float for reals, by hand for integers). Everything else goes
// through a general path that reads one value at a time and can stop mid-polygon when a batch is full.
//
// Nothing is allocated from a header count until the data has shown it can hold it: fixed-size binary vertex
// records are checked against the file size first, other layouts reserve what the remaining bytes could hold
// at the least and grow; faces are streamed.

#include <fast_float/fast_float.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <tuple>

#include "byte_reader.h"
#include "formats.h"
#include "ocsimp/core/error.h"
#include "origin_sample.h"
#include "ply_header.h"
#include "polygon.h"

namespace ocsimp::detail {
namespace {

// Large enough that read(2) costs little per byte, small enough to stay in cache between the kernel's copy
// and our parse: draining a 10M-triangle binary file took 37 ms of CPU with 1 MiB, 41-43 ms with 64-256 KiB
// and 42+ ms with 4 MiB. Also the longest ascii line we accept.
constexpr std::size_t kBufferBytes = 1 << 20;
constexpr std::uint64_t kProgressBytes = 8 << 20;

// ---- Binary loads ----------------------------------------------------------------------------------------

template <class T>
T byte_swapped(T value) {
  if constexpr (sizeof(T) == 1) {
    return value;
  } else {
    using Bits = std::conditional_t<sizeof(T) == 2, std::uint16_t,
                                    std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>;
    Bits bits;
    std::memcpy(&bits, &value, sizeof bits);
    if constexpr (sizeof(T) == 2) bits = __builtin_bswap16(bits);
    if constexpr (sizeof(T) == 4) bits = __builtin_bswap32(bits);
    if constexpr (sizeof(T) == 8) bits = __builtin_bswap64(bits);
    std::memcpy(&value, &bits, sizeof bits);
    return value;
  }
}

template <class T, bool Swap>
T load(const char* p) {
  T value;
  std::memcpy(&value, p, sizeof value);
  if constexpr (Swap) value = byte_swapped(value);
  return value;
}

template <bool Swap>
double load_number(const char* p, PlyType type) {
  switch (type) {
    case PlyType::int8:
      return load<std::int8_t, Swap>(p);
    case PlyType::uint8:
      return load<std::uint8_t, Swap>(p);
    case PlyType::int16:
      return load<std::int16_t, Swap>(p);
    case PlyType::uint16:
      return load<std::uint16_t, Swap>(p);
    case PlyType::int32:
      return load<std::int32_t, Swap>(p);
    case PlyType::uint32:
      return load<std::uint32_t, Swap>(p);
    case PlyType::float32:
      return load<float, Swap>(p);
    case PlyType::float64:
      return load<double, Swap>(p);
  }
  return 0;
}

// Narrowing that saturates to +-inf instead of being undefined outside float's range.
float to_float(double value) {
  if (value > std::numeric_limits<float>::max()) return std::numeric_limits<float>::infinity();
  if (value < -std::numeric_limits<float>::max()) return -std::numeric_limits<float>::infinity();
  return static_cast<float>(value);
}

// An integer-valued double in [-2^63, 2^63) as an integer; nullopt for fractions, NaN and huge values.
std::optional<std::int64_t> exact_integer(double value) {
  if (!(value >= -9.2e18 && value <= 9.2e18)) return std::nullopt;
  const auto integer = static_cast<std::int64_t>(value);
  if (static_cast<double>(integer) != value) return std::nullopt;
  return integer;
}

// The values an integer type holds (the widest for floating-point types).
std::pair<std::int64_t, std::int64_t> integer_range(PlyType type) {
  switch (type) {
    case PlyType::int8:
      return {INT8_MIN, INT8_MAX};
    case PlyType::uint8:
      return {0, UINT8_MAX};
    case PlyType::int16:
      return {INT16_MIN, INT16_MAX};
    case PlyType::uint16:
      return {0, UINT16_MAX};
    case PlyType::int32:
      return {INT32_MIN, INT32_MAX};
    case PlyType::uint32:
      return {0, UINT32_MAX};
    case PlyType::float32:
    case PlyType::float64:
      break;
  }
  return {INT64_MIN, INT64_MAX};
}

// The value that means full intensity in a color channel of this type: 65535 for ushort, the one wider
// integer encoding of color in use (16-bit PNG and TIFF channels); 255 for every other integer type, which
// turns up where a writer stores every number as one type, with 0..255 in it (read over the type's range,
// an int's 255 came out black); 1 for floating point.
double color_span(PlyType type) {
  return !ply_type_is_integer(type) ? 1.0 : type == PlyType::uint16 ? 65535.0 : 255.0;
}

std::uint8_t color_channel(double value, PlyType type) {
  const double unit = value / color_span(type);
  if (!(unit > 0.0)) return 0;
  if (unit >= 1.0) return 255;
  return static_cast<std::uint8_t>(std::lround(unit * 255.0));
}

// Grows lo/hi (3 floats each) over n packed x y z triples. Returns the index of the first point with a NaN or
// infinite coordinate, or n. Takes 4 points (12 floats, three 4-float vectors) at a time: a per-point loop
// made this check cost as much as reading the vertices, and GCC does not vectorize the plain 12-lane loop.
using Float4 = float __attribute__((vector_size(16)));

std::size_t scan_points(const float* xyz, std::size_t n, float* lo, float* hi) {
  // Lane k of vector j holds coordinate (4 j + k) % 3.
  Float4 lo_v[3] = {{lo[0], lo[1], lo[2], lo[0]}, {lo[1], lo[2], lo[0], lo[1]}, {lo[2], lo[0], lo[1], lo[2]}};
  Float4 hi_v[3] = {{hi[0], hi[1], hi[2], hi[0]}, {hi[1], hi[2], hi[0], hi[1]}, {hi[2], hi[0], hi[1], hi[2]}};
  Float4 nonfinite = {0, 0, 0, 0};  // v - v is 0 for finite v and NaN for inf or NaN; NaN then sticks
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    for (int j = 0; j < 3; ++j) {
      Float4 v;
      std::memcpy(&v, xyz + 3 * i + 4 * j, sizeof v);
      lo_v[j] = v < lo_v[j] ? v : lo_v[j];
      hi_v[j] = v > hi_v[j] ? v : hi_v[j];
      nonfinite += v - v;
    }
  }
  bool special = false;
  for (int k = 0; k < 4; ++k) special |= nonfinite[k] != 0;
  for (int j = 0; j < 3; ++j) {
    for (int k = 0; k < 4; ++k) {
      lo[(4 * j + k) % 3] = std::min(lo[(4 * j + k) % 3], lo_v[j][k]);
      hi[(4 * j + k) % 3] = std::max(hi[(4 * j + k) % 3], hi_v[j][k]);
    }
  }
  for (; i < n; ++i) {
    for (int k = 0; k < 3; ++k) {
      const float v = xyz[3 * i + k];
      special |= !std::isfinite(v);
      lo[k] = std::min(lo[k], v);
      hi[k] = std::max(hi[k], v);
    }
  }
  if (special) {
    for (std::size_t j = 0; j < 3 * n; ++j) {
      if (!std::isfinite(xyz[j])) return j / 3;
    }
  }
  return n;
}

// ---- Vertex properties we keep ----------------------------------------------------------------------------

enum class Slot : std::uint8_t { none, x, y, z, nx, ny, nz, red, green, blue, alpha, u, v };

// What color_check says of a color channel outside its type's span (color_span).
enum class ColorCheck : std::uint8_t { in_range, clamped, not_finite };

struct VertexValues {
  double position[3] = {0, 0, 0};  // as read: made relative to the origin before narrowing to float
  float normal[3] = {0, 0, 0};
  Color color = {0, 0, 0, 255};
  ColorCheck color_check[4] = {};  // set with each channel's value
  float uv[2] = {0, 0};
};

void set_value(VertexValues& values, Slot slot, PlyType type, double value) {
  switch (slot) {
    case Slot::none:
      break;
    case Slot::x:
    case Slot::y:
    case Slot::z:
      values.position[int(slot) - int(Slot::x)] = value;
      break;
    case Slot::nx:
    case Slot::ny:
    case Slot::nz:
      values.normal[int(slot) - int(Slot::nx)] = to_float(value);
      break;
    case Slot::red:
    case Slot::green:
    case Slot::blue:
    case Slot::alpha:
      values.color[int(slot) - int(Slot::red)] = color_channel(value, type);
      values.color_check[int(slot) - int(Slot::red)] = value >= 0.0 && value <= color_span(type)
                                                           ? ColorCheck::in_range
                                                       : std::isfinite(value) ? ColorCheck::clamped
                                                                              : ColorCheck::not_finite;
      break;
    case Slot::u:
    case Slot::v:
      values.uv[int(slot) - int(Slot::u)] = to_float(value);
      break;
  }
}

// Where each property of the vertex element goes. Attributes are kept only when complete (all of nx ny nz,
// all of red green blue, both texture coordinates).
struct VertexPlan {
  std::vector<Slot> slots;  // one per property
  bool normals = false, colors = false, uvs = false;
};

VertexPlan plan_vertices(const std::string& path, const PlyElement& element) {
  VertexPlan plan;
  plan.slots.assign(element.properties.size(), Slot::none);
  auto scalar = [&](std::string_view name) -> std::optional<std::size_t> {
    auto index = element.find(name);
    if (index && element.properties[*index].is_list) return std::nullopt;
    return index;
  };
  for (const char* axis : {"x", "y", "z"}) {
    const auto index = element.find(axis);
    if (!index) {
      throw Error(path, FilePosition::line(element.header_line),
                  std::string("the vertex element has no property ") + axis);
    }
    if (element.properties[*index].is_list) {
      throw Error(path, FilePosition::line(element.properties[*index].header_line),
                  std::string("vertex property ") + axis + " is a list, not a number");
    }
  }
  // Assigns `slots` to the first spelling whose every name is a scalar property.
  auto assign = [&](std::initializer_list<std::initializer_list<const char*>> spellings,
                    std::initializer_list<Slot> slots) {
    for (const auto& names : spellings) {
      std::vector<std::size_t> found;
      for (const char* name : names) {
        if (auto index = scalar(name)) found.push_back(*index);
      }
      if (found.size() != names.size()) continue;
      auto slot = slots.begin();
      for (std::size_t index : found) plan.slots[index] = *slot++;
      return true;
    }
    return false;
  };
  assign({{"x", "y", "z"}}, {Slot::x, Slot::y, Slot::z});
  plan.normals = assign({{"nx", "ny", "nz"}}, {Slot::nx, Slot::ny, Slot::nz});
  plan.colors = assign({{"red", "green", "blue"}, {"diffuse_red", "diffuse_green", "diffuse_blue"}},
                       {Slot::red, Slot::green, Slot::blue});
  if (plan.colors) {
    if (auto alpha = scalar("alpha"))
      plan.slots[*alpha] = Slot::alpha;
    else if (auto diffuse_alpha = scalar("diffuse_alpha"))
      plan.slots[*diffuse_alpha] = Slot::alpha;
  }
  plan.uvs = assign({{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}, {"texture_s", "texture_t"}},
                    {Slot::u, Slot::v});
  return plan;
}

// ---- The stream
// ---------------------------------------------------------------------------------------------

// The face element's list of corners, under either of its usual names.
std::optional<std::size_t> index_list(const PlyElement& faces) {
  const auto list = faces.find("vertex_indices");
  return list ? list : faces.find("vertex_index");
}

// A face element's count is only a hint: bound it by what the data could hold at the smallest record, so
// no one plans for the 10^15 faces a header may claim.
std::uint64_t bounded_face_count(const PlyElement& faces, const PlyProperty& index, bool ascii,
                                 std::uint64_t data_bytes) {
  const std::uint64_t min_face_bytes =
      ascii ? 8 : ply_type_size(index.count_type) + 3 * ply_type_size(index.type);
  return std::min(faces.count, data_bytes / min_face_bytes);
}

class PlyStream final : public TriangleStream {
 public:
  PlyStream(const std::string& path, const ReadOptions& options);

  bool next(TriangleBatch& batch) override;
  const IndexedMesh& vertices() const override { return vertices_; }
  Box3 bounds() override { return bounds_; }
  std::uint64_t triangles_hint() const override { return triangles_hint_; }
  std::uint64_t bytes_read() const override;
  std::uint64_t bytes_total() const override { return bytes_total_; }
  const std::string& path() const override { return reader_.path(); }
  // Out of core the vertices go to the sink as they load, before per-corner texture coordinates are read.
  std::string attributes_left_out() const override {
    return vertex_sink_ && wedge_property_ ? attribute_list(false, false, true) : std::string();
  }

 private:
  // -- positions for errors
  std::uint64_t byte_position() const {
    return ascii_ ? reader_.offset() + static_cast<std::uint64_t>(cursor_ - reader_.data())
                  : reader_.offset();
  }
  [[noreturn]] void fail(const std::string& reason) const {
    if (ascii_) throw Error(path(), FilePosition::line(line_), reason);
    throw Error(path(), FilePosition::byte(reader_.offset()), reason);
  }
  [[noreturn]] void fail_at_byte(std::uint64_t offset, const std::string& reason) const {
    throw Error(path(), FilePosition::byte(offset), reason);
  }
  [[noreturn]] void fail_truncated() const;
  std::string where() const;  // "record R of element 'NAME'"

  // -- binary input
  const char* need(std::size_t bytes) {
    if (reader_.available() < bytes && reader_.fill(bytes) < bytes) fail_truncated();
    return reader_.data();
  }
  void skip_bytes(std::uint64_t bytes);

  // -- ascii input: `cursor_` walks complete lines in [reader_.data(), lines_end_)
  bool begin_ascii_record();  // false at the end of the file
  void end_ascii_record();
  void refill_lines();
  std::string_view ascii_token(PlyType type);
  double ascii_number(PlyType type);
  std::int64_t ascii_integer(PlyType type);
  std::int64_t ascii_integer_slow(PlyType type);
  void read_ascii_triangles();
  void skip_ascii_spaces() {
    while (cursor_ < lines_end_ && (*cursor_ == ' ' || *cursor_ == '\t' || *cursor_ == '\r')) ++cursor_;
  }

  // -- values of either encoding
  double read_number(PlyType type);
  std::int64_t read_integer(PlyType type, const char* what);
  std::uint64_t read_list_count(const PlyProperty& property);
  void skip_property(const PlyProperty& property);

  // -- elements
  void begin_record();
  void end_record();
  void skip_element(std::size_t element);
  void load_vertices();
  template <bool Swap>
  void load_fixed_vertices(const std::vector<std::size_t>& offsets);
  void load_positions_directly();
  void load_vertex_records();
  void add_vertex(std::size_t index, const VertexValues& values, std::uint64_t offset);
  // Chooses the origin from the vertices held for it (OriginSample::settle).
  void settle_origin();
  // Hands the positions read so far to the sink, when there is one and the origin is chosen.
  void flush_vertices();
  void check_end_of_data();
  void report_progress(bool final = false);

  // -- faces
  void read_face_values();
  void check_corner(std::int64_t index, std::uint64_t offset) const;
  void add_corner(std::int64_t index, std::uint64_t offset);
  void emit_polygon();
  void load_wedge_uvs();
  void rewind_to_faces();
  template <class CountT, class IndexT, bool Swap>
  void read_triangle_records();
  bool read_fast_faces();
  void finish_faces();

  detail::ByteReader reader_;
  ProgressFn progress_;
  std::function<void(const std::string&)> warn_;
  // What the file holds that no output keeps (unread_note, colors finer than 8 bits), said once every face is
  // read: a file that then fails got the warning and its error both.
  std::vector<std::string> notes_at_end_;
  std::uint64_t clamped_colors_ = 0;  // vertices with a color channel outside its color_span
  std::uint64_t concave_fans_ = 0;    // polygons polygon_triangles fanned though concave
  bool integer_colors_ = false;       // the red channel's type is an integer, for the note on clamped ones
  std::function<void(const VertexChunk&)> vertex_sink_;  // out of core: vertices go there, not kept
  // Unless x y z are of double or 32-bit integer type (more precise than floats far from zero), settled from
  // the start: the origin stays zero.
  OriginSample origin_sample_;
  std::size_t capacity_;
  PlyHeader header_;
  bool ascii_ = false;
  bool swap_ = false;  // the file's byte order is not ours

  IndexedMesh vertices_;
  // Triangle strips do not say how many triangles they make. Every strip index past a strip's first two adds
  // at most one, so the index count bounds it: in a binary file, the bytes the other elements leave (when
  // their records have a fixed size) over the index size; otherwise, or in ascii, no hint.
  std::uint64_t strip_triangles_bound(const PlyElement& strips, std::uint64_t data_bytes) const {
    if (ascii_) return 0;
    std::uint64_t other_bytes = 0;
    for (const PlyElement& element : header_.elements) {
      if (&element == &strips) continue;
      if (element.has_lists()) return 0;
      const std::uint64_t size = element.min_binary_size();
      if (size > 0 && element.count > (data_bytes - other_bytes) / size) return 0;
      other_bytes += element.count * size;
    }
    const PlyProperty& list = strips.properties[index_property_];
    const std::uint64_t record = strips.min_binary_size();
    if (strips.count > (data_bytes - other_bytes) / record) return 0;  // record >= the list's count
    const std::uint64_t index_bytes = data_bytes - other_bytes - strips.count * record;
    return index_bytes / ply_type_size(list.type);
  }

  Box3 bounds_;
  VertexPlan vertex_plan_;
  std::size_t vertex_element_ = 0;
  std::uint64_t vertex_count_ = 0;

  std::size_t face_element_ = 0;
  std::size_t index_property_ = 0;
  bool strips_ = false;       // "tristrips": one long list, -1 ends a strip
  bool faces_first_ = false;  // the face element comes before the vertex element
  bool fast_faces_ = false;   // the face record is just the index list
  std::uint64_t face_offset_ = 0, face_line_ = 0, face_bytes_ = 0;
  std::optional<std::size_t> wedge_property_;  // the face element's per-corner "texcoord" list
  // ReadOptions::split_corner_attributes: the corners whose texcoord disagrees with their vertex's first, in
  // file order, with the copy of the vertex each reads instead; the faces meet them in that order, so a
  // cursor finds each (next_copy_).
  struct CornerCopy {
    std::uint64_t record, corner;
    Index copy;
  };
  bool split_ = false;
  std::vector<CornerCopy> corner_copies_;
  std::size_t next_copy_ = 0;
  std::uint64_t triangles_hint_ = 0;
  std::uint64_t bytes_total_ = 0;

  // The element being read, for error messages and ascii record counts.
  std::size_t current_element_ = 0;
  std::uint64_t current_record_ = 0;

  // The batch being filled by next().
  Triangle* out_ = nullptr;
  std::size_t filled_ = 0;

  // Face decoding state, kept across batches: we may stop in the middle of a record.
  bool in_record_ = false;
  std::size_t next_property_ = 0;
  std::uint64_t list_left_ = 0;
  bool in_list_ = false;
  std::int64_t first_corner_ = 0, previous_corner_ = 0;  // fan: first and previous corner
  std::uint64_t corners_seen_ = 0;                       // in this polygon or strip
  // A polygon of more than three corners, gathered whole when its positions are at hand and cut in its
  // plane (see polygon.h); its triangles beyond the batch wait in `pending_` for the next one.
  std::uint64_t polygon_size_ = 0;
  std::vector<Index> polygon_;
  PolygonScratch polygon_scratch_;
  std::vector<Triangle> pending_;
  std::size_t pending_next_ = 0;
  std::int64_t strip_before_ = 0;  // strips: the corner before previous_corner_
  std::uint64_t triangles_emitted_ = 0;
  bool faces_done_ = false;
  // Bytes read by earlier passes beyond the present position (the faces read again after a pass over them).
  std::uint64_t reread_bytes_ = 0;

  // Ascii cursor.
  const char* cursor_ = nullptr;
  const char* lines_end_ = nullptr;
  bool file_end_ = false;  // lines_end_ is the end of the file, not of a line
  std::uint64_t line_ = 0;

  std::uint64_t next_progress_ = kProgressBytes;
};

PlyStream::PlyStream(const std::string& path, const ReadOptions& options)
    : reader_(path, kBufferBytes),
      progress_(options.progress),
      warn_(options.warn),
      vertex_sink_(options.vertex_sink),
      capacity_(std::max<std::size_t>(options.batch_capacity, 1)) {
  split_ = options.split_corner_attributes && !options.vertex_sink;
  header_ = parse_ply_header(reader_);
  ascii_ = header_.encoding == PlyEncoding::ascii;
  swap_ = !ascii_ &&
          ((header_.encoding == PlyEncoding::binary_big_endian) != (std::endian::native == std::endian::big));
  line_ = header_.data_line;
  cursor_ = lines_end_ = reader_.data();
  const std::uint64_t end_header_line = header_.data_line - 1;

  auto find_element = [&](std::string_view name) -> std::optional<std::size_t> {
    for (std::size_t i = 0; i < header_.elements.size(); ++i) {
      if (header_.elements[i].name == name) return i;
    }
    return std::nullopt;
  };
  const auto vertex = find_element("vertex");
  if (!vertex)
    throw Error(path, FilePosition::line(end_header_line), "the header declares no vertex element");
  vertex_element_ = *vertex;
  const PlyElement& vertex_element = header_.elements[vertex_element_];
  vertex_count_ = vertex_element.count;
  if (vertex_count_ > std::numeric_limits<Index>::max()) {
    throw Error(path, FilePosition::line(vertex_element.header_line),
                "element vertex " + std::to_string(vertex_count_) + " is more than 2^32-1 vertices");
  }
  vertex_plan_ = plan_vertices(path, vertex_element);
  for (std::size_t i = 0; i < vertex_plan_.slots.size(); ++i) {
    const Slot slot = vertex_plan_.slots[i];
    const PlyType type = vertex_element.properties[i].type;
    if ((slot == Slot::x || slot == Slot::y || slot == Slot::z) &&
        (type == PlyType::float64 || type == PlyType::int32 || type == PlyType::uint32)) {
      origin_sample_.settled = false;
    }
  }

  auto face = find_element("face");
  if (!face) {
    face = find_element("tristrips");
    strips_ = face.has_value();
  }
  if (!face) {
    throw Error(path, FilePosition::line(end_header_line),
                "the header declares no face element (a point cloud is not a mesh)");
  }
  face_element_ = *face;
  const PlyElement& face_element = header_.elements[face_element_];
  const auto list = index_list(face_element);
  if (!list) {
    throw Error(path, FilePosition::line(face_element.header_line),
                "element " + face_element.name + " has no vertex_indices list");
  }
  index_property_ = *list;
  const PlyProperty& index_property = face_element.properties[index_property_];
  if (!index_property.is_list) {
    throw Error(path, FilePosition::line(index_property.header_line),
                "property " + index_property.name + " must be a list");
  }
  if (face_element.count == 0 && options.faces_required) {
    throw Error(path, FilePosition::line(face_element.header_line),
                "element " + face_element.name + " is empty");
  }
  faces_first_ = face_element_ < vertex_element_;
  if (const auto texcoord = face_element.find("texcoord");
      texcoord && !strips_ && !vertex_plan_.uvs && face_element.properties[*texcoord].is_list) {
    wedge_property_ = texcoord;
  }
  fast_faces_ = !strips_ && face_element.properties.size() == 1 &&
                (ascii_ ? ply_type_is_integer(index_property.type)
                        : index_property.type == PlyType::int32 || index_property.type == PlyType::uint32);

  if (warn_) {
    UnreadData vertex_properties{"vertex property", "vertex properties", {}},
        face_properties{face_element.name + " property", face_element.name + " properties", {}},
        elements{"element", "elements", {}}, textures{"texture file", "texture files", {}};
    for (std::size_t i = 0; i < vertex_plan_.slots.size(); ++i) {
      if (vertex_plan_.slots[i] == Slot::none) vertex_properties.add(vertex_element.properties[i].name);
    }
    for (std::size_t i = 0; i < face_element.properties.size(); ++i) {
      if (i != index_property_ && i != wedge_property_) face_properties.add(face_element.properties[i].name);
    }
    for (std::size_t i = 0; i < header_.elements.size(); ++i) {
      if (i != vertex_element_ && i != face_element_ && header_.elements[i].count > 0)
        elements.add(header_.elements[i].name);
    }
    for (const std::string& name : header_.texture_files) textures.add(name);
    if (std::string note = unread_note({vertex_properties, face_properties, elements, textures});
        !note.empty())
      notes_at_end_.push_back(std::move(note));
    // Colors are held, and written, at 8 bits a channel: 16-bit or floating-point ones lose their low bits.
    for (std::size_t i = 0; i < vertex_plan_.slots.size(); ++i) {
      const PlyType type = vertex_element.properties[i].type;
      if (vertex_plan_.slots[i] != Slot::red) continue;
      integer_colors_ = ply_type_is_integer(type);
      if (color_span(type) != 255.0) {
        notes_at_end_.push_back(std::string("its colors, stored as ") + ply_type_name(type) +
                                ", are kept to 8 bits a channel, as every output writes them");
      }
    }
  }

  const std::uint64_t data_bytes = reader_.file_size() - header_.data_offset;
  triangles_hint_ = strips_ ? strip_triangles_bound(face_element, data_bytes)
                            : bounded_face_count(face_element, index_property, ascii_, data_bytes);
  bytes_total_ = reader_.file_size();

  std::size_t element = 0;
  for (; element < vertex_element_; ++element) {
    if (element == face_element_) {
      face_offset_ = byte_position();
      face_line_ = line_;
    }
    skip_element(element);
    if (element == face_element_) face_bytes_ = byte_position() - face_offset_;
  }
  load_vertices();
  if (faces_first_) {
    // Check the rest of the file now, then come back for the faces.
    for (++element; element < header_.elements.size(); ++element) skip_element(element);
    check_end_of_data();
    rewind_to_faces();
  } else {
    for (++element; element < face_element_; ++element) skip_element(element);
    face_offset_ = byte_position();
    face_line_ = line_;
  }
  if (wedge_property_ && !vertex_sink_) {
    load_wedge_uvs();
    face_bytes_ = byte_position() - face_offset_;
    rewind_to_faces();
  }
  current_element_ = face_element_;
  current_record_ = 0;
}

std::uint64_t PlyStream::bytes_read() const {
  return reread_bytes_ + byte_position();
}

// Back to the first face record, for another pass over the faces.
void PlyStream::rewind_to_faces() {
  reread_bytes_ += byte_position() - face_offset_;
  bytes_total_ += face_bytes_;
  reader_.seek(face_offset_);
  cursor_ = lines_end_ = reader_.data();
  file_end_ = false;
  line_ = face_line_;
}

std::string PlyStream::where() const {
  const PlyElement& element = header_.elements[current_element_];
  return "record " + std::to_string(current_record_) + " of element " + element.name + " (" +
         std::to_string(element.count) + " declared)";
}

void PlyStream::fail_truncated() const {
  if (ascii_) fail("the file ends in " + where());
  throw Error(path(), FilePosition::byte(reader_.file_size()), "the file ends in " + where());
}

void PlyStream::report_progress(bool final) {
  const std::uint64_t done = bytes_read();
  if (done >= next_progress_ || final) {
    next_progress_ = done + kProgressBytes;
    report(progress_, "read", done, bytes_total_);
  }
}

void PlyStream::skip_bytes(std::uint64_t bytes) {
  if (bytes <= reader_.available()) {
    reader_.consume(static_cast<std::size_t>(bytes));
    return;
  }
  const std::uint64_t offset = reader_.offset();
  if (bytes > reader_.file_size() - offset) fail_truncated();
  reader_.seek(offset + bytes);
}

// ---- Ascii ------------------------------------------------------------------------------------------------

void PlyStream::refill_lines() {
  reader_.consume(static_cast<std::size_t>(cursor_ - reader_.data()));
  // fill() stops short of the capacity only at the end of the file.
  const std::size_t available = reader_.fill(reader_.capacity());
  const char* begin = reader_.data();
  cursor_ = begin;
  if (available < reader_.capacity()) {
    lines_end_ = begin + available;  // the rest of the file; its last line may lack a newline
    file_end_ = true;
    return;
  }
  const void* last_newline = memrchr(begin, '\n', available);
  if (last_newline == nullptr) fail("a line longer than " + std::to_string(reader_.capacity()) + " bytes");
  lines_end_ = static_cast<const char*>(last_newline) + 1;
  file_end_ = false;
}

bool PlyStream::begin_ascii_record() {
  while (true) {
    skip_ascii_spaces();
    if (cursor_ == lines_end_) {
      if (file_end_) return false;
      refill_lines();
      if (cursor_ == lines_end_) return false;
      continue;
    }
    if (*cursor_ != '\n') return true;
    ++cursor_;
    ++line_;
  }
}

void PlyStream::end_ascii_record() {
  skip_ascii_spaces();
  if (cursor_ == lines_end_) return;  // the last line of the file
  if (*cursor_ != '\n') {
    const char* end = cursor_;
    while (end < lines_end_ && *end != ' ' && *end != '\t' && *end != '\r' && *end != '\n' &&
           end - cursor_ < 32)
      ++end;
    fail("unexpected value '" + std::string(cursor_, end) + "' after the end of " + where());
  }
  ++cursor_;
  ++line_;
}

std::string_view PlyStream::ascii_token(PlyType type) {
  skip_ascii_spaces();
  const char* begin = cursor_;
  while (cursor_ < lines_end_ && *cursor_ != ' ' && *cursor_ != '\t' && *cursor_ != '\r' && *cursor_ != '\n')
    ++cursor_;
  if (cursor_ == begin) {
    const std::string name = ply_type_name(type);
    fail("the line ends early: expected " + std::string(name[0] == 'i' ? "an " : "a ") + name + " in " +
         where());
  }
  return std::string_view(begin, static_cast<std::size_t>(cursor_ - begin));
}

namespace {

bool is_ascii_delimiter(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n';
}

}  // namespace

// Parses straight from the cursor, without finding the token's end first: values are the bulk of an ascii
// file. Anything unusual (a sign without digits, a stray character, a huge number) goes to the careful
// token-based parse below, which also words the error.
std::int64_t PlyStream::ascii_integer(PlyType type) {
  skip_ascii_spaces();
  const char* p = cursor_;
  const bool negative = p < lines_end_ && *p == '-';
  if (p < lines_end_ && (*p == '-' || *p == '+')) ++p;
  const char* const digits = p;
  std::int64_t magnitude = 0;
  // Twelve digits cannot overflow and exceed every PLY integer type.
  while (p < lines_end_ && static_cast<unsigned>(*p - '0') <= 9 && p - digits < 12) {
    magnitude = magnitude * 10 + (*p - '0');
    ++p;
  }
  if (p == digits || (p < lines_end_ && !is_ascii_delimiter(*p))) return ascii_integer_slow(type);
  const std::int64_t value = negative ? -magnitude : magnitude;
  const auto [lo, hi] = integer_range(type);
  if (value < lo || value > hi) return ascii_integer_slow(type);
  cursor_ = p;
  return value;
}

std::int64_t PlyStream::ascii_integer_slow(PlyType type) {
  const std::string_view token = ascii_token(type);
  std::size_t i = 0;
  const bool negative = token[0] == '-';
  if (negative || token[0] == '+') ++i;
  if (i == token.size()) fail("'" + std::string(token) + "' is not an integer");
  std::uint64_t magnitude = 0;
  for (; i < token.size(); ++i) {
    const unsigned digit = static_cast<unsigned char>(token[i]) - '0';
    if (digit > 9) fail("'" + std::string(token) + "' is not an integer");
    // Every PLY integer type fits in 32 bits; anything past 2^40 is out of range whatever the type.
    if (magnitude > (std::uint64_t(1) << 40)) fail("integer '" + std::string(token) + "' is out of range");
    magnitude = magnitude * 10 + digit;
  }
  const std::int64_t value =
      negative ? -static_cast<std::int64_t>(magnitude) : static_cast<std::int64_t>(magnitude);
  const auto [lo, hi] = integer_range(type);
  if (value < lo || value > hi)
    fail("'" + std::string(token) + "' is out of range for " + ply_type_name(type));
  return value;
}

double PlyStream::ascii_number(PlyType type) {
  if (ply_type_is_integer(type)) return static_cast<double>(ascii_integer(type));
  skip_ascii_spaces();
  const char* begin = cursor_;
  if (begin < lines_end_ && *begin == '+') ++begin;  // from_chars rejects a leading '+', which strtod accepts
  double value = 0;
  fast_float::from_chars_result result;
  if (type == PlyType::float32) {
    // Parse straight to float: correctly rounded, so shortest-form floats round-trip exactly.
    float narrow = 0;
    result = fast_float::from_chars(begin, lines_end_, narrow);
    value = narrow;
  } else {
    result = fast_float::from_chars(begin, lines_end_, value);
  }
  if (result.ec != std::errc() || (result.ptr < lines_end_ && !is_ascii_delimiter(*result.ptr))) {
    const std::string_view token = ascii_token(type);  // fails itself when the line has ended
    fail("'" + std::string(token) + "' is not a number");
  }
  cursor_ = result.ptr;
  return value;
}

// ---- Values of either encoding
// ------------------------------------------------------------------------------

double PlyStream::read_number(PlyType type) {
  if (ascii_) return ascii_number(type);
  const std::size_t size = ply_type_size(type);
  const char* p = need(size);
  const double value = swap_ ? load_number<true>(p, type) : load_number<false>(p, type);
  reader_.consume(size);
  return value;
}

std::int64_t PlyStream::read_integer(PlyType type, const char* what) {
  if (ascii_ && ply_type_is_integer(type)) return ascii_integer(type);
  const std::uint64_t offset = byte_position();
  const double value = read_number(type);
  const auto integer = exact_integer(value);
  if (!integer) {
    // The shortest form that reads back as the file's value: std::to_string's six fixed decimals print 1e-9
    // as 0.000000.
    char text[32];
    const char* end = type == PlyType::float32
                          ? std::to_chars(text, text + sizeof text, static_cast<float>(value)).ptr
                          : std::to_chars(text, text + sizeof text, value).ptr;
    const std::string number(static_cast<const char*>(text), end);
    const std::string reason = std::string(what) + " " + number + " is not an integer";
    if (ascii_) fail(reason);
    fail_at_byte(offset, reason);
  }
  return *integer;
}

std::uint64_t PlyStream::read_list_count(const PlyProperty& property) {
  const std::uint64_t offset = byte_position();
  const std::int64_t count = read_integer(property.count_type, "list count");
  if (count < 0) {
    const std::string reason = "negative list count " + std::to_string(count) + " in " + where();
    if (ascii_) fail(reason);
    fail_at_byte(offset, reason);
  }
  return static_cast<std::uint64_t>(count);
}

void PlyStream::skip_property(const PlyProperty& property) {
  if (!property.is_list) {
    if (ascii_) {
      ascii_number(property.type);
    } else {
      skip_bytes(ply_type_size(property.type));
    }
    return;
  }
  const std::uint64_t count = read_list_count(property);
  if (ascii_) {
    for (std::uint64_t i = 0; i < count; ++i) ascii_number(property.type);
  } else {
    // count < 2^32 and items are at most 8 bytes: no overflow.
    skip_bytes(count * ply_type_size(property.type));
  }
}

void PlyStream::begin_record() {
  if (ascii_ && !begin_ascii_record()) fail_truncated();
}

void PlyStream::end_record() {
  if (ascii_) end_ascii_record();
  ++current_record_;
}

// ---- Elements ---------------------------------------------------------------------------------------------

void PlyStream::skip_element(std::size_t index) {
  const PlyElement& element = header_.elements[index];
  current_element_ = index;
  current_record_ = 0;
  if (element.properties.empty()) return;  // records of nothing take no room in either encoding
  if (!ascii_ && !element.has_lists()) {
    const std::size_t size = element.min_binary_size();
    if (element.count > (reader_.file_size() - reader_.offset()) / size) {
      current_record_ = (reader_.file_size() - reader_.offset()) / size;
      fail_truncated();
    }
    skip_bytes(element.count * size);
    current_record_ = element.count;
    return;
  }
  for (; current_record_ < element.count;) {
    begin_record();
    for (const PlyProperty& property : element.properties) skip_property(property);
    end_record();
    if ((current_record_ & 0xfff) == 0) report_progress();
  }
}

void PlyStream::load_vertices() {
  const PlyElement& element = header_.elements[vertex_element_];
  current_element_ = vertex_element_;
  current_record_ = 0;
  // Never trust the count for allocation before the data has proved itself: with fixed-size binary records
  // the file size settles it, otherwise reserve what the remaining bytes could hold at the least and grow.
  const std::uint64_t remaining = reader_.file_size() - byte_position();
  std::uint64_t min_record = ascii_ ? 2 * element.properties.size() : element.min_binary_size();
  const bool fixed = !ascii_ && !element.has_lists();
  if (fixed && vertex_count_ > remaining / min_record) {
    current_record_ = remaining / min_record;
    fail_truncated();
  }
  const std::size_t reserve =
      vertex_sink_ ? 0 : static_cast<std::size_t>(std::min(vertex_count_, remaining / min_record));
  vertices_.positions.reserve(reserve);
  if (vertex_plan_.normals) vertices_.normals.reserve(reserve);
  if (vertex_plan_.colors) vertices_.colors.reserve(reserve);
  if (vertex_plan_.uvs) vertices_.uvs.reserve(reserve);
  // No transparent huge pages for these arrays: on this VM fresh 2 MiB pages are often handed back to the
  // host when freed and cost about 0.3 GB/s at first touch, against about 2 GB/s for 4 KiB pages. Clustering
  // a 100 M-triangle scan (600 MB of positions) took 4.05 s with them and 3.67 s without (medians of 4
  // alternated runs); a 10 M-triangle file reads in the same time either way.

  try {
    if (fixed) {
      std::vector<std::size_t> offsets;
      std::size_t offset = 0;
      for (const PlyProperty& property : element.properties) {
        offsets.push_back(offset);
        offset += ply_type_size(property.type);
      }
      offsets.push_back(offset);  // the record size
      if (swap_) {
        load_fixed_vertices<true>(offsets);
      } else {
        load_fixed_vertices<false>(offsets);
      }
    } else {
      load_vertex_records();
    }
  } catch (const Error&) {
    // A vertex held for the origin's sample may be bad too, and it comes first in the file: that is the error
    // to report (settle_origin throws it), taken against the origin of the vertices read so far.
    if (!origin_sample_.settled) settle_origin();
    throw;
  }
  if (!origin_sample_.settled) {
    settle_origin();  // fewer vertices than the sample
    flush_vertices();
  }
  if (warn_ && clamped_colors_ > 0) {
    warn_(clamped_colors_note(clamped_colors_, integer_colors_));
  }
  report_progress();
}

void PlyStream::add_vertex(std::size_t index, const VertexValues& values, std::uint64_t offset) {
  const Vec3d read(values.position[0], values.position[1], values.position[2]);
  // Beyond float's range a coordinate is refused wherever the origin falls (it never lies beyond that range).
  auto refuse = [&](const char* what) {
    const std::string reason =
        "vertex " + std::to_string(index) + " has " + what + " that is not a finite float";
    if (ascii_) fail(reason);
    fail_at_byte(offset, reason);
  };
  if (!read.allFinite()) refuse("a coordinate");
  if (Eigen::Index axis = 0; read.cwiseAbs().maxCoeff(&axis) > std::numeric_limits<float>::max()) {
    // A double property: finite, but no float holds it.
    char value[32];
    std::snprintf(value, sizeof value, "%g", read[axis]);
    const std::string reason = "vertex " + std::to_string(index) +
                               " has a coordinate beyond the float range (+-3.4e38), which positions are "
                               "held in: " +
                               value;
    if (ascii_) fail(reason);
    fail_at_byte(offset, reason);
  }
  // Attributes too, as the OBJ and Draco readers refuse them: a NaN normal made every attribute-weighted
  // collapse cost NaN, and the decimation order arbitrary.
  if (vertex_plan_.normals && !(std::isfinite(values.normal[0]) && std::isfinite(values.normal[1]) &&
                                std::isfinite(values.normal[2])))
    refuse("a normal");
  if (vertex_plan_.uvs && !(std::isfinite(values.uv[0]) && std::isfinite(values.uv[1])))
    refuse("a texture coordinate");
  if (vertex_plan_.colors) {
    const ColorCheck* check = values.color_check;
    if (check[0] == ColorCheck::not_finite || check[1] == ColorCheck::not_finite ||
        check[2] == ColorCheck::not_finite || check[3] == ColorCheck::not_finite)
      refuse("a color");
    if (check[0] != ColorCheck::in_range || check[1] != ColorCheck::in_range ||
        check[2] != ColorCheck::in_range || check[3] != ColorCheck::in_range)
      ++clamped_colors_;
  }
  const FilePosition where = ascii_ ? FilePosition::line(line_) : FilePosition::byte(offset);
  if (!origin_sample_.settled) {
    // Also held in double until the origin is chosen from them.
    origin_sample_.held.push_back({read, where});
    vertices_.positions.push_back(read.cast<float>());
    if (origin_sample_.full()) settle_origin();
  } else {
    vertices_.positions.push_back(vertices_.origin == Vec3d::Zero()
                                      ? read.cast<float>()  // in range: checked above
                                      : float_offset(read, vertices_.origin, path(), where, index));
    bounds_.add(vertices_.positions.back());
  }
  if (vertex_plan_.normals)
    vertices_.normals.emplace_back(values.normal[0], values.normal[1], values.normal[2]);
  if (vertex_plan_.colors) vertices_.colors.push_back(values.color);
  if (vertex_plan_.uvs) vertices_.uvs.emplace_back(values.uv[0], values.uv[1]);
}

template <bool Swap>
void PlyStream::load_fixed_vertices(const std::vector<std::size_t>& offsets) {
  const PlyElement& element = header_.elements[vertex_element_];
  const std::size_t record = offsets.back();
  struct Field {
    std::size_t offset;
    PlyType type;
    Slot slot;
  };
  std::vector<Field> fields;
  for (std::size_t i = 0; i < element.properties.size(); ++i) {
    if (vertex_plan_.slots[i] != Slot::none)
      fields.push_back({offsets[i], element.properties[i].type, vertex_plan_.slots[i]});
  }
  // Exactly float x y z: the records are the positions' memory layout.
  const bool bulk =
      !Swap && record == 12 && fields.size() == 3 && fields[0].slot == Slot::x && fields[1].slot == Slot::y &&
      fields[2].slot == Slot::z && element.properties[0].type == PlyType::float32 &&
      element.properties[1].type == PlyType::float32 && element.properties[2].type == PlyType::float32;
  static_assert(sizeof(Vec3f) == 12);
  if (bulk && !vertex_sink_) {
    load_positions_directly();
    return;
  }

  std::uint64_t done = 0;
  Vec3f lo = Vec3f::Constant(std::numeric_limits<float>::infinity()), hi = -lo;
  while (done < vertex_count_) {
    const std::uint64_t left = vertex_count_ - done;
    std::size_t available = reader_.available();
    // At least one whole record, however large (the reader's window grows to hold it).
    if (available < record)
      available = reader_.fill(
          std::min<std::uint64_t>(std::max<std::uint64_t>(reader_.capacity(), record), left * record));
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(left, available / record));
    if (n == 0) fail_truncated();  // cannot happen after the size check, unless the file shrank
    const char* data = reader_.data();
    const std::uint64_t base = reader_.offset();
    if (bulk) {
      vertices_.positions.resize(n);
      float* out = vertices_.positions[0].data();
      std::memcpy(out, data, n * record);
      const std::size_t bad = scan_points(out, n, lo.data(), hi.data());
      if (bad < n) {
        current_record_ = done + bad;
        fail_at_byte(base + bad * record,
                     "vertex " + std::to_string(done + bad) + " has a coordinate that is not a finite float");
      }
    } else {
      VertexValues values;
      for (std::size_t i = 0; i < n; ++i) {
        const char* p = data + i * record;
        for (const Field& field : fields) {
          set_value(values, field.slot, field.type, load_number<Swap>(p + field.offset, field.type));
        }
        add_vertex(done + i, values, base + i * record);
      }
    }
    reader_.consume(n * record);
    done += n;
    current_record_ = done;
    report_progress();
    flush_vertices();
  }
  if (bulk && vertex_count_ > 0) {
    bounds_.add(lo);
    bounds_.add(hi);
  }
}

// Float x y z records, kept in memory: read straight into the positions array, by all threads. Through the
// reader's buffer every byte was copied twice, and one thread took every first touch of the new array's pages
// (the kernel zeroes each; on the 100 M-triangle throughput scan that was about a sixth of the run's CPU
// time, all of it on one core while the other waited). Each task reads whole records of its piece with
// pread(2) and checks them; pieces go in batches so that progress is reported and a bad file stops early.
void PlyStream::load_positions_directly() {
  constexpr std::size_t kRecord = 12;
  constexpr std::size_t kPieceRecords = std::size_t{1} << 16;  // 768 KiB
  constexpr std::size_t kBatchPieces = 16;
  vertices_.positions.resize(static_cast<std::size_t>(vertex_count_));
  char* out = reinterpret_cast<char*>(vertices_.positions.data());
  const std::uint64_t start = reader_.offset();
  const std::uint64_t bytes = vertex_count_ * kRecord;
  // What the reader's window already holds is copied from there.
  const std::size_t held = static_cast<std::size_t>(std::min<std::uint64_t>(reader_.available(), bytes));
  if (held > 0) std::memcpy(out, reader_.data(), held);  // (with no vertices, out and data may be null)

  struct Piece {
    std::size_t first = 0, count = 0;  // records
    std::size_t read = 0;              // bytes of the piece that arrived
    std::size_t bad = 0;               // first non-finite record of the piece, or count
    float lo[3], hi[3];
  };
  Vec3f lo = Vec3f::Constant(std::numeric_limits<float>::infinity()), hi = -lo;
  const std::size_t total = static_cast<std::size_t>(vertex_count_);
  std::vector<Piece> pieces(kBatchPieces);
  for (std::size_t batch = 0; batch < total; batch += kBatchPieces * kPieceRecords) {
    const std::size_t n = std::min(kBatchPieces, (total - batch + kPieceRecords - 1) / kPieceRecords);
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
      Piece& piece = pieces[i];
      piece.first = batch + i * kPieceRecords;
      piece.count = std::min(kPieceRecords, total - piece.first);
      const std::size_t begin = piece.first * kRecord, end = begin + piece.count * kRecord;
      const std::size_t from = std::max(begin, held);
      piece.read = from - begin;
      if (from < end) piece.read += reader_.read_at(start + from, out + from, end - from);
      for (int k = 0; k < 3; ++k) {
        piece.lo[k] = std::numeric_limits<float>::infinity();
        piece.hi[k] = -std::numeric_limits<float>::infinity();
      }
      const std::size_t whole = piece.read / kRecord;
      piece.bad = scan_points(reinterpret_cast<const float*>(out + begin), whole, piece.lo, piece.hi);
      if (piece.bad == whole) piece.bad = piece.count;
    });
    // The first problem in file order is the one reported.
    for (std::size_t i = 0; i < n; ++i) {
      const Piece& piece = pieces[i];
      if (piece.bad < piece.count) {
        current_record_ = piece.first + piece.bad;
        fail_at_byte(start + current_record_ * kRecord, "vertex " + std::to_string(current_record_) +
                                                            " has a coordinate that is not a finite float");
      }
      if (piece.read < piece.count * kRecord) {
        current_record_ = piece.first + piece.read / kRecord;
        fail_truncated();  // the file shrank after its size was checked
      }
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], piece.lo[k]);
        hi[k] = std::max(hi[k], piece.hi[k]);
      }
    }
    current_record_ = batch + std::min(total - batch, kBatchPieces * kPieceRecords);
    report(progress_, "read", start + current_record_ * kRecord, bytes_total_);
  }
  reader_.seek(start + bytes);
  current_record_ = vertex_count_;
  if (vertex_count_ > 0) {
    bounds_.add(lo);
    bounds_.add(hi);
  }
}

void PlyStream::load_vertex_records() {
  const PlyElement& element = header_.elements[vertex_element_];
  VertexValues values;
  while (current_record_ < vertex_count_) {
    begin_record();
    const std::uint64_t offset = byte_position();
    for (std::size_t i = 0; i < element.properties.size(); ++i) {
      const PlyProperty& property = element.properties[i];
      if (property.is_list || vertex_plan_.slots[i] == Slot::none) {
        skip_property(property);
      } else {
        set_value(values, vertex_plan_.slots[i], property.type, read_number(property.type));
      }
    }
    add_vertex(static_cast<std::size_t>(current_record_), values, offset);
    end_record();
    if ((current_record_ & 0xfff) == 0) {
      report_progress();
      flush_vertices();
    }
  }
  flush_vertices();
}

void PlyStream::settle_origin() {
  vertices_.origin = origin_sample_.settle(path(), 0, vertices_.positions, bounds_);
}

void PlyStream::flush_vertices() {
  // Until the sample is complete the vertices stay here (at most kOriginSample and a buffer's worth), so the
  // origin comes from the same vertices in core and out of core.
  if (!vertex_sink_ || vertices_.positions.empty() || !origin_sample_.settled) return;
  vertex_sink_({vertices_.positions, vertices_.normals, vertices_.colors, vertices_.uvs});
  vertices_.positions.clear();
  vertices_.normals.clear();
  vertices_.colors.clear();
  vertices_.uvs.clear();
}

void PlyStream::check_end_of_data() {
  if (ascii_) {
    if (begin_ascii_record()) fail("unexpected data after the last element");
    return;
  }
  // Line breaks or spaces after the binary data (some writers end the file with a newline) are not data;
  // anything else is, and most likely means the header's counts are wrong.
  const std::uint64_t end = reader_.offset();
  while (!reader_.at_end()) {
    const std::size_t n = reader_.fill(kBufferBytes);
    const char* bytes = reader_.data();
    for (std::size_t i = 0; i < n; ++i) {
      if (bytes[i] != '\n' && bytes[i] != '\r' && bytes[i] != ' ' && bytes[i] != '\t') {
        const std::uint64_t extra = reader_.file_size() - end;
        fail_at_byte(end, std::to_string(extra) + (extra == 1 ? " byte" : " bytes") +
                              " of unexpected data after the last element");
      }
    }
    reader_.consume(n);
  }
}

// ---- Faces ------------------------------------------------------------------------------------------------

bool PlyStream::next(TriangleBatch& batch) {
  // A soup's fields, should the caller reuse a batch; the triangles are kept for the resize below.
  batch.corners.clear();
  batch.corner_normals.clear();
  batch.corner_colors.clear();
  batch.corner_uvs.clear();
  if (faces_done_) {
    batch.triangles.clear();
    return false;
  }
  // Filled through a pointer, then cut to size: push_back's bookkeeping cost as much as decoding a
  // triangle. A caller that reuses its batch keeps the full size between calls, so this resize is free.
  batch.triangles.resize(capacity_);
  out_ = batch.triangles.data();
  filled_ = 0;
  while (pending_next_ < pending_.size() && filled_ < capacity_) out_[filled_++] = pending_[pending_next_++];
  if (pending_next_ == pending_.size()) {
    pending_.clear();
    pending_next_ = 0;
  }
  const std::uint64_t count = header_.elements[face_element_].count;
  while (filled_ < capacity_) {
    if (!in_record_ && current_record_ == count) {
      finish_faces();
      break;
    }
    if (!in_record_ && fast_faces_ && read_fast_faces()) continue;
    read_face_values();
  }
  batch.triangles.resize(filled_);
  out_ = nullptr;
  report_progress();
  return filled_ > 0;
}

void PlyStream::finish_faces() {
  if (strips_ && triangles_emitted_ == 0) {
    throw Error(path(), FilePosition::line(header_.elements[face_element_].header_line),
                "the triangle strips hold no triangle");
  }
  if (!faces_first_) {
    for (std::size_t element = face_element_ + 1; element < header_.elements.size(); ++element) {
      skip_element(element);
    }
    check_end_of_data();
  }
  current_element_ = face_element_;
  faces_done_ = true;
  report_progress(true);
  if (warn_) {
    for (const std::string& note : std::exchange(notes_at_end_, {})) warn_(note);
    if (concave_fans_ > 0) warn_(concave_fans_note(std::exchange(concave_fans_, 0)));
  }
}

void PlyStream::check_corner(std::int64_t index, std::uint64_t offset) const {
  if (index < 0 || static_cast<std::uint64_t>(index) >= vertex_count_) {
    const std::string reason = "vertex index " + std::to_string(index) + " is out of range (" +
                               std::to_string(vertex_count_) + " vertices) in " + where();
    if (ascii_) fail(reason);
    fail_at_byte(offset, reason);
  }
}

void PlyStream::add_corner(std::int64_t index, std::uint64_t offset) {
  if (strips_ && index == -1) {
    corners_seen_ = 0;  // a new strip starts
    return;
  }
  check_corner(index, offset);
  if (next_copy_ < corner_copies_.size() && corner_copies_[next_copy_].record == current_record_ &&
      corner_copies_[next_copy_].corner == corners_seen_)
    index = corner_copies_[next_copy_++].copy;
  if (strips_) {
    if (corners_seen_ >= 2) {
      // Every other triangle of a strip is wound the other way; skip the degenerate ones that join strips.
      const Index a = static_cast<Index>(strip_before_), b = static_cast<Index>(previous_corner_),
                  c = static_cast<Index>(index);
      if (a != b && b != c && a != c) {
        out_[filled_++] = corners_seen_ % 2 == 0 ? Triangle{a, b, c} : Triangle{b, a, c};
        ++triangles_emitted_;
      }
    }
    strip_before_ = previous_corner_;
  } else if (polygon_size_ > 3 && positions_known()) {
    polygon_.push_back(static_cast<Index>(index));
    if (polygon_.size() == polygon_size_) emit_polygon();
  } else if (corners_seen_ == 0) {
    first_corner_ = index;
  } else if (corners_seen_ >= 2) {
    out_[filled_++] = {static_cast<Index>(first_corner_), static_cast<Index>(previous_corner_),
                       static_cast<Index>(index)};
    ++triangles_emitted_;
  }
  previous_corner_ = index;
  ++corners_seen_;
}

void PlyStream::emit_polygon() {
  polygon_.resize(drop_repeated_corners(polygon_.data(), polygon_.size(),
                                        [&](Index a, Index b) { return same_point(a, b); }));
  concave_fans_ += polygon_triangles(
      polygon_.data(), polygon_.size(), [&](std::size_t i) { return position(polygon_[i]); },
      polygon_scratch_,
      [&](const Triangle& t) {
        if (filled_ < capacity_)
          out_[filled_++] = t;
        else
          pending_.push_back(t);
        ++triangles_emitted_;
      });
  polygon_.clear();
}

// The general path: one value at a time, any types, any other properties around the index list. Returns at
// the end of the record or when the batch is full (each corner adds at most one triangle; a polygon gathered
// whole adds its triangles at its last corner, and what the batch cannot take waits in `pending_`).
void PlyStream::read_face_values() {
  const PlyElement& element = header_.elements[face_element_];
  if (!in_record_) {
    begin_record();
    in_record_ = true;
    next_property_ = 0;
    in_list_ = false;
  }
  while (true) {
    if (in_list_) {
      const PlyType type = element.properties[index_property_].type;
      while (list_left_ > 0) {
        if (filled_ >= capacity_) return;
        const std::uint64_t offset = byte_position();
        add_corner(read_integer(type, "vertex index"), offset);
        --list_left_;
      }
      in_list_ = false;
      ++next_property_;
    }
    if (next_property_ == element.properties.size()) break;
    const PlyProperty& property = element.properties[next_property_];
    if (next_property_ != index_property_) {
      skip_property(property);
      ++next_property_;
      continue;
    }
    const std::uint64_t offset = byte_position();
    list_left_ = read_list_count(property);
    if (!strips_ && list_left_ < 3) {
      const std::string reason = "a face with " + std::to_string(list_left_) +
                                 (list_left_ == 1 ? " corner in " : " corners in ") + where();
      if (ascii_) fail(reason);
      fail_at_byte(offset, reason);
    }
    in_list_ = true;
    corners_seen_ = 0;
    polygon_size_ = list_left_;
    polygon_.clear();
  }
  end_record();
  in_record_ = false;
  if ((current_record_ & 0xfff) == 0) report_progress();
}

// Each vertex takes the texture coordinates of the first face corner that references it (see the top of the
// file); a vertex no face references keeps (0, 0). The faces are checked as the stream will read them.
void PlyStream::load_wedge_uvs() {
  const PlyElement& element = header_.elements[face_element_];
  const PlyProperty& indices = element.properties[index_property_];
  const PlyProperty& texcoords = element.properties[*wedge_property_];
  current_element_ = face_element_;
  current_record_ = 0;
  vertices_.uvs.assign(vertices_.positions.size(), Vec2f::Zero());
  std::vector<std::uint8_t> given(vertices_.positions.size(), 0);  // see take_first_corner
  std::uint64_t seams = 0;
  // One face's lists; they grow with the values actually read, never with a count the file claims.
  std::vector<std::int64_t> corners;
  std::vector<float> uv;
  std::map<std::tuple<std::size_t, float, float>, Index> copies;  // split_: (vertex, texcoord) -> its copy
  while (current_record_ < element.count) {
    begin_record();
    corners.clear();
    uv.clear();
    std::uint64_t uv_offset = 0;
    for (std::size_t p = 0; p < element.properties.size(); ++p) {
      const PlyProperty& property = element.properties[p];
      if (p == index_property_) {
        for (std::uint64_t n = read_list_count(property); n > 0; --n) {
          const std::uint64_t offset = byte_position();
          corners.push_back(read_integer(indices.type, "vertex index"));
          check_corner(corners.back(), offset);
        }
      } else if (p == *wedge_property_) {
        uv_offset = byte_position();
        for (std::uint64_t n = read_list_count(property); n > 0; --n) {
          const std::uint64_t offset = byte_position();
          uv.push_back(to_float(read_number(texcoords.type)));
          if (!std::isfinite(uv.back())) {
            const std::string reason = "a texture coordinate that is not a finite float in " + where();
            if (ascii_) fail(reason);
            fail_at_byte(offset, reason);
          }
        }
      } else {
        skip_property(property);
      }
    }
    // An empty list gives a face no coordinates, as a writer may for an untextured face.
    if (!uv.empty() && uv.size() != 2 * corners.size()) {
      const std::string reason = "texcoord holds " + std::to_string(uv.size()) + " numbers for " +
                                 std::to_string(corners.size()) + " corners (two a corner) in " + where();
      if (ascii_) fail(reason);
      fail_at_byte(uv_offset, reason);
    }
    for (std::size_t k = 0; k < corners.size() && !uv.empty(); ++k) {
      const auto v = static_cast<std::size_t>(corners[k]);
      const Vec2f value(uv[2 * k], uv[2 * k + 1]);
      take_first_corner(given, vertices_.uvs, v, value, seams);
      if (split_ && vertices_.uvs[v] != value) {
        // One copy per vertex and distinct texcoord, at the vertex's position with its other attributes.
        if (vertices_.positions.size() >= std::numeric_limits<Index>::max())
          fail("too many vertices once texture seams are split, in " + where());
        const auto [at, added] = copies.emplace(std::tuple(v, value.x(), value.y()),
                                                static_cast<Index>(vertices_.positions.size()));
        if (added) {
          vertices_.positions.push_back(vertices_.positions[v]);
          if (!vertices_.normals.empty()) vertices_.normals.push_back(vertices_.normals[v]);
          if (!vertices_.colors.empty()) vertices_.colors.push_back(vertices_.colors[v]);
          vertices_.uvs.push_back(value);
        }
        corner_copies_.push_back({current_record_, k, at->second});
      }
    }
    end_record();
    if ((current_record_ & 0xfff) == 0) report_progress();
  }
  if (warn_ && !split_ && seams > 0) warn_(merged_corners_note(seams, 0));
}

// Records of a count followed by the indices, nothing else, while the count is 3.
template <class CountT, class IndexT, bool Swap>
void PlyStream::read_triangle_records() {
  constexpr std::size_t kRecord = sizeof(CountT) + 3 * sizeof(IndexT);
  const std::uint64_t count = header_.elements[face_element_].count;
  const std::uint64_t vertex_count = vertex_count_;
  // A negative index converts to an Index of at least 2^31, which the range check then catches by itself.
  const bool negatives_wrap = vertex_count <= (std::uint64_t{1} << 31);
  while (filled_ < capacity_ && current_record_ < count) {
    std::size_t available = reader_.available();
    if (available < kRecord) {
      available = reader_.fill(reader_.capacity());
      if (available < kRecord) return;  // the general path reports the truncation
    }
    const char* const begin = reader_.data();
    const char* p = begin;
    const auto fit = static_cast<std::size_t>(
        std::min<std::uint64_t>({available / kRecord, capacity_ - filled_, count - current_record_}));
    Triangle* const out = out_ + filled_;
    std::size_t done = 0;
    bool other_count = false;
    for (; done < fit; ++done, p += kRecord) {
      if (load<CountT, Swap>(p) != 3) {
        other_count = true;
        break;
      }
      const IndexT a = load<IndexT, Swap>(p + sizeof(CountT));
      const IndexT b = load<IndexT, Swap>(p + sizeof(CountT) + sizeof(IndexT));
      const IndexT c = load<IndexT, Swap>(p + sizeof(CountT) + 2 * sizeof(IndexT));
      const Triangle t = {static_cast<Index>(a), static_cast<Index>(b), static_cast<Index>(c)};
      bool bad = std::max({t[0], t[1], t[2]}) >= vertex_count;
      if constexpr (std::is_signed_v<IndexT>) bad |= !negatives_wrap && (a | b | c) < 0;
      if (bad) [[unlikely]] {
        const std::uint64_t record_offset = reader_.offset() + static_cast<std::uint64_t>(p - begin);
        current_record_ += done;
        const IndexT corners[3] = {a, b, c};
        for (int k = 0; k < 3; ++k) {
          if (corners[k] < 0 || static_cast<std::uint64_t>(corners[k]) >= vertex_count) {
            fail_at_byte(record_offset + sizeof(CountT) + k * sizeof(IndexT),
                         "vertex index " + std::to_string(corners[k]) + " is out of range (" +
                             std::to_string(vertex_count) + " vertices) in " + where());
          }
        }
      }
      out[done] = t;
    }
    reader_.consume(done * kRecord);
    filled_ += done;
    current_record_ += done;
    triangles_emitted_ += done;
    if (other_count) return;
  }
}

// Ascii lines of "3 a b c", while they are triangles.
void PlyStream::read_ascii_triangles() {
  const PlyProperty& list = header_.elements[face_element_].properties[index_property_];
  const std::uint64_t count = header_.elements[face_element_].count;
  while (filled_ < capacity_ && current_record_ < count) {
    if (!begin_ascii_record()) return;  // the general path reports the truncation
    const char* const start = cursor_;
    if (ascii_integer(list.count_type) != 3) {
      cursor_ = start;  // the general path reads this record from its start
      return;
    }
    Triangle t;
    for (Index& corner : t) {
      const std::int64_t index = ascii_integer(list.type);
      if (index < 0 || static_cast<std::uint64_t>(index) >= vertex_count_) {
        fail("vertex index " + std::to_string(index) + " is out of range (" + std::to_string(vertex_count_) +
             " vertices) in " + where());
      }
      corner = static_cast<Index>(index);
    }
    end_ascii_record();
    out_[filled_++] = t;
    ++current_record_;
    ++triangles_emitted_;
  }
}

// Dispatches the fast path on the count and index types; returns false when the next record needs the
// general path (a polygon, the end of the data) and nothing was read.
bool PlyStream::read_fast_faces() {
  const PlyProperty& list = header_.elements[face_element_].properties[index_property_];
  const std::uint64_t before = current_record_;
  if (ascii_) {
    read_ascii_triangles();
    return current_record_ != before;
  }
  auto run = [&](auto count_tag, auto index_tag) {
    using CountT = decltype(count_tag);
    using IndexT = decltype(index_tag);
    if (swap_) {
      read_triangle_records<CountT, IndexT, true>();
    } else {
      read_triangle_records<CountT, IndexT, false>();
    }
  };
  auto with_index = [&](auto count_tag) {
    if (list.type == PlyType::int32) {
      run(count_tag, std::int32_t{});
    } else {
      run(count_tag, std::uint32_t{});
    }
  };
  switch (list.count_type) {
    case PlyType::int8:
      with_index(std::int8_t{});
      break;
    case PlyType::uint8:
      with_index(std::uint8_t{});
      break;
    case PlyType::int16:
      with_index(std::int16_t{});
      break;
    case PlyType::uint16:
      with_index(std::uint16_t{});
      break;
    case PlyType::int32:
      with_index(std::int32_t{});
      break;
    case PlyType::uint32:
      with_index(std::uint32_t{});
      break;
    case PlyType::float32:
    case PlyType::float64:
      return false;
  }
  return current_record_ != before;
}

}  // namespace

std::unique_ptr<TriangleStream> open_ply_stream(const std::string& path, const ReadOptions& options) {
  return std::make_unique<PlyStream>(path, options);
}

std::uint64_t ply_triangles_hint(const std::string& path) {
  ByteReader reader(path, 1 << 16);
  const PlyHeader header = parse_ply_header(reader);
  for (const PlyElement& element : header.elements) {
    if (element.name != "face") continue;
    const auto index = index_list(element);
    if (!index || !element.properties[*index].is_list) return 0;
    return bounded_face_count(element, element.properties[*index], header.encoding == PlyEncoding::ascii,
                              reader.file_size() - header.data_offset);
  }
  return 0;
}

std::uint64_t ply_vertex_bytes(const std::string& path, const PlyElement& element) {
  const VertexPlan plan = plan_vertices(path, element);
  return vertex_bytes(plan.normals, plan.colors, plan.uvs);
}

}  // namespace ocsimp::detail
