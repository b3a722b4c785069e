// Draco (.drc) through Google's draco library. Draco has no streaming decoder, so the reader decodes the
// whole file up front and then serves faces in batches like any indexed stream.
//
// Draco meshes index their faces by *point*, a point being one combination of attribute values; a position on
// a uv seam may therefore appear as several points. Each point becomes one of our vertices (the seam stays
// split, as in the file).
#include <draco/compression/config/compression_shared.h>
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>
#include <draco/mesh/mesh.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "byte_reader.h"
#include "formats.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/atomic_file.h"
#include "text_io.h"

namespace ocsimp::detail {
namespace {

// Draco shrinks meshes roughly tenfold, so a 1 GiB file decodes to far more than a machine holds: refuse
// rather than start. (The decoder needs the whole file in memory.)
constexpr std::uint64_t kMaxDracoBytes = std::uint64_t(1) << 30;
// "DRACO", version major and minor, geometry type, encoding method, flags (uint16).
constexpr std::size_t kHeaderBytes = 11;
// Attribute quantization besides positions (which WriteOptions sets): normals keep 12 bits per octahedral
// component (under 0.05 degrees), uvs 16 bits over their range; colors are stored as bytes, unquantized.
constexpr int kNormalBits = 12;
constexpr int kUvBits = 16;
// The sum of squared face counts of vertices with more than 256 faces above which meshes are written with
// Draco's sequential coder (see write_drc): a single fan of about 30,000 faces, where the edgebreaker coder
// spends about 0.1 s more than the rest of its work.
constexpr double kMaxFanWork = 1e9;

std::vector<char> read_whole_file(const std::string& path) {
  ByteReader reader(path, 1 << 20);
  if (reader.file_size() > kMaxDracoBytes)
    throw Error(path, {},
                "Draco file of " + std::to_string(reader.file_size()) + " bytes is over the " +
                    std::to_string(kMaxDracoBytes >> 20) + " MiB this reader decodes in memory");
  std::vector<char> data;
  data.reserve(static_cast<std::size_t>(reader.file_size()));
  while (std::size_t n = reader.fill(reader.capacity())) {
    if (data.size() + n > reader.file_size())
      throw Error(path, FilePosition::byte(data.size()), "file grew while being read");
    data.insert(data.end(), reader.data(), reader.data() + n);
    reader.consume(n);
  }
  return data;
}

// The header fields this reader can place an error on, checked before draco (whose errors say nothing of
// where) sees the file.
void check_header(const std::string& path, const std::vector<char>& data) {
  if (data.size() < 5 || std::memcmp(data.data(), "DRACO", 5) != 0)
    throw Error(path, FilePosition::byte(0), "not a Draco file (no DRACO magic)");
  if (data.size() < kHeaderBytes)
    throw Error(path, FilePosition::byte(data.size()),
                "Draco header cut short (" + std::to_string(data.size()) + " of " +
                    std::to_string(kHeaderBytes) + " bytes)");
  const auto byte = [&](std::size_t i) { return static_cast<unsigned>(static_cast<unsigned char>(data[i])); };
  if (byte(7) == draco::POINT_CLOUD)
    throw Error(path, FilePosition::byte(7), "Draco point cloud: no faces to read");
  if (byte(7) != draco::TRIANGULAR_MESH)
    throw Error(path, FilePosition::byte(7), "unknown Draco geometry type " + std::to_string(byte(7)));
  if (DRACO_BITSTREAM_VERSION(byte(5), byte(6)) >
      DRACO_BITSTREAM_VERSION(draco::kDracoMeshBitstreamVersionMajor, draco::kDracoMeshBitstreamVersionMinor))
    throw Error(path, FilePosition::byte(5),
                "Draco version " + std::to_string(byte(5)) + "." + std::to_string(byte(6)) +
                    " is newer than this reader's " + std::to_string(draco::kDracoMeshBitstreamVersionMajor) +
                    "." + std::to_string(draco::kDracoMeshBitstreamVersionMinor));
  if (byte(8) != draco::MESH_SEQUENTIAL_ENCODING && byte(8) != draco::MESH_EDGEBREAKER_ENCODING)
    throw Error(path, FilePosition::byte(8), "unknown Draco mesh encoding method " + std::to_string(byte(8)));
}

// The attribute of `type` if the file has a usable one: at least `components` values, and a value for every
// point (checked here because draco's accessors do not).
const draco::PointAttribute* usable_attribute(const std::string& path, const draco::Mesh& mesh,
                                              draco::GeometryAttribute::Type type, int components,
                                              const char* name) {
  const draco::PointAttribute* attribute = mesh.GetNamedAttribute(type);
  if (attribute == nullptr) return nullptr;
  if (attribute->num_components() < components)
    throw Error(path, {},
                std::string("Draco ") + name + " attribute has " +
                    std::to_string(attribute->num_components()) + " components, expected " +
                    std::to_string(components));
  const std::size_t points = mesh.num_points();
  const bool mapped = attribute->is_mapping_identity() ? attribute->size() >= points
                                                       : attribute->indices_map_size() >= points;
  if (!mapped) throw Error(path, {}, std::string("Draco ") + name + " attribute does not cover every point");
  return attribute;
}

// Reads a value of point `point` as `count` floats, refusing a value index past the attribute's storage.
void value_of(const std::string& path, const draco::PointAttribute& attribute, draco::PointIndex point,
              int count, const char* name, float* out) {
  const draco::AttributeValueIndex index = attribute.mapped_index(point);
  if (index.value() >= attribute.size() ||
      !attribute.ConvertValue<float>(index, static_cast<int8_t>(count), out))
    throw Error(
        path, {},
        std::string("Draco ") + name + " value of point " + std::to_string(point.value()) + " is missing");
  for (int k = 0; k < count; ++k) {
    if (!std::isfinite(out[k]))
      throw Error(path, {},
                  std::string("Draco ") + name + " of point " + std::to_string(point.value()) +
                      " is NaN or infinite");
  }
}

IndexedMesh convert(const std::string& path, const draco::Mesh& mesh) {
  IndexedMesh out;
  const std::size_t points = mesh.num_points();
  const draco::PointAttribute* position =
      usable_attribute(path, mesh, draco::GeometryAttribute::POSITION, 3, "position");
  if (position == nullptr) throw Error(path, {}, "Draco mesh without a position attribute");
  const draco::PointAttribute* normal =
      usable_attribute(path, mesh, draco::GeometryAttribute::NORMAL, 3, "normal");
  const draco::PointAttribute* color =
      usable_attribute(path, mesh, draco::GeometryAttribute::COLOR, 3, "color");
  const draco::PointAttribute* uv =
      usable_attribute(path, mesh, draco::GeometryAttribute::TEX_COORD, 2, "uv");

  out.positions.resize(points);
  if (normal) out.normals.resize(points);
  if (color) out.colors.resize(points);
  if (uv) out.uvs.resize(points);
  // Colors arrive as floats: 0..1 from float and normalized integer storage (draco scales the latter), raw
  // numbers from plain integers.
  const bool color_unit = color && (color->data_type() == draco::DT_FLOAT32 ||
                                    color->data_type() == draco::DT_FLOAT64 || color->normalized());
  for (std::uint32_t i = 0; i < points; ++i) {
    const draco::PointIndex p(i);
    value_of(path, *position, p, 3, "position", out.positions[i].data());
    if (normal) value_of(path, *normal, p, 3, "normal", out.normals[i].data());
    if (uv) value_of(path, *uv, p, 2, "uv", out.uvs[i].data());
    if (color) {
      const int channels = std::min<int>(color->num_components(), 4);
      float rgba[4] = {0, 0, 0, color_unit ? 1.0f : 255.0f};
      value_of(path, *color, p, channels, "color", rgba);
      for (int k = 0; k < 4; ++k) {
        const float byte = color_unit ? rgba[k] * 255.0f : rgba[k];
        out.colors[i][k] = static_cast<std::uint8_t>(std::clamp(byte, 0.0f, 255.0f) + 0.5f);
      }
    }
  }
  out.triangles.resize(mesh.num_faces());
  for (std::uint32_t f = 0; f < mesh.num_faces(); ++f) {
    const draco::Mesh::Face& face = mesh.face(draco::FaceIndex(f));
    for (int k = 0; k < 3; ++k) {
      if (face[k].value() >= points)
        throw Error(path, {},
                    "Draco face " + std::to_string(f) + " uses point " + std::to_string(face[k].value()) +
                        " of only " + std::to_string(points));
      out.triangles[f][k] = face[k].value();
    }
  }
  return out;
}

class DracoStream final : public TriangleStream {
 public:
  DracoStream(const std::string& path, const ReadOptions& options)
      : path_(path), capacity_(std::max<std::size_t>(options.batch_capacity, 1)) {
    std::vector<char> data = read_whole_file(path);
    file_size_ = data.size();
    report(options.progress, "read", 0, file_size_);
    check_header(path, data);
    draco::DecoderBuffer buffer;
    buffer.Init(data.data(), data.size());
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
    // Draco's errors carry no place; where its decoder stopped reading is the best there is.
    if (!decoded.ok())
      throw Error(path, FilePosition::byte(std::max<std::int64_t>(buffer.decoded_size(), kHeaderBytes)),
                  std::string("Draco: ") + decoded.status().error_msg());
    const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
    if (mesh == nullptr) throw Error(path, {}, "Draco: decoding produced no mesh");
    vertices_ = convert(path, *mesh);
    triangles_ = std::move(vertices_.triangles);
    vertices_.triangles = {};
    bounds_ = vertices_.bounds();
    report(options.progress, "read", file_size_, file_size_);
  }

  bool next(TriangleBatch& batch) override {
    batch.clear();
    const std::size_t end = std::min(triangles_.size(), cursor_ + capacity_);
    batch.triangles.assign(triangles_.begin() + static_cast<std::ptrdiff_t>(cursor_),
                           triangles_.begin() + static_cast<std::ptrdiff_t>(end));
    cursor_ = end;
    return !batch.triangles.empty();
  }

  const IndexedMesh& vertices() const override { return vertices_; }
  Box3 bounds() override { return bounds_; }
  std::uint64_t triangles_hint() const override { return triangles_.size(); }
  // The file is decoded before the first batch; report faces served as the same fraction of its bytes.
  std::uint64_t bytes_read() const override {
    return triangles_.empty() ? file_size_ : file_size_ * cursor_ / triangles_.size();
  }
  std::uint64_t bytes_total() const override { return file_size_; }
  const std::string& path() const override { return path_; }

 private:
  std::string path_;
  std::size_t capacity_;
  std::uint64_t file_size_ = 0;
  IndexedMesh vertices_;
  std::vector<Triangle> triangles_;
  std::size_t cursor_ = 0;
  Box3 bounds_;
};

// Adds a float attribute with one value per point (identity mapping).
template <typename Vec>
void add_float_attribute(draco::Mesh& mesh, draco::GeometryAttribute::Type type,
                         const std::vector<Vec>& values) {
  constexpr int components = Vec::RowsAtCompileTime;
  draco::GeometryAttribute attribute;
  attribute.Init(type, nullptr, components, draco::DT_FLOAT32, false, sizeof(float) * components, 0);
  draco::PointAttribute* added = mesh.attribute(mesh.AddAttribute(attribute, true, values.size()));
  for (std::size_t i = 0; i < values.size(); ++i) {
    added->SetAttributeValue(draco::AttributeValueIndex(static_cast<std::uint32_t>(i)), values[i].data());
  }
}

// Draco quantizes positions and uvs over their range, the largest span of one component, a float difference
// inside the encoder, with the scale (2^bits - 1) / range, a float too: values spanning more than the largest
// float (say -2e38 to 2e38) overflow the range, values spanning too little (1e-34 at 16 bits) overflow the
// scale. Either way the encoder wrote garbage or crashed. (Normals are normalized first, so any finite ones
// encode; a zero range is Draco's own special case.)
template <class Vec>
void check_quantizable(const std::string& path, const char* what, const std::vector<Vec>& values, int bits) {
  auto text = [](float value) {
    char buffer[16];
    return std::string(buffer, print_float(buffer, value));
  };
  float range = 0;
  for (int axis = 0; axis < Vec::RowsAtCompileTime && !values.empty(); ++axis) {
    float lo = values[0][axis], hi = lo;
    for (const Vec& v : values) {
      lo = std::min(lo, v[axis]);
      hi = std::max(hi, v[axis]);
    }
    if (!std::isfinite(hi - lo)) {
      throw Error(
          path, {},
          std::string("cannot write Draco: the ") + what + " span " + text(lo) + " to " + text(hi) +
              " along axis " + "xyz"[axis] +
              ", more than a float can hold, and Draco quantizes over that span (PLY or OBJ can hold them)");
    }
    range = std::max(range, hi - lo);
  }
  const float steps = static_cast<float>((std::uint32_t{1} << bits) - 1);
  if (range > 0 && !std::isfinite(steps / range)) {
    throw Error(path, {},
                std::string("cannot write Draco: the ") + what + " span only " + text(range) +
                    ", too little for Draco's " + std::to_string(bits) +
                    "-bit quantization, whose scale would overflow a float (PLY or OBJ can hold them)");
  }
}

}  // namespace

std::unique_ptr<TriangleStream> open_drc_stream(const std::string& path, const ReadOptions& options) {
  return std::make_unique<DracoStream>(path, options);
}

void write_drc(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options) {
  check_writable(path, mesh);
  if (options.draco_position_bits < 1 || options.draco_position_bits > kMaxDracoPositionBits)
    throw Error(path, {},
                "Draco position bits must be 1.." + std::to_string(kMaxDracoPositionBits) + ", not " +
                    std::to_string(options.draco_position_bits));
  if (options.draco_compression_level < 0 || options.draco_compression_level > 10)
    throw Error(
        path, {},
        "Draco compression level must be 0..10, not " + std::to_string(options.draco_compression_level));
  if (mesh.triangles.empty()) throw Error(path, {}, "cannot write a Draco mesh without faces");

  check_quantizable(path, "positions", mesh.positions, options.draco_position_bits);
  if (mesh.has_uvs()) check_quantizable(path, "texture coordinates", mesh.uvs, kUvBits);

  draco::Mesh out;
  const std::size_t n = mesh.positions.size();
  out.set_num_points(static_cast<std::uint32_t>(n));
  add_float_attribute(out, draco::GeometryAttribute::POSITION, mesh.positions);
  if (mesh.has_normals()) add_float_attribute(out, draco::GeometryAttribute::NORMAL, mesh.normals);
  if (mesh.has_uvs()) add_float_attribute(out, draco::GeometryAttribute::TEX_COORD, mesh.uvs);
  if (mesh.has_colors()) {
    draco::GeometryAttribute attribute;
    attribute.Init(draco::GeometryAttribute::COLOR, nullptr, 4, draco::DT_UINT8, true, 4, 0);
    draco::PointAttribute* added = out.attribute(out.AddAttribute(attribute, true, n));
    for (std::size_t i = 0; i < n; ++i)
      added->SetAttributeValue(draco::AttributeValueIndex(static_cast<std::uint32_t>(i)),
                               mesh.colors[i].data());
  }
  out.SetNumFaces(mesh.triangles.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    out.SetFace(draco::FaceIndex(static_cast<std::uint32_t>(f)),
                {draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
  }
  report(options.progress, "write", 0, mesh.triangles.size());

  draco::Encoder encoder;
  // Draco's edgebreaker coder splits non-manifold edges in time that grows with the square of a vertex's
  // face count (a 640,000-face fan took 50 s to write); past a budget of that work, the sequential coder
  // writes the faces as they are (a larger file, read by every Draco decoder).
  std::vector<std::uint32_t> faces_at(n, 0);
  for (const Triangle& t : mesh.triangles) {
    for (Index v : t) ++faces_at[v];
  }
  double fan_work = 0;
  for (std::uint32_t count : faces_at) {
    if (count > 256) fan_work += double(count) * count;
  }
  if (fan_work > kMaxFanWork) encoder.SetEncodingMethod(draco::MESH_SEQUENTIAL_ENCODING);
  const int speed = 10 - options.draco_compression_level;
  encoder.SetSpeedOptions(speed, speed);
  encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, options.draco_position_bits);
  encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, kNormalBits);
  encoder.SetAttributeQuantization(draco::GeometryAttribute::TEX_COORD, kUvBits);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeMeshToBuffer(out, &buffer);
  if (!status.ok()) throw Error(path, {}, std::string("Draco encoder: ") + status.error_msg());

  AtomicFile file(path);
  file.write(buffer.data(), buffer.size());
  // Before the commit: a callback that throws (a cancel) must leave no file behind.
  report(options.progress, "write", mesh.triangles.size(), mesh.triangles.size());
  file.commit();
}

}  // namespace ocsimp::detail
