// The PLY reader and writers: round trips, every encoding and type, layouts in any order, streaming, the
// shared meshes, and one test per malformed file in tests/data/malformed/ply.

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/ply_writer.h"
#include "test_support.h"

namespace ocsimp {
namespace {

namespace fs = std::filesystem;

void write_bytes(const std::string& path, const std::string& bytes) {
  // A new file rather than a truncated one: ext4 flushes truncated-and-rewritten files to disk on close.
  fs::remove(path);
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good());
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// Binary record bytes in either byte order.
struct Bytes {
  bool big_endian = false;
  std::string data;

  template <class T>
  Bytes& put(T value) {
    char raw[sizeof(T)];
    std::memcpy(raw, &value, sizeof(T));
    if (big_endian) std::reverse(raw, raw + sizeof(T));
    data.append(raw, sizeof(T));
    return *this;
  }
};

std::uint32_t bits(float f) {
  std::uint32_t b;
  std::memcpy(&b, &f, 4);
  return b;
}

// Exact equality, down to the sign of zero.
void expect_same_floats(const float* a, const float* b, int n, const std::string& what, std::size_t i) {
  for (int k = 0; k < n; ++k) {
    ASSERT_EQ(bits(a[k]), bits(b[k])) << what << " " << i << "[" << k << "]: " << a[k] << " vs " << b[k];
  }
}

void expect_same_mesh(const IndexedMesh& a, const IndexedMesh& b) {
  ASSERT_EQ(a.positions.size(), b.positions.size());
  ASSERT_EQ(a.triangles, b.triangles);
  ASSERT_EQ(a.normals.size(), b.normals.size());
  ASSERT_EQ(a.colors, b.colors);
  ASSERT_EQ(a.uvs.size(), b.uvs.size());
  for (std::size_t i = 0; i < a.positions.size(); ++i) {
    expect_same_floats(a.positions[i].data(), b.positions[i].data(), 3, "position", i);
    if (!a.normals.empty()) expect_same_floats(a.normals[i].data(), b.normals[i].data(), 3, "normal", i);
    if (!a.uvs.empty()) expect_same_floats(a.uvs[i].data(), b.uvs[i].data(), 2, "uv", i);
  }
}

// Floats that are hard to print and read back: tiny, huge, subnormal, negative zero, many digits.
float awkward_float(std::size_t i, int channel) {
  static const float kAwkward[] = {
      0.1f,        -0.0f,      1e-30f, 1.17549435e-38f, 1e-40f, 3.4028235e38f,  -2.5e-7f, 0.33333334f,
      16777216.0f, 123456.79f, 1.0f,   -1.0f,           0.5f,   6.02214076e23f, 1e-45f,   -3.14159274f};
  const std::size_t n = sizeof(kAwkward) / sizeof(kAwkward[0]);
  return kAwkward[(i * 7 + static_cast<std::size_t>(channel) * 3) % n];
}

IndexedMesh mesh_with(bool normals, bool colors, bool uvs) {
  IndexedMesh mesh = test::sphere(2);
  // Some positions awkward too (the sphere's are ordinary floats).
  for (std::size_t i = 0; i < mesh.positions.size(); i += 5) mesh.positions[i].x() = awkward_float(i, 0);
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
    if (normals) mesh.normals.emplace_back(awkward_float(i, 1), awkward_float(i, 2), mesh.positions[i].z());
    if (colors) {
      mesh.colors.push_back({static_cast<std::uint8_t>(i * 37), static_cast<std::uint8_t>(i * 11),
                             static_cast<std::uint8_t>(255 - i), static_cast<std::uint8_t>(i * 3)});
    }
    if (uvs) mesh.uvs.emplace_back(awkward_float(i, 3), static_cast<float>(i) / 7.0f);
  }
  return mesh;
}

struct Drained {
  IndexedMesh vertices;
  std::vector<Triangle> triangles;
  std::size_t batches = 0;
  std::size_t largest_batch = 0;
};

Drained drain(const std::string& path, std::size_t capacity) {
  ReadOptions options;
  options.batch_capacity = capacity;
  auto stream = open_triangle_stream(path, options);
  Drained result;
  result.vertices = stream->vertices();
  TriangleBatch batch;
  while (stream->next(batch)) {
    EXPECT_TRUE(batch.corners.empty());
    ++result.batches;
    result.largest_batch = std::max(result.largest_batch, batch.size());
    result.triangles.insert(result.triangles.end(), batch.triangles.begin(), batch.triangles.end());
  }
  EXPECT_TRUE(batch.triangles.empty());
  EXPECT_FALSE(stream->next(batch));
  EXPECT_EQ(stream->bytes_read(), stream->bytes_total());
  return result;
}

const char* const kSquareAscii =
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
const std::vector<Triangle> kSquareTriangles = {{0, 1, 2}, {0, 2, 3}};

// ---- Round trips ------------------------------------------------------------------------------------------

TEST(PlyRoundTrip, EveryAttributeCombinationBinaryAndAsciiIsExact) {
  test::TempDir dir;
  for (int mask = 0; mask < 8; ++mask) {
    const IndexedMesh mesh = mesh_with(mask & 1, mask & 2, mask & 4);
    SCOPED_TRACE("attributes mask " + std::to_string(mask));
    WriteOptions binary, ascii;
    ascii.ascii = true;
    // Fresh names each round: ext4 flushes a file renamed over an existing one to disk, which is slow.
    auto round = [&](const std::string& name) { return dir / (std::to_string(mask) + "_" + name); };
    write_mesh(round("binary.ply"), mesh, binary);
    write_mesh(round("ascii.ply"), mesh, ascii);
    const IndexedMesh from_binary = read_mesh(round("binary.ply"));
    const IndexedMesh from_ascii = read_mesh(round("ascii.ply"));
    expect_same_mesh(mesh, from_binary);
    expect_same_mesh(mesh, from_ascii);
    // Converting between the encodings loses nothing either.
    write_mesh(round("binary_to_ascii.ply"), from_binary, ascii);
    write_mesh(round("ascii_to_binary.ply"), from_ascii, binary);
    EXPECT_EQ(read_bytes(round("binary_to_ascii.ply")), read_bytes(round("ascii.ply")));
    EXPECT_EQ(read_bytes(round("ascii_to_binary.ply")), read_bytes(round("binary.ply")));
  }
}

TEST(PlyRoundTrip, OutputIsByteIdenticalForIdenticalInput) {
  test::TempDir dir;
  const IndexedMesh mesh = mesh_with(true, true, true);
  for (bool ascii : {false, true}) {
    WriteOptions options;
    options.ascii = ascii;
    const std::string name = ascii ? "ascii" : "binary";
    write_mesh(dir / (name + "_a.ply"), mesh, options);
    write_mesh(dir / (name + "_b.ply"), mesh, options);
    const std::string a = read_bytes(dir / (name + "_a.ply"));
    EXPECT_FALSE(a.empty());
    EXPECT_EQ(a, read_bytes(dir / (name + "_b.ply")));
  }
}

TEST(PlyRoundTrip, BinaryFileHasTheDocumentedLayout) {
  test::TempDir dir;
  IndexedMesh mesh;
  mesh.positions = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  mesh.triangles = {{0, 1, 2}};
  mesh.colors = {Color{1, 2, 3, 4}, Color{5, 6, 7, 8}, Color{9, 10, 11, 12}};
  write_mesh(dir / "m.ply", mesh);
  const std::string bytes = read_bytes(dir / "m.ply");
  const std::string header =
      "ply\nformat binary_little_endian 1.0\ncomment written by ocsimp\nelement vertex 3\n"
      "property float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  ASSERT_EQ(bytes.size(), header.size() + 3 * 16 + 13);
  float y;
  std::memcpy(&y, bytes.data() + header.size() + 16 + 4, 4);
  EXPECT_EQ(y, 5.0f);
  EXPECT_EQ(bytes[header.size() + 3 * 16], 3);  // the face's corner count
}

TEST(PlyRoundTrip, AsciiWriterUsesShortestFloats) {
  test::TempDir dir;
  IndexedMesh mesh;
  mesh.positions = {{0.1f, -0.0f, 1e-30f}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  WriteOptions options;
  options.ascii = true;
  write_mesh(dir / "m.ply", mesh, options);
  const std::string text = read_bytes(dir / "m.ply");
  EXPECT_NE(text.find("end_header\n0.1 -0 1e-30\n1 0 0\n0 1 0\n3 0 1 2\n"), std::string::npos) << text;
}

// ---- Writers ----------------------------------------------------------------------------------------------

TEST(PlyStreamWriter, WritesWhatItIsGiven) {
  test::TempDir dir;
  PlyLayout layout;
  layout.vertices = 4;
  layout.faces = 2;
  layout.normals = true;
  {
    PlyStreamWriter writer(dir / "square.ply", layout);
    const Vec3f up(0, 0, 1);
    for (const Vec3f& p : {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(1, 1, 0), Vec3f(0, 1, 0)})
      writer.add_vertex(p, &up);
    writer.add_face({0, 1, 2});
    writer.add_face({0, 2, 3});
    writer.finish();
  }
  const IndexedMesh mesh = read_mesh(dir / "square.ply");
  EXPECT_EQ(mesh.triangles, kSquareTriangles);
  ASSERT_EQ(mesh.normals.size(), 4u);
  EXPECT_EQ(mesh.normals[2], Vec3f(0, 0, 1));
  EXPECT_EQ(mesh.positions[2], Vec3f(1, 1, 0));
  EXPECT_FALSE(mesh.has_colors());
}

TEST(PlyStreamWriter, RecordByRecordMatchesWriteMesh) {
  test::TempDir dir;
  const IndexedMesh mesh = mesh_with(true, true, true);
  for (bool ascii : {false, true}) {
    PlyLayout layout;
    layout.vertices = mesh.positions.size();
    layout.faces = mesh.triangles.size();
    layout.normals = layout.colors = layout.uvs = true;
    layout.ascii = ascii;
    const std::string name = ascii ? "ascii" : "binary";
    {
      PlyStreamWriter writer(dir / (name + "_single.ply"), layout);
      for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
        writer.add_vertex(mesh.positions[i], &mesh.normals[i], &mesh.colors[i], &mesh.uvs[i]);
      }
      for (const Triangle& t : mesh.triangles) writer.add_face(t);
      writer.finish();
    }
    WriteOptions options;
    options.ascii = ascii;
    write_mesh(dir / (name + "_mesh.ply"), mesh, options);
    EXPECT_EQ(read_bytes(dir / (name + "_single.ply")), read_bytes(dir / (name + "_mesh.ply")));
  }
}

bool folder_is_empty(const fs::path& folder) {
  return fs::directory_iterator(folder) == fs::directory_iterator();
}

TEST(PlyStreamWriter, UnfinishedWriterLeavesNoFile) {
  test::TempDir dir;
  PlyLayout layout;
  layout.vertices = 3;
  layout.faces = 1;
  {
    PlyStreamWriter writer(dir / "never.ply", layout);
    writer.add_vertex({0, 0, 0});
    writer.add_vertex({1, 0, 0});
  }
  EXPECT_FALSE(fs::exists(dir / "never.ply"));
  EXPECT_TRUE(folder_is_empty(dir.path)) << "a temporary was left behind";
}

TEST(PlyStreamWriter, FinishWithMissingRecordsThrowsAndLeavesNoFile) {
  test::TempDir dir;
  PlyLayout layout;
  layout.vertices = 3;
  layout.faces = 2;
  {
    PlyStreamWriter writer(dir / "short.ply", layout);
    for (int i = 0; i < 3; ++i) writer.add_vertex({float(i), 0, 0});
    writer.add_face({0, 1, 2});
    EXPECT_THROW(writer.finish(), Error);
  }
  EXPECT_TRUE(folder_is_empty(dir.path));
}

TEST(PlyStreamWriter, FailedWriteKeepsThePreviousFile) {
  test::TempDir dir;
  write_bytes(dir / "kept.ply", kSquareAscii);
  IndexedMesh bad = test::grid_square(2);
  bad.triangles.push_back({0, 1, 99});  // out of range: the writer refuses it
  EXPECT_THROW(write_mesh(dir / "kept.ply", bad), Error);
  EXPECT_EQ(read_bytes(dir / "kept.ply"), kSquareAscii);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path), fs::directory_iterator()), 1);
}

TEST(PlyStreamWriter, AReplacedFileKeepsItsPermissions) {
  // Outputs are renamed over the old file: they used to take the usual 0666 & ~umask, so a private 0600 file
  // became readable by everyone.
  test::TempDir dir;
  const std::string path = dir / "private.ply";
  write_mesh(path, test::grid_square(2));
  for (const fs::perms mode :
       {fs::perms::owner_read | fs::perms::owner_write, fs::perms::owner_all | fs::perms::group_read}) {
    fs::permissions(path, mode);
    write_mesh(path, test::grid_square(3));
    EXPECT_EQ(fs::status(path).permissions(), mode);
  }
  // A new file gets the usual ones, not mkstemp's 0600.
  const mode_t mask = ::umask(0);
  ::umask(mask);
  write_mesh(dir / "new.ply", test::grid_square(2));
  EXPECT_EQ(static_cast<unsigned>(fs::status(dir / "new.ply").permissions()), 0666u & ~mask);
}

// An output path that is a symbolic link used to be renamed over: the link became a regular file and its
// target kept the old mesh. Writing goes through the links now, as a shell redirection does.
// A name up to the file system's 255 bytes is valid, but from 244 bytes on its temporary's decoration (a
// dot before, ".tmp.XXXXXX" after) went past the limit, and writing failed.
TEST(PlyStreamWriter, AnOutputNameOfTheLongestLengthIsWritten) {
  test::TempDir dir;
  for (std::size_t length : {243u, 244u, 255u}) {
    const std::string name = std::string(length - 4, 'n') + ".ply";
    write_mesh(dir / name, test::grid_square(2));
    EXPECT_EQ(read_mesh(dir / name).face_count(), 8u) << length;
  }
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path), fs::directory_iterator()), 3);
}

TEST(PlyStreamWriter, AnOutputThatIsASymbolicLinkIsWrittenThroughIt) {
  test::TempDir dir;
  const std::string real = dir / "real.ply", link = dir / "link.ply", chain = dir / "chain.ply";
  write_mesh(real, test::grid_square(2));
  fs::create_symlink("real.ply", link);  // relative: to the link's folder
  fs::create_symlink(link, chain);       // absolute, to another link
  write_mesh(link, test::grid_square(3));
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(read_mesh(real).face_count(), 18u);
  write_mesh(chain, test::grid_square(4));
  EXPECT_TRUE(fs::is_symlink(chain));
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(read_mesh(real).face_count(), 32u);
  // A dangling link's target is created.
  fs::create_directory(dir / "sub");
  fs::create_symlink("sub/new.ply", dir / "dangling.ply");
  write_mesh(dir / "dangling.ply", test::grid_square(2));
  EXPECT_TRUE(fs::is_symlink(dir / "dangling.ply"));
  EXPECT_EQ(read_mesh(dir / "sub/new.ply").face_count(), 8u);
  // Links in a loop are an error, and leave nothing.
  fs::create_symlink("loop_b.ply", dir / "loop_a.ply");
  fs::create_symlink("loop_a.ply", dir / "loop_b.ply");
  try {
    write_mesh(dir / "loop_a.ply", test::grid_square(2));
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("symbolic links"), std::string::npos) << e.what();
  }
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path), fs::directory_iterator()), 7);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir / "sub"), fs::directory_iterator()), 1);
}

TEST(PlyStreamWriter, RejectsMisuse) {
  test::TempDir dir;
  PlyLayout layout;
  layout.vertices = 3;
  layout.faces = 1;
  layout.colors = true;
  PlyStreamWriter writer(dir / "m.ply", layout);
  EXPECT_THROW(writer.add_vertex({0, 0, 0}), Error);  // the layout has colors
  const Color red{255, 0, 0, 255};
  EXPECT_THROW(writer.add_face({0, 1, 2}), Error);  // before the vertices
  EXPECT_THROW(writer.add_vertex({std::numeric_limits<float>::quiet_NaN(), 0, 0}, nullptr, &red), Error);
  for (int i = 0; i < 3; ++i) writer.add_vertex({float(i), 0, 0}, nullptr, &red);
  EXPECT_THROW(writer.add_vertex({0, 0, 0}, nullptr, &red), Error);  // one too many
  EXPECT_THROW(writer.add_face({0, 1, 3}), Error);                   // no vertex 3
  writer.add_face({0, 1, 2});
  EXPECT_THROW(writer.add_face({0, 1, 2}), Error);  // one too many
  writer.finish();
  EXPECT_EQ(read_mesh(dir / "m.ply").colors[1], red);
}

TEST(PlyWriter, RejectsAttributeArraysOfTheWrongSize) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(1);
  mesh.normals.resize(1);
  EXPECT_THROW(write_mesh(dir / "m.ply", mesh), Error);
  EXPECT_TRUE(folder_is_empty(dir.path));
}

// ---- Encodings and types ----------------------------------------------------------------------------------

struct TypeCase {
  const char* name;
  int size;
  bool is_float;
  bool is_signed;
};
const TypeCase kTypes[] = {
    {"char", 1, false, true},    {"uchar", 1, false, false},  {"short", 2, false, true},
    {"ushort", 2, false, false}, {"int", 4, false, true},     {"uint", 4, false, false},
    {"float", 4, true, true},    {"double", 8, true, true},   {"int8", 1, false, true},
    {"uint8", 1, false, false},  {"int16", 2, false, true},   {"uint16", 2, false, false},
    {"int32", 4, false, true},   {"uint32", 4, false, false}, {"float32", 4, true, true},
    {"float64", 8, true, true},
};

void put_typed(Bytes& out, const TypeCase& type, double value) {
  if (type.is_float) {
    type.size == 4 ? (void)out.put(static_cast<float>(value)) : (void)out.put(value);
    return;
  }
  const auto v = static_cast<std::int64_t>(value);
  switch (type.size) {
    case 1:
      type.is_signed ? (void)out.put(static_cast<std::int8_t>(v))
                     : (void)out.put(static_cast<std::uint8_t>(v));
      break;
    case 2:
      type.is_signed ? (void)out.put(static_cast<std::int16_t>(v))
                     : (void)out.put(static_cast<std::uint16_t>(v));
      break;
    default:
      type.is_signed ? (void)out.put(static_cast<std::int32_t>(v))
                     : (void)out.put(static_cast<std::uint32_t>(v));
  }
}

// A pentagon fan and a triangle over 6 vertices, with `coordinate` types for x y z, `count` and `index`
// types for the face list, in the given encoding.
std::string typed_file(const std::string& format, const TypeCase& coordinate, const TypeCase& count,
                       const TypeCase& index) {
  std::string header = "ply\nformat " + format + " 1.0\nelement vertex 6\n";
  for (const char* axis : {"x", "y", "z"})
    header += std::string("property ") + coordinate.name + " " + axis + "\n";
  header +=
      std::string("element face 2\nproperty list ") + count.name + " " + index.name + " vertex_indices\n";
  header += "end_header\n";
  const double xyz[6][3] = {{0, 0, 0}, {2, 0, 0}, {3, 2, 0}, {1, 3, 0}, {0, 2, 0}, {1, 1, 5}};
  const std::vector<std::vector<int>> faces = {{0, 1, 2, 3, 4}, {5, 1, 0}};
  if (format == "ascii") {
    std::ostringstream body;
    for (const auto& p : xyz) body << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
    for (const auto& f : faces) {
      body << f.size();
      for (int i : f) body << ' ' << i;
      body << '\n';
    }
    return header + body.str();
  }
  Bytes out;
  out.big_endian = format == "binary_big_endian";
  for (const auto& p : xyz) {
    for (double c : p) put_typed(out, coordinate, c);
  }
  for (const auto& f : faces) {
    put_typed(out, count, static_cast<double>(f.size()));
    for (int i : f) put_typed(out, index, i);
  }
  return header + out.data;
}

TEST(PlyTypes, EveryCountAndIndexTypeInEveryEncoding) {
  test::TempDir dir;
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {5, 1, 0}};
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    for (const TypeCase& count : kTypes) {
      if (count.is_float) continue;  // list counts must be integers (see malformed/list_count_float.ply)
      for (const TypeCase& index : kTypes) {
        SCOPED_TRACE(std::string(format) + " list " + count.name + " " + index.name);
        write_bytes(dir / "t.ply", typed_file(format, kTypes[6], count, index));
        const IndexedMesh mesh = read_mesh(dir / "t.ply");
        ASSERT_EQ(mesh.triangles, expected);
        EXPECT_EQ(mesh.positions[2], Vec3f(3, 2, 0));
      }
    }
  }
}

TEST(PlyTypes, EveryCoordinateTypeInEveryEncoding) {
  test::TempDir dir;
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    for (const TypeCase& coordinate : kTypes) {
      SCOPED_TRACE(std::string(format) + " coordinates " + coordinate.name);
      write_bytes(dir / "t.ply", typed_file(format, coordinate, kTypes[1], kTypes[4]));
      const IndexedMesh mesh = read_mesh(dir / "t.ply");
      ASSERT_EQ(mesh.positions.size(), 6u);
      EXPECT_EQ(mesh.positions[4], Vec3f(0, 2, 0));
      EXPECT_EQ(mesh.positions[5], Vec3f(1, 1, 5));
      EXPECT_EQ(mesh.triangles.size(), 4u);
    }
  }
}

TEST(PlyTypes, DoubleCoordinatesAreRoundedToFloat) {
  test::TempDir dir;
  Bytes out;
  const double values[] = {0.1, 1.0 / 3.0, -1e-300, 2, 0, 0, 0, 2, 0};
  for (double v : values) out.put(v);
  out.put<std::uint8_t>(3).put<std::int32_t>(0).put<std::int32_t>(1).put<std::int32_t>(2);
  write_bytes(dir / "d.ply",
              "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
              "property double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n" +
                  out.data);
  const IndexedMesh mesh = read_mesh(dir / "d.ply");
  EXPECT_EQ(mesh.positions[0], Vec3f(0.1f, float(1.0 / 3.0), -0.0f));
  EXPECT_EQ(mesh.positions[1], Vec3f(2, 0, 0));
  EXPECT_EQ(mesh.triangles, (std::vector<Triangle>{{0, 1, 2}}));
}

// An ASCII PLY of one triangle whose vertices have red, green and blue properties of `type`, with these
// values ("r g b") at its three corners.
std::string rgb_triangle(const std::string& type, const std::array<std::string, 3>& colors) {
  return "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
         "property " +
         type + " red\nproperty " + type + " green\nproperty " + type +
         " blue\n"
         "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 " +
         colors[0] + "\n1 0 0 " + colors[1] + "\n0 1 0 " + colors[2] + "\n3 0 1 2\n";
}

// Unsigned 16-bit colors span 0..65535 (mid-grey, 32768, is 128). Other integer types hold 0..255: read over
// their type's range, an int's 255 came out black; values outside are clamped, and the reader says how many
// vertices have one. An int channel holding 0..255 loses nothing, so it gets no note on 8 bits.
TEST(PlyTypes, IntegerColorsSpanZeroTo255ButUshortSpansItsRange) {
  test::TempDir dir;
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property ushort red\nproperty short green\nproperty uint blue\nproperty char alpha\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  write_bytes(dir / "c.ply", header +
                                 "0 0 0 65535 255 0 100\n"
                                 "1 0 0 32768 -5 128 -3\n"
                                 "0 1 0 300 16384 4294967295 127\n"
                                 "3 0 1 2\n");
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  const IndexedMesh mesh = read_mesh(dir / "c.ply", options);
  ASSERT_EQ(mesh.colors.size(), 3u);
  EXPECT_EQ(mesh.colors[0], (Color{255, 255, 0, 100}));
  EXPECT_EQ(mesh.colors[1], (Color{128, 0, 128, 0}));
  EXPECT_EQ(mesh.colors[2], (Color{1, 255, 255, 127}));
  EXPECT_EQ(told,
            (std::vector<std::string>{
                "2 vertices have an integer color channel outside 0..255, clamped to it",
                "its colors, stored as ushort, are kept to 8 bits a channel, as every output writes them"}));

  told.clear();
  write_bytes(dir / "i.ply", rgb_triangle("int", {"255 0 128", "1 2 3", "7 8 9"}));
  EXPECT_EQ(read_mesh(dir / "i.ply", options).colors[0], (Color{255, 0, 128, 255}));
  EXPECT_TRUE(told.empty()) << told[0];
}

// A big-endian file written by hand with every attribute, and unusual types for each.
TEST(PlyTypes, BigEndianWithAttributes) {
  test::TempDir dir;
  const std::string header =
      "ply\nformat binary_big_endian 1.0\ncomment by hand\nelement vertex 3\n"
      "property double x\nproperty double y\nproperty double z\n"
      "property float nx\nproperty float ny\nproperty float nz\n"
      "property float red\nproperty float green\nproperty float blue\n"
      "property float s\nproperty float t\n"
      "element face 1\nproperty list ushort uint vertex_index\nend_header\n";
  Bytes out;
  out.big_endian = true;
  for (int i = 0; i < 3; ++i) {
    out.put(double(i)).put(double(2 * i)).put(-0.5);
    out.put(0.0f).put(0.0f).put(1.0f);
    out.put(0.0f).put(0.5f).put(1.5f);  // colors in [0, 1]; 1.5 clamps to 255
    out.put(float(i) / 4).put(0.75f);
  }
  out.put<std::uint16_t>(3).put<std::uint32_t>(2).put<std::uint32_t>(0).put<std::uint32_t>(1);
  write_bytes(dir / "be.ply", header + out.data);
  const IndexedMesh mesh = read_mesh(dir / "be.ply");
  ASSERT_EQ(mesh.positions.size(), 3u);
  EXPECT_EQ(mesh.positions[2], Vec3f(2, 4, -0.5f));
  EXPECT_EQ(mesh.normals[1], Vec3f(0, 0, 1));
  EXPECT_EQ(mesh.colors[0], (Color{0, 128, 255, 255}));
  EXPECT_EQ(mesh.uvs[1], Vec2f(0.25f, 0.75f));
  EXPECT_EQ(mesh.triangles, (std::vector<Triangle>{{2, 0, 1}}));
}

TEST(PlyTypes, BigEndianMatchesLittleEndian) {
  test::TempDir dir;
  const IndexedMesh mesh = test::sphere(2);
  // Write the big-endian twin of what our writer produces, by hand.
  std::string header =
      "ply\nformat binary_big_endian 1.0\nelement vertex " + std::to_string(mesh.positions.size()) +
      "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
      std::to_string(mesh.triangles.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  Bytes out;
  out.big_endian = true;
  for (const Vec3f& p : mesh.positions) out.put(p.x()).put(p.y()).put(p.z());
  for (const Triangle& t : mesh.triangles) {
    out.put<std::uint8_t>(3);
    for (Index i : t) out.put(static_cast<std::int32_t>(i));
  }
  write_bytes(dir / "be.ply", header + out.data);
  expect_same_mesh(mesh, read_mesh(dir / "be.ply"));
}

// Floating-point colors span [0, 1]; some writers put 0..255 in them, and every such color came out white
// without a word. Values outside are still clamped, and the reader says how many vertices have one.
TEST(PlyTypes, FloatColorsOutsideZeroToOneAreClampedWithAWarning) {
  test::TempDir dir;
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property float red\nproperty float green\nproperty float blue\nproperty double alpha\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  write_bytes(dir / "c.ply", header + "0 0 0 200 50 25 1\n1 0 0 0 0.5 1 1\n0 1 0 0 0 -0.25 1\n3 0 1 2\n");
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  const IndexedMesh mesh = read_mesh(dir / "c.ply", options);
  EXPECT_EQ(mesh.colors, (std::vector<Color>{{255, 255, 255, 255}, {0, 128, 255, 255}, {0, 0, 0, 255}}));
  // And that they are kept to 8 bits, as every output writes them.
  const std::string eight_bits =
      "its colors, stored as float, are kept to 8 bits a channel, as every output writes them";
  ASSERT_EQ(told.size(), 2u);
  EXPECT_EQ(told[0],
            "2 vertices have a floating-point color channel outside 0..1, clamped to it (are the colors on a "
            "0..255 scale?)");
  EXPECT_EQ(told[1], eight_bits);
  told.clear();
  write_bytes(dir / "d.ply", header + "0 0 0 1 0.5 0 1\n1 0 0 0 0.5 1 0\n0 1 0 0 0 0.25 1\n3 0 1 2\n");
  EXPECT_EQ(read_mesh(dir / "d.ply", options).colors.size(), 3u);
  EXPECT_EQ(told, std::vector<std::string>{eight_bits});
  // 8-bit colors lose nothing: no word.
  told.clear();
  write_bytes(dir / "e.ply", rgb_triangle("uchar", {"1 2 3", "4 5 6", "7 8 9"}));
  EXPECT_EQ(read_mesh(dir / "e.ply", options).colors[2], (Color{7, 8, 9, 255}));
  EXPECT_TRUE(told.empty()) << told[0];
}

// A scan's confidence values, face colors, an edge element or a texture file went missing from every output
// without a word. The reader names what it does not read, once, and says nothing of a file it reads whole.
TEST(PlyLayout, SaysWhatItDoesNotRead) {
  test::TempDir dir;
  const std::string body = "0 0 0 1 2\n1 0 0 1 2\n0 1 0 1 2\n3 0 1 2 255 0 0\n0 1\n1 2\n";
  write_bytes(
      dir / "extra.ply",
      "ply\nformat ascii 1.0\ncomment TextureFile the skin.png\ncomment TextureFile the skin.png\n"
      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property float confidence\nproperty uchar intensity\n"
      "element face 1\nproperty list uchar int vertex_indices\nproperty uchar red\nproperty uchar green\n"
      "property uchar blue\nelement edge 2\nproperty int vertex1\nproperty int vertex2\n"
      "element camera 0\nproperty float f\nend_header\n" +
          body);
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  const IndexedMesh mesh = read_mesh(dir / "extra.ply", options);
  EXPECT_EQ(mesh.triangles, (std::vector<Triangle>{{0, 1, 2}}));
  ASSERT_EQ(told.size(), 1u);
  // The empty camera element holds nothing to lose.
  EXPECT_EQ(
      told[0],
      "not read, so no output keeps them (ocsimp reads triangles and their vertices' positions, normals, "
      "colors and texture coordinates): vertex properties confidence, intensity; face properties red, "
      "green, blue; element edge; texture file the skin.png");
  // A long list is cut short.
  std::string header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n";
  std::string line;
  for (int i = 0; i < 40; ++i) {
    header += "property uchar p" + std::to_string(i) + "\n";
    line += " 0";
  }
  header += "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  write_bytes(dir / "many.ply",
              header + "0 0" + line + " 0\n1 0" + line + " 0\n0 1" + line + " 0\n3 0 1 2\n");
  told.clear();
  EXPECT_EQ(read_mesh(dir / "many.ply", options).positions[1], Vec3f(1, 0, 0));
  ASSERT_EQ(told.size(), 1u);
  EXPECT_NE(told[0].find("vertex properties p0, p1, p2, p3, p4, p5 and more"), std::string::npos) << told[0];
  // A file that then fails gets its error alone: it is said once every face is read.
  write_bytes(dir / "cut.ply", header + "0 0" + line + " 0\n1 0" + line + " 0\n0 1" + line + " 0\n3 0 1\n");
  told.clear();
  EXPECT_THROW(read_mesh(dir / "cut.ply", options), Error);
  EXPECT_TRUE(told.empty()) << told[0];
  // Nothing to say of a file of positions, normals, colors and uvs only.
  write_mesh(dir / "plain.ply", test::sphere(2));
  told.clear();
  read_mesh(dir / "plain.ply", options);
  EXPECT_TRUE(told.empty()) << told[0];
}

TEST(PlyTypes, ColorsAsUcharWithoutAlphaGetOpaqueAlpha) {
  test::TempDir dir;
  write_bytes(
      dir / "c.ply",
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
      "property float texture_u\nproperty float texture_v\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0 10 20 30 0.5 0.25\n1 0 0 255 0 0 1 1\n0 1 0 0 0 0 0 0\n3 0 1 2\n");
  const IndexedMesh mesh = read_mesh(dir / "c.ply");
  EXPECT_EQ(mesh.colors[0], (Color{10, 20, 30, 255}));
  EXPECT_EQ(mesh.colors[1], (Color{255, 0, 0, 255}));
  EXPECT_EQ(mesh.uvs[0], Vec2f(0.5f, 0.25f));
  EXPECT_FALSE(mesh.has_normals());
}

TEST(PlyTypes, IncompleteAttributesAreNotKept) {
  test::TempDir dir;
  write_bytes(
      dir / "c.ply",
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty uchar red\nproperty float u\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0 1 0 5 1\n1 0 0 1 0 5 1\n0 1 0 1 0 5 1\n3 0 1 2\n");
  const IndexedMesh mesh = read_mesh(dir / "c.ply");
  EXPECT_FALSE(mesh.has_normals());
  EXPECT_FALSE(mesh.has_colors());
  EXPECT_FALSE(mesh.has_uvs());
  EXPECT_EQ(mesh.positions[1], Vec3f(1, 0, 0));
}

TEST(PlyTypes, CrlfHeaderCommentsAndObjInfo) {
  test::TempDir dir;
  write_bytes(
      dir / "crlf.ply",
      "ply\r\nformat ascii 1.0\r\ncomment made on Windows\r\nobj_info scanner 7\r\nelement vertex 4\r\n"
      "property float x\r\nproperty float y\r\nproperty float z\r\nelement face 2\r\n"
      "property list uchar int vertex_indices\r\nend_header\r\n"
      "0 0 0\r\n1 0 0\r\n1 1 0\r\n0 1 0\r\n3 0 1 2\r\n3 0 2 3\r\n");
  EXPECT_EQ(read_mesh(dir / "crlf.ply").triangles, kSquareTriangles);
  // Saved by a Windows editor with a UTF-8 byte order mark, under any name: read as OBJ and STL files are.
  write_bytes(dir / "bom.txt", "\xEF\xBB\xBF" + read_bytes(dir / "crlf.ply"));
  EXPECT_EQ(detect_format(dir / "bom.txt"), FileFormat::ply);
  EXPECT_EQ(read_mesh(dir / "bom.txt").triangles, kSquareTriangles);

  Bytes out;
  for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 0.f}) out.put(v);
  out.put<std::uint8_t>(3).put<std::int32_t>(0).put<std::int32_t>(1).put<std::int32_t>(2);
  write_bytes(dir / "crlf_binary.ply",
              "ply\r\nformat binary_little_endian 1.0\r\nelement vertex 3\r\nproperty float x\r\n"
              "property float y\r\nproperty float z\r\nelement face 1\r\n"
              "property list uchar int vertex_indices\r\nend_header\r\n" +
                  out.data);
  const IndexedMesh binary = read_mesh(dir / "crlf_binary.ply");
  EXPECT_EQ(binary.positions[2], Vec3f(1, 1, 0));
  EXPECT_EQ(binary.triangles, (std::vector<Triangle>{{0, 1, 2}}));
  // A line break after the binary data, as some writers end their files, is not data (it was refused).
  write_bytes(dir / "crlf_binary.ply", read_bytes(dir / "crlf_binary.ply") + "\r\n");
  EXPECT_EQ(read_mesh(dir / "crlf_binary.ply").triangles, binary.triangles);
}

TEST(PlyTypes, AsciiToleratesBlankLinesAndExtraSpacesAndNoFinalNewline) {
  test::TempDir dir;
  write_bytes(
      dir / "loose.ply",
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "\n  0 0 0  \n1\t0 +0\n\n1 1 0\n0 1 0\n3 0 1 2\n  3 0 2 3");
  EXPECT_EQ(read_mesh(dir / "loose.ply").triangles, kSquareTriangles);
  // Trailing blanks on the first line too, as on every other header line (it was refused as not a PLY).
  write_bytes(dir / "blank.ply", "ply \t" + read_bytes(dir / "loose.ply").substr(3));
  EXPECT_EQ(read_mesh(dir / "blank.ply").triangles, kSquareTriangles);
}

// ---- Layouts
// ------------------------------------------------------------------------------------------------

// A concave polygon is cut inside its outline, as an OBJ's is (its fan covered the notches), also when its
// triangles do not fit the batch they start in.
TEST(PlyLayout, ConcavePolygonsAreCutInsideTheirOutline) {
  test::TempDir dir;
  // A comb with three notches, 12 corners, in z = 0.
  const std::vector<std::array<float, 2>> comb = {{0, 0}, {7, 0}, {7, 3}, {6, 3}, {6, 1}, {5, 1},
                                                  {5, 3}, {4, 3}, {4, 1}, {3, 1}, {3, 3}, {0, 3}};
  std::string text =
      "ply\nformat ascii 1.0\nelement vertex 12\nproperty float x\nproperty float y\n"
      "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& p : comb) text += std::to_string(p[0]) + " " + std::to_string(p[1]) + " 0\n";
  text += "12 0 1 2 3 4 5 6 7 8 9 10 11\n3 0 1 11\n";
  write_bytes(dir / "comb.ply", text);
  const IndexedMesh mesh = read_mesh(dir / "comb.ply");
  ASSERT_EQ(mesh.face_count(), 11u);
  double area = 0;
  for (std::size_t f = 0; f < 10; ++f) {
    const Triangle& t = mesh.triangles[f];
    const Vec3f n =
        (mesh.positions[t[1]] - mesh.positions[t[0]]).cross(mesh.positions[t[2]] - mesh.positions[t[0]]);
    EXPECT_GT(n.z(), 0) << "a triangle turns against its polygon";
    area += 0.5 * n.z();
    // Inside: no centroid in a notch (x in (3, 4) or (5, 6), y above 1).
    const Vec3f c = (mesh.positions[t[0]] + mesh.positions[t[1]] + mesh.positions[t[2]]) / 3;
    const bool notch = c.y() > 1 && ((c.x() > 3 && c.x() < 4) || (c.x() > 5 && c.x() < 6));
    EXPECT_FALSE(notch) << c.transpose();
  }
  EXPECT_NEAR(area, 7 * 3 - 2 * 2, 1e-5);
  EXPECT_EQ(mesh.triangles[10], (Triangle{0, 1, 11}));
  // In batches of 4, the polygon's 10 triangles span three of them: the same triangles, in the same order.
  ReadOptions options;
  options.batch_capacity = 4;
  auto stream = open_triangle_stream(dir / "comb.ply", options);
  std::vector<Triangle> streamed;
  TriangleBatch batch;
  while (stream->next(batch)) {
    EXPECT_LE(batch.size(), 4u);
    streamed.insert(streamed.end(), batch.triangles.begin(), batch.triangles.end());
  }
  EXPECT_EQ(streamed, mesh.triangles);
}

TEST(PlyLayout, PolygonsAreFanTriangulated) {
  test::TempDir dir;
  // A quad, a hexagon, a triangle: 2 + 4 + 1 triangles.
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 3\nproperty list uchar int vertex_indices\nend_header\n";
  const std::string vertices = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n3 0 0\n3 1 0\n2 1 0\n";
  write_bytes(dir / "poly.ply", header + vertices + "4 0 1 2 3\n6 4 5 6 7 2 1\n3 7 6 5\n");
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}, {4, 5, 6}, {4, 6, 7},
                                          {4, 7, 2}, {4, 2, 1}, {7, 6, 5}};
  EXPECT_EQ(read_mesh(dir / "poly.ply").triangles, expected);
  // A triangle written as a quad with a corner twice is one triangle, not one and a degenerate one.
  const std::string repeated_header =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n";
  write_bytes(dir / "repeated.ply", repeated_header + "4 0 1 2 2\n5 3 0 0 1 2\n");
  EXPECT_EQ(read_mesh(dir / "repeated.ply").triangles,
            (std::vector<Triangle>{{0, 1, 2}, {3, 0, 1}, {3, 1, 2}}));

  // The same in binary, where triangles take the fast path and polygons interrupt it.
  Bytes out;
  for (int i = 0; i < 8; ++i)
    out.put(float(i % 4 == 1 || i % 4 == 2) + (i >= 4 ? 2.f : 0.f)).put(float(i % 4 >= 2)).put(0.f);
  auto face = [&](std::vector<int> corners) {
    out.put(static_cast<std::uint8_t>(corners.size()));
    for (int c : corners) out.put(static_cast<std::int32_t>(c));
  };
  face({0, 1, 2});
  face({0, 1, 2, 3});
  face({4, 5, 6});
  face({4, 5, 6, 7, 2, 1});
  face({7, 6, 5});
  std::string binary_header = header;
  binary_header.replace(binary_header.find("ascii"), 5, "binary_little_endian");
  binary_header.replace(binary_header.find("face 3"), 6, "face 5");
  write_bytes(dir / "poly_binary.ply", binary_header + out.data);
  const std::vector<Triangle> expected_binary = {{0, 1, 2}, {0, 1, 2}, {0, 2, 3}, {4, 5, 6}, {4, 5, 6},
                                                 {4, 6, 7}, {4, 7, 2}, {4, 2, 1}, {7, 6, 5}};
  const IndexedMesh mesh = read_mesh(dir / "poly_binary.ply");
  EXPECT_EQ(mesh.triangles, expected_binary);
  EXPECT_EQ(mesh.positions[6], Vec3f(3, 1, 0));
  auto stream = open_triangle_stream(dir / "poly_binary.ply");
  EXPECT_EQ(stream->triangles_hint(), 5u);  // faces, not triangles: a hint
}

// Float x y z vertex blocks larger than the reader's window are read straight into the positions array, in
// pieces by several threads: every vertex must land in place, the bounds must cover all of them, and a bad
// coordinate or a short file far past the window must still be reported at its own vertex and byte.
TEST(PlyLayout, LargeFloatVertexBlockReadDirectly) {
  test::TempDir dir;
  constexpr std::uint32_t kVertices = 1'500'001;  // 18 MB: past the 4 MiB window and across two batches
  const std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex " +
                             std::to_string(kVertices) +
                             "\nproperty float x\nproperty float y\nproperty float z\nelement face 1\n"
                             "property list uchar int vertex_indices\nend_header\n";
  auto position = [](std::uint32_t v) {
    return Vec3f(static_cast<float>(v % 1000), static_cast<float>(v / 1000),
                 static_cast<float>(v % 7) - 3.0f);
  };
  Bytes vertices;
  for (std::uint32_t v = 0; v < kVertices; ++v) {
    const Vec3f p = position(v);
    vertices.put(p.x()).put(p.y()).put(p.z());
  }
  Bytes face;
  face.put<std::uint8_t>(3).put<std::int32_t>(0).put<std::int32_t>(1).put<std::int32_t>(kVertices - 1);
  write_bytes(dir / "big.ply", header + vertices.data + face.data);

  const IndexedMesh mesh = read_mesh(dir / "big.ply");
  ASSERT_EQ(mesh.positions.size(), kVertices);
  std::uint32_t wrong = 0;
  for (std::uint32_t v = 0; v < kVertices; ++v) wrong += mesh.positions[v] != position(v);
  EXPECT_EQ(wrong, 0u);
  EXPECT_EQ(mesh.triangles, std::vector<Triangle>({{0, 1, kVertices - 1}}));
  const Box3 bounds = open_triangle_stream(dir / "big.ply")->bounds();
  EXPECT_EQ(bounds.lo, Vec3d(0, 0, -3));
  EXPECT_EQ(bounds.hi, Vec3d(999, (kVertices - 1) / 1000, 3));

  // A NaN in the second batch, and a file cut inside it.
  constexpr std::uint32_t kBad = 1'234'567;
  std::string bad = header + vertices.data + face.data;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(bad.data() + header.size() + 12 * std::size_t{kBad} + 4, &nan, 4);
  write_bytes(dir / "nan.ply", bad);
  try {
    read_mesh(dir / "nan.ply");
    FAIL() << "read a NaN coordinate";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 1234567 has a coordinate that is not a finite float"),
              std::string::npos)
        << e.what();
    EXPECT_EQ(e.position().kind, FilePosition::Kind::byte);
    EXPECT_EQ(e.position().value, header.size() + 12 * std::uint64_t{kBad});
  }
  write_bytes(dir / "cut.ply", header + vertices.data.substr(0, 12 * std::size_t{kBad}));
  try {
    read_mesh(dir / "cut.ply");
    FAIL() << "read a truncated vertex block";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("element vertex"), std::string::npos) << e.what();
  }
}

TEST(PlyLayout, TriangleStripsWithRestarts) {
  test::TempDir dir;
  // Strip 0 1 2 3 4 gives (0 1 2) (2 1 3) (2 3 4); after -1, strip 5 6 6 7 has only degenerate triangles, and
  // strip 4 3 5 gives (4 3 5).
  write_bytes(
      dir / "strips.ply",
      "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
      "element tristrips 1\nproperty list int int vertex_indices\nend_header\n"
      "0 0 0\n0 1 0\n1 0 0\n1 1 0\n2 0 0\n2 1 0\n3 0 0\n3 1 0\n"
      "14 0 1 2 3 4 -1 5 6 6 7 -1 4 3 5\n");
  const std::vector<Triangle> expected = {{0, 1, 2}, {2, 1, 3}, {2, 3, 4}, {4, 3, 5}};
  EXPECT_EQ(read_mesh(dir / "strips.ply").triangles, expected);
  const Drained small = drain(dir / "strips.ply", 1);
  EXPECT_EQ(small.triangles, expected);
  EXPECT_EQ(small.largest_batch, 1u);
  // Ascii strips say nothing of their triangle count.
  EXPECT_EQ(open_triangle_stream(dir / "strips.ply")->triangles_hint(), 0u);

  // A binary strip file bounds it by its index count (14 indices for 4 triangles), so a pipeline sizing its
  // stages by the hint never takes the file for smaller than it is.
  Bytes out;
  for (int v = 0; v < 8; ++v) out.put(float(v / 2)).put(float(v % 2)).put(0.0f);
  out.put<std::int32_t>(14);
  for (int i : {0, 1, 2, 3, 4, -1, 5, 6, 6, 7, -1, 4, 3, 5}) out.put<std::int32_t>(i);
  write_bytes(dir / "strips_binary.ply",
              "ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty float x\nproperty float y\n"
              "property float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n" +
                  out.data);
  EXPECT_EQ(read_mesh(dir / "strips_binary.ply").triangles, expected);
  EXPECT_EQ(open_triangle_stream(dir / "strips_binary.ply")->triangles_hint(), 14u);
}

// Elements and properties we do not know, before, between and after the ones we read, in both encodings.
TEST(PlyLayout, UnknownElementsAndPropertiesAreSkipped) {
  test::TempDir dir;
  const std::string header_body =
      "comment a material before the vertices, an edge list after the faces\n"
      "element material 2\nproperty uchar ambient_red\nproperty list uchar float coefficients\n"
      "element vertex 4\nproperty float confidence\nproperty float x\nproperty list uchar int neighbors\n"
      "property float y\nproperty float z\nproperty double intensity\n"
      "element face 2\nproperty uchar flags\nproperty list uchar int vertex_indices\n"
      "property list uchar float weights\nproperty int segment\n"
      "element edge 3\nproperty int vertex1\nproperty int vertex2\n"
      "element nothing 1000000000000000\n"
      "end_header\n";
  const std::string ascii = "ply\nformat ascii 1.0\n" + header_body +
                            "7 2 0.5 0.25\n8 0\n"
                            "0.9 0 2 1 3 0 0 1e-3\n0.8 1 0 0 0 -5\n0.7 1 3 0 1 3 1 0 7\n0.6 0 0 1 0 0\n"
                            "1 3 0 1 2 6 0 0 1 0 1 1 4\n0 3 0 2 3 0 -1\n"
                            "0 1\n1 2\n2 0\n";
  write_bytes(dir / "unknown_ascii.ply", ascii);
  const IndexedMesh from_ascii = read_mesh(dir / "unknown_ascii.ply");
  EXPECT_EQ(from_ascii.triangles, kSquareTriangles);
  EXPECT_EQ(from_ascii.positions[2], Vec3f(1, 1, 0));
  EXPECT_EQ(from_ascii.positions[3], Vec3f(0, 1, 0));

  Bytes out;
  out.put<std::uint8_t>(7).put<std::uint8_t>(2).put(0.5f).put(0.25f);
  out.put<std::uint8_t>(8).put<std::uint8_t>(0);
  const float xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (int i = 0; i < 4; ++i) {
    out.put(0.5f).put(xyz[i][0]).put<std::uint8_t>(static_cast<std::uint8_t>(i));
    for (int k = 0; k < i; ++k) out.put<std::int32_t>(k);
    out.put(xyz[i][1]).put(xyz[i][2]).put(double(i));
  }
  for (const Triangle& t : kSquareTriangles) {
    out.put<std::uint8_t>(1).put<std::uint8_t>(3);
    for (Index i : t) out.put(static_cast<std::int32_t>(i));
    out.put<std::uint8_t>(2).put(0.f).put(1.f).put<std::int32_t>(-1);
  }
  for (int i = 0; i < 3; ++i) out.put<std::int32_t>(i).put<std::int32_t>((i + 1) % 3);
  write_bytes(dir / "unknown_binary.ply", "ply\nformat binary_little_endian 1.0\n" + header_body + out.data);
  expect_same_mesh(from_ascii, read_mesh(dir / "unknown_binary.ply"));
}

// Texture coordinates per face corner, as MeshLab writes a textured mesh: each vertex takes those of the
// first corner that references it, whatever the layout (before or after the index list, faces before the
// vertices, binary or ascii), in core; a reader that hands its vertices on as it loads them says it left
// them out.
TEST(PlyLayout, PerCornerTextureCoordinatesGoToTheirVertices) {
  test::TempDir dir;
  // A unit square as two triangles with a uv seam along its diagonal: vertex 0 is used by the first
  // triangle with (0, 0) and by the second with (0.5, 0.5); vertex 4 is used by no face.
  const float xyz[5][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {5, 5, 5}};
  const Triangle faces[2] = {{0, 1, 2}, {0, 2, 3}};
  const float uv[2][6] = {{0, 0, 1, 0, 1, 1}, {0.5f, 0.5f, 0.75f, 0.75f, 0, 1}};
  const std::vector<Vec2f> expected = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {0, 0}};
  for (bool texcoord_first : {false, true}) {
    for (bool faces_first : {false, true}) {
      const std::string vertex_element =
          "element vertex 5\nproperty float x\nproperty float y\nproperty float z\n";
      const std::string face_element =
          "element face 2\n" +
          std::string(texcoord_first ? "property list uchar float texcoord\nproperty list uchar int "
                                       "vertex_indices\n"
                                     : "property list uchar int vertex_indices\nproperty list uchar float "
                                       "texcoord\n") +
          "property int texnumber\n";
      const std::string elements =
          faces_first ? face_element + vertex_element : vertex_element + face_element;
      std::string ascii_vertices, ascii_faces;
      Bytes binary_vertices, binary_faces;
      for (const auto& p : xyz) {
        ascii_vertices +=
            std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + "\n";
        binary_vertices.put(p[0]).put(p[1]).put(p[2]);
      }
      for (int f = 0; f < 2; ++f) {
        std::string indices = "3", coords = "6";
        Bytes index_bytes, coord_bytes;
        index_bytes.put<std::uint8_t>(3);
        coord_bytes.put<std::uint8_t>(6);
        for (Index v : faces[f]) {
          indices.append(" ").append(std::to_string(v));
          index_bytes.put(static_cast<std::int32_t>(v));
        }
        for (float c : uv[f]) {
          coords.append(" ").append(std::to_string(c));
          coord_bytes.put(c);
        }
        ascii_faces += (texcoord_first ? coords + " " + indices : indices + " " + coords) + " 0\n";
        binary_faces.data +=
            texcoord_first ? coord_bytes.data + index_bytes.data : index_bytes.data + coord_bytes.data;
        binary_faces.put<std::int32_t>(0);
      }
      for (bool ascii : {false, true}) {
        SCOPED_TRACE(std::string(ascii ? "ascii" : "binary") + (faces_first ? ", faces first" : "") +
                     (texcoord_first ? ", texcoord first" : ""));
        const std::string body =
            ascii ? (faces_first ? ascii_faces + ascii_vertices : ascii_vertices + ascii_faces)
                  : (faces_first ? binary_faces.data + binary_vertices.data
                                 : binary_vertices.data + binary_faces.data);
        const std::string path = dir / "wedge.ply";
        write_bytes(path, std::string("ply\nformat ") + (ascii ? "ascii" : "binary_little_endian") +
                              " 1.0\n" + elements + "end_header\n" + body);
        std::vector<std::string> told;
        ReadOptions options;
        options.warn = [&](const std::string& message) { told.push_back(message); };
        const IndexedMesh mesh = read_mesh(path, options);
        // Vertices 0 and 2 are on the seam, and (said once the faces are all read) the texture's number is
        // not read.
        ASSERT_EQ(told.size(), 2u);
        EXPECT_EQ(told[0].rfind("2 vertices on texture seams", 0), 0u) << told[0];
        EXPECT_NE(told[1].find("face property texnumber"), std::string::npos) << told[1];
        EXPECT_EQ(mesh.triangles, (std::vector<Triangle>{faces[0], faces[1]}));
        ASSERT_TRUE(mesh.has_uvs());
        EXPECT_EQ(mesh.uvs, expected);
        // Streamed in batches of one, the same; its progress ends at its total, which counts the faces twice.
        const Drained drained = drain(path, 1);
        EXPECT_EQ(drained.triangles, mesh.triangles);
        EXPECT_EQ(drained.vertices.uvs, expected);
        ReadOptions sink;
        sink.vertex_sink = [](const VertexChunk&) {};
        EXPECT_EQ(open_triangle_stream(path, sink)->attributes_left_out(), "texture coordinates");
        EXPECT_EQ(open_triangle_stream(path)->attributes_left_out(), "");
        // With split_corner_attributes every corner reads its own texcoord: vertices 0 and 2 get a copy
        // each for the second triangle, and nothing is said of seams. In batches of one triangle, the same.
        options.split_corner_attributes = true;
        for (const std::size_t capacity : {std::size_t{1}, TriangleBatch::default_capacity}) {
          options.batch_capacity = capacity;
          told.clear();
          const IndexedMesh split = read_mesh(path, options);
          ASSERT_EQ(told.size(), 1u);
          EXPECT_NE(told[0].find("face property texnumber"), std::string::npos) << told[0];
          ASSERT_EQ(split.vertex_count(), 7u);
          ASSERT_EQ(split.face_count(), 2u);
          for (int f = 0; f < 2; ++f) {
            for (int k = 0; k < 3; ++k) {
              const Index at = split.triangles[f][k];
              EXPECT_EQ(split.uvs[at], Vec2f(uv[f][2 * k], uv[f][2 * k + 1])) << f << " " << k;
              const float* p = xyz[faces[f][k]];
              EXPECT_EQ(split.positions[at], Vec3f(p[0], p[1], p[2])) << f << " " << k;
            }
          }
        }
      }
    }
  }
  // Per-vertex texture coordinates, when the file has both, are the ones kept.
  write_bytes(
      dir / "both.ply",
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property float u\nproperty float v\nelement face 1\nproperty list uchar int vertex_indices\n"
      "property list uchar float texcoord\nend_header\n0 0 0 0.25 0.25\n1 0 0 0.5 0.25\n0 1 0 0.25 0.5\n"
      "3 0 1 2 6 0 0 1 0 0 1\n");
  EXPECT_EQ(read_mesh(dir / "both.ply").uvs,
            (std::vector<Vec2f>{{0.25f, 0.25f}, {0.5f, 0.25f}, {0.25f, 0.5f}}));
}

// The face element before the vertex element: legal, and read with a second pass instead of buffering.
TEST(PlyLayout, FacesBeforeVertices) {
  test::TempDir dir;
  const IndexedMesh mesh = mesh_with(true, false, false);
  write_mesh(dir / "normal_order.ply", mesh);

  std::string header =
      "ply\nformat binary_little_endian 1.0\nelement face " + std::to_string(mesh.triangles.size()) +
      "\nproperty list uchar int vertex_indices\nelement extra 2\nproperty short s\n"
      "element vertex " +
      std::to_string(mesh.positions.size()) +
      "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\n"
      "property float nz\nelement tail 1\nproperty list uchar uchar stuff\nend_header\n";
  Bytes out;
  for (const Triangle& t : mesh.triangles) {
    out.put<std::uint8_t>(3);
    for (Index i : t) out.put(static_cast<std::int32_t>(i));
  }
  out.put<std::int16_t>(1).put<std::int16_t>(2);
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
    for (int k = 0; k < 3; ++k) out.put(mesh.positions[i][k]);
    for (int k = 0; k < 3; ++k) out.put(mesh.normals[i][k]);
  }
  out.put<std::uint8_t>(2).put<std::uint8_t>(9).put<std::uint8_t>(9);
  write_bytes(dir / "faces_first.ply", header + out.data);
  expect_same_mesh(mesh, read_mesh(dir / "faces_first.ply"));

  // Small batches across the second pass.
  const Drained drained = drain(dir / "faces_first.ply", 7);
  EXPECT_EQ(drained.triangles, mesh.triangles);
  EXPECT_LE(drained.largest_batch, 7u);

  // Ascii, with the triangles as quads where possible.
  std::string ascii =
      "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int vertex_indices\n"
      "element vertex 4\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
      "4 0 1 2 3\n\n3 3 2 1\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n";
  write_bytes(dir / "faces_first_ascii.ply", ascii);
  const IndexedMesh quad = read_mesh(dir / "faces_first_ascii.ply");
  EXPECT_EQ(quad.triangles, (std::vector<Triangle>{{0, 1, 2}, {0, 2, 3}, {3, 2, 1}}));
  EXPECT_EQ(quad.positions[3], Vec3f(0, 1, 0));

  // An index out of range is found in the second pass, with the right line.
  write_bytes(dir / "faces_first_bad.ply", ascii.replace(ascii.find("3 3 2 1"), 7, "3 3 2 4"));
  try {
    read_mesh(dir / "faces_first_bad.ply");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.position().kind, FilePosition::Kind::line);
    EXPECT_EQ(e.position().value, 12u) << e.what();
  }
}

// ---- Streaming --------------------------------------------------------------------------------------------

TEST(PlyStream, SmallBatchesGiveTheSameTriangles) {
  test::TempDir dir;
  const IndexedMesh mesh = test::sphere(3);
  for (bool ascii : {false, true}) {
    WriteOptions options;
    options.ascii = ascii;
    const std::string path = dir / (ascii ? "ascii.ply" : "binary.ply");
    write_mesh(path, mesh, options);
    const Drained one = drain(path, 1 << 20);
    const Drained seven = drain(path, 7);
    EXPECT_EQ(one.batches, 1u);
    EXPECT_EQ(one.triangles, mesh.triangles);
    EXPECT_EQ(seven.triangles, mesh.triangles);
    EXPECT_EQ(seven.largest_batch, 7u);
    EXPECT_EQ(seven.batches, (mesh.triangles.size() + 6) / 7);
  }
  // Polygons split across batches.
  write_bytes(
      dir / "poly.ply",
      "ply\nformat ascii 1.0\nelement vertex 9\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n2 1 0\n2 2 0\n1 3 0\n0 3 0\n-1 2 0\n-1 1 0\n5 5 5\n"
      "8 0 1 2 3 4 5 6 7\n3 8 0 1\n");
  const Drained whole = drain(dir / "poly.ply", 100);
  ASSERT_EQ(whole.triangles.size(), 7u);
  for (std::size_t capacity : {1, 2, 4, 5}) {
    const Drained split = drain(dir / "poly.ply", capacity);
    EXPECT_EQ(split.triangles, whole.triangles) << capacity;
    EXPECT_LE(split.largest_batch, capacity);
  }
}

TEST(PlyStream, ContractFacts) {
  test::TempDir dir;
  const IndexedMesh mesh = test::sphere(3, 2.5f);
  write_mesh(dir / "s.ply", mesh);
  std::vector<std::uint64_t> reported;
  ReadOptions options;
  options.progress = [&](std::string_view phase, std::uint64_t done, std::uint64_t total) {
    EXPECT_EQ(phase, "read");
    EXPECT_EQ(total, fs::file_size(dir / "s.ply"));
    reported.push_back(done);
  };
  auto stream = open_triangle_stream(dir / "s.ply", options);
  EXPECT_TRUE(stream->indexed());
  EXPECT_EQ(stream->path(), dir / "s.ply");
  EXPECT_EQ(stream->triangles_hint(), mesh.triangles.size());
  EXPECT_EQ(stream->vertices().positions.size(), mesh.positions.size());
  EXPECT_TRUE(stream->vertices().triangles.empty());
  const Box3 box = stream->bounds();
  const Box3 expected = mesh.bounds();
  EXPECT_EQ(box.lo, expected.lo);
  EXPECT_EQ(box.hi, expected.hi);
  EXPECT_LT(stream->bytes_read(), stream->bytes_total());
  TriangleBatch batch;
  while (stream->next(batch)) {
  }
  EXPECT_EQ(stream->bytes_read(), stream->bytes_total());
  ASSERT_FALSE(reported.empty());
  EXPECT_TRUE(std::is_sorted(reported.begin(), reported.end()));
  EXPECT_EQ(reported.back(), fs::file_size(dir / "s.ply"));
}

// ---- The shared meshes
// --------------------------------------------------------------------------------------

// An independent decoder for the simplest layout (float x y z [nx ny nz], uchar int triangles, little
// endian), to check the reader against the shared meshes value by value.
void expect_matches_raw_file(const std::string& path, const IndexedMesh& mesh, bool normals) {
  const std::string bytes = read_bytes(path);
  std::size_t at = bytes.find("end_header\n") + 11;
  const std::size_t floats = normals ? 6 : 3;
  for (std::size_t i = 0; i < mesh.positions.size(); ++i, at += 4 * floats) {
    float values[6];
    std::memcpy(values, bytes.data() + at, 4 * floats);
    ASSERT_EQ(mesh.positions[i], Vec3f(values[0], values[1], values[2])) << i;
    if (normals) {
      ASSERT_EQ(mesh.normals[i], Vec3f(values[3], values[4], values[5])) << i;
    }
  }
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i, at += 13) {
    ASSERT_EQ(bytes[at], 3);
    std::int32_t corners[3];
    std::memcpy(corners, bytes.data() + at + 1, 12);
    ASSERT_EQ(mesh.triangles[i], (Triangle{Index(corners[0]), Index(corners[1]), Index(corners[2])})) << i;
  }
  EXPECT_EQ(at, bytes.size());
}

TEST(PlySharedMeshes, Bunny) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "bunny.ply");
  const IndexedMesh mesh = read_mesh(path);
  EXPECT_EQ(mesh.positions.size(), 35947u);
  EXPECT_EQ(mesh.triangles.size(), 69451u);
  EXPECT_FALSE(mesh.has_normals());
  expect_matches_raw_file(path, mesh, false);
}

TEST(PlySharedMeshes, HorseWithNormals) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "horse.ply");
  const IndexedMesh mesh = read_mesh(path);
  EXPECT_EQ(mesh.positions.size(), 48485u);
  EXPECT_EQ(mesh.triangles.size(), 96966u);
  ASSERT_TRUE(mesh.has_normals());
  expect_matches_raw_file(path, mesh, true);
}

TEST(PlySharedMeshes, IgeaAsTriangleStrips) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "igea.ply");
  const IndexedMesh mesh = read_mesh(path);
  EXPECT_EQ(mesh.positions.size(), 134345u);
  EXPECT_EQ(mesh.triangles.size(), 268686u);
  // Strips with alternating winding must give a consistently oriented surface.
  const MeshTopology topology = analyze_topology(mesh);
  EXPECT_EQ(topology.inconsistent_edges, 0u);
  EXPECT_EQ(topology.degenerate_faces, 0u);
}

TEST(PlySharedMeshes, SurviveARoundTrip) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "horse.ply");
  test::TempDir dir;
  const IndexedMesh mesh = read_mesh(path);
  WriteOptions ascii;
  ascii.ascii = true;
  write_mesh(dir / "horse_ascii.ply", mesh, ascii);
  expect_same_mesh(mesh, read_mesh(dir / "horse_ascii.ply"));
}

// ---- Malformed input
// ----------------------------------------------------------------------------------------

struct Malformed {
  const char* file;
  const char* reason;  // a piece of the expected message
};

// Every file in tests/data/malformed/ply, with what its error must say.
const Malformed kMalformed[] = {
    {"bad_magic.ply", "first line must be 'ply'"},
    {"unknown_format.ply", "unknown format 'binary_middle_endian'"},
    {"no_end_header.ply", "unknown header keyword"},
    {"property_before_element.ply", "property outside any element"},
    {"duplicate_element.ply", "a second element named 'vertex'"},
    {"duplicate_property.ply", "a second property named 'y' in element 'vertex'"},
    {"negative_count.ply", "negative element count"},
    {"non_numeric_count.ply", "is not a number"},
    {"unsupported_type.ply", "unsupported property type 'half'"},
    {"list_count_float.ply", "list count must have an integer type"},
    {"missing_z.ply", "no property z"},
    {"x_is_list.ply", "is a list"},
    {"no_face_element.ply", "no face element"},
    {"zero_faces.ply", "element face is empty"},
    {"indices_not_a_list.ply", "must be a list"},
    {"no_vertex_indices.ply", "no vertex_indices list"},
    {"ascii_truncated_faces.ply", "the file ends in record 1 of element face"},
    {"ascii_truncated_line.ply", "the line ends early"},
    {"ascii_non_numeric.ply", "'zero' is not a number"},
    {"ascii_garbage_after_header.ply", "'hello' is not a number"},
    {"ascii_extra_values.ply", "unexpected value '3'"},
    {"ascii_data_after_last_element.ply", "unexpected data after the last element"},
    {"ascii_nan_coordinate.ply", "not a finite float"},
    {"ascii_inf_coordinate.ply", "not a finite float"},
    {"ascii_float_overflow.ply", "not a finite float"},
    {"ascii_index_out_of_range.ply", "vertex index 4 is out of range"},
    {"ascii_negative_index.ply", "vertex index -2 is out of range"},
    {"ascii_face_two_corners.ply", "a face with 2 corners"},
    {"ascii_face_zero_corners.ply", "a face with 0 corners"},
    {"ascii_count_out_of_range.ply", "'300' is out of range for uchar"},
    {"ascii_fractional_index.ply", "vertex index 2.5 is not an integer"},
    {"ascii_absurd_vertex_count.ply", "more than 2^32-1 vertices"},
    {"ascii_too_many_vertices.ply", "more than 2^32-1 vertices"},
    {"binary_absurd_vertex_count.ply", "more than 2^32-1 vertices"},
    {"binary_vertex_count_exceeds_data.ply", "the file ends in record"},
    {"binary_absurd_face_count.ply", "the file ends in record 2 of element face"},
    {"binary_huge_list_count.ply", "the file ends in record 1 of element face"},
    {"binary_truncated_vertices.ply", "the file ends in record 2 of element vertex"},
    {"binary_truncated_faces.ply", "the file ends in record 1 of element face"},
    {"binary_index_out_of_range.ply", "vertex index 7 is out of range (4 vertices)"},
    {"binary_negative_index.ply", "vertex index -1 is out of range"},
    {"binary_face_one_corner.ply", "a face with 1 corner in"},
    {"binary_nan_coordinate.ply", "vertex 1 has a coordinate that is not a finite float"},
    {"binary_double_overflow.ply",
     "vertex 1 has a coordinate beyond the float range (+-3.4e38), which positions are held in: 1e+300"},
    {"binary_trailing_bytes.ply", "4 bytes of unexpected data after the last element"},
    {"binary_big_endian_truncated.ply", "the file ends in record 1 of element face"},
    {"binary_truncated_unknown_element.ply", "the file ends in record 3 of element edge"},
    {"binary_header_garbage.ply", "without an end_header"},
    {"cr_line_endings.ply", "end in a carriage return alone"},
    {"binary_nan_normal.ply", "vertex 1 has a normal that is not a finite float"},
    {"ascii_inf_uv.ply", "vertex 2 has a texture coordinate that is not a finite float"},
    {"ascii_inf_color.ply", "vertex 2 has a color that is not a finite float"},
    {"ascii_texcoord_count.ply", "texcoord holds 4 numbers for 3 corners (two a corner) in record 1"},
    {"ascii_texcoord_nan.ply", "a texture coordinate that is not a finite float in record 0"},
};

std::string malformed_path(const std::string& name) {
  return (fs::path(OCSIMP_TEST_DATA) / "malformed" / "ply" / name).string();
}

class PlyMalformed : public ::testing::TestWithParam<Malformed> {};

TEST_P(PlyMalformed, ThrowsAnErrorNamingFilePlaceAndReason) {
  const std::string path = malformed_path(GetParam().file);
  ASSERT_TRUE(fs::exists(path)) << path;
  const auto start = std::chrono::steady_clock::now();
  try {
    const IndexedMesh mesh = read_mesh(path);
    FAIL() << "read " << mesh.triangles.size() << " triangles from " << path;
  } catch (const Error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path), std::string::npos) << message;
    EXPECT_TRUE(message.find(": byte ") != std::string::npos || message.find(": line ") != std::string::npos)
        << message;
    EXPECT_NE(e.position().kind, FilePosition::Kind::none) << message;
    EXPECT_NE(message.find(GetParam().reason), std::string::npos) << message;
  }
  // Absurd counts must fail on the spot, not after allocating or looping over what the header claims.
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
}

INSTANTIATE_TEST_SUITE_P(Files, PlyMalformed, ::testing::ValuesIn(kMalformed),
                         [](const ::testing::TestParamInfo<Malformed>& info) {
                           std::string name = info.param.file;
                           name = name.substr(0, name.find('.'));
                           return name;
                         });

TEST(PlyMalformed, AFileWithoutFacesReadsWhenFacesAreNotRequired) {
  // What `info` and `convert` ask for: ocsimp itself writes such a file when every triangle collapses.
  ReadOptions options;
  options.faces_required = false;
  const IndexedMesh mesh = read_mesh(malformed_path("zero_faces.ply"), options);
  EXPECT_GT(mesh.vertex_count(), 0u);
  EXPECT_EQ(mesh.face_count(), 0u);
}

// An end_header as the file's last line, without a line ending, ends an empty mesh (it was "the header ends
// without an end_header line"); any other last line without one still ends a header that is cut short.
// A vertex record larger than the reader's 1 MiB window was reported as the file ending inside it, complete
// as the file was. The window grows to hold a record, but only as far as the file goes: one cut short inside
// its second record still says so.
TEST(PlyLayout, AVertexRecordLargerThanTheReadWindowReads) {
  test::TempDir dir;
  constexpr int kExtra = 140'000;  // doubles after x y z: a record of 1,120,012 bytes
  std::string text =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\n";
  for (int i = 0; i < kExtra; ++i) text += "property double p" + std::to_string(i) + "\n";
  text += "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const std::size_t header = text.size();
  const float points[3][3] = {{0, 0, 0}, {1, 0, 0}, {0, 2, 0}};
  for (const auto& p : points) {
    text.append(reinterpret_cast<const char*>(p), sizeof p);
    const std::vector<double> extra(kExtra, 0.5);
    text.append(reinterpret_cast<const char*>(extra.data()), extra.size() * sizeof(double));
  }
  const std::uint8_t three = 3;
  const std::int32_t corners[3] = {0, 1, 2};
  text.append(reinterpret_cast<const char*>(&three), 1);
  text.append(reinterpret_cast<const char*>(corners), sizeof corners);
  write_bytes(dir / "wide.ply", text);
  const IndexedMesh mesh = read_mesh(dir / "wide.ply");
  ASSERT_EQ(mesh.vertex_count(), 3u);
  EXPECT_EQ(mesh.positions[2], Vec3f(0, 2, 0));
  EXPECT_EQ(mesh.triangles, (std::vector<Triangle>{{0, 1, 2}}));

  const std::size_t record = 12 + kExtra * sizeof(double);
  write_bytes(dir / "cut.ply", text.substr(0, header + record + record / 2));
  try {
    read_mesh(dir / "cut.ply");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.reason(), "the file ends in record 1 of element vertex (3 declared)");
  }
}

TEST(PlyMalformed, AnEndHeaderWithoutALineEndingEndsAnEmptyFile) {
  test::TempDir dir;
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
      "property float z\nelement face 0\nproperty list uchar int vertex_indices\n";
  ReadOptions options;
  options.faces_required = false;
  for (const char* last : {"end_header", "end_header \r"}) {
    write_bytes(dir / "empty.ply", header + last);
    const IndexedMesh mesh = read_mesh(dir / "empty.ply", options);
    EXPECT_EQ(mesh.vertex_count() + mesh.face_count(), 0u) << last;
  }
  write_bytes(dir / "cut.ply", header + "end_hea");
  try {
    read_mesh(dir / "cut.ply", options);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.reason(), "the header ends without an end_header line");
    EXPECT_EQ(e.position().value, 9u);
  }
  // And a record cut short names the type it expected with its article.
  write_bytes(dir / "short.ply",
              "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty int z\n"
              "element face 0\nproperty list uchar int vertex_indices\nend_header\n1.5 2.5\n");
  try {
    read_mesh(dir / "short.ply", options);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(e.reason().find("expected an int in record 0 of element vertex"), std::string::npos)
        << e.what();
  }
}

TEST(PlyMalformedFolder, EveryFileHasATest) {
  std::set<std::string> listed;
  for (const Malformed& m : kMalformed) listed.insert(m.file);
  std::size_t files = 0;
  for (const auto& entry : fs::directory_iterator(malformed_path(""))) {
    ++files;
    EXPECT_EQ(listed.count(entry.path().filename().string()), 1u) << entry.path() << " has no test";
  }
  EXPECT_EQ(files, listed.size());
}

TEST(PlyMalformedPositions, BinaryErrorsNameTheByteAndAsciiErrorsTheLine) {
  try {
    read_mesh(malformed_path("binary_index_out_of_range.ply"));
    FAIL();
  } catch (const Error& e) {
    // The header is 188 bytes, the vertices 48, the first face 13; then the count and two indices.
    const std::uint64_t header =
        read_bytes(malformed_path("binary_index_out_of_range.ply")).find("end_header\n") + 11;
    EXPECT_EQ(e.position().kind, FilePosition::Kind::byte);
    EXPECT_EQ(e.position().value, header + 48 + 13 + 1 + 8) << e.what();
  }
  try {
    read_mesh(malformed_path("ascii_non_numeric.ply"));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.position().kind, FilePosition::Kind::line);
    EXPECT_EQ(e.position().value, 11u) << e.what();  // 9 header lines, then the second vertex
  }
  try {
    read_mesh(malformed_path("unsupported_type.ply"));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.position().kind, FilePosition::Kind::line);
    EXPECT_EQ(e.position().value, 6u) << e.what();
  }
}

// Any prefix of a valid file is an error, never a crash or a hang, in every encoding.
TEST(PlyMalformedPrefixes, EveryTruncationThrows) {
  test::TempDir dir;
  IndexedMesh mesh = mesh_with(true, true, true);
  mesh.positions.resize(30);
  mesh.normals.resize(30);
  mesh.colors.resize(30);
  mesh.uvs.resize(30);
  mesh.triangles.erase(
      std::remove_if(mesh.triangles.begin(), mesh.triangles.end(),
                     [](const Triangle& t) { return t[0] >= 30 || t[1] >= 30 || t[2] >= 30; }),
      mesh.triangles.end());
  ASSERT_GT(mesh.triangles.size(), 5u);
  for (bool ascii : {false, true}) {
    WriteOptions options;
    options.ascii = ascii;
    write_mesh(dir / "whole.ply", mesh, options);
    const std::string whole = read_bytes(dir / "whole.ply");
    const std::size_t data = whole.find("end_header\n") + 11;
    // Cutting an ascii file inside its last number leaves a complete file (with a different last index).
    const std::size_t end = ascii ? whole.rfind(' ') + 1 : whole.size();
    for (std::size_t size = 0; size < end; size += (size < data ? 17 : 1)) {
      write_bytes(dir / "cut.ply", whole.substr(0, size));
      EXPECT_THROW(read_mesh(dir / "cut.ply"), Error) << (ascii ? "ascii" : "binary") << " cut at " << size;
    }
  }
}

// Random byte changes anywhere in small valid files give a mesh or an Error, never a crash or another
// exception (the sanitizer build checks that nothing reads out of bounds on the way).
TEST(PlyMalformedMutations, RandomByteChangesNeverCrash) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(3);
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
    mesh.normals.emplace_back(0, 0, 1);
    mesh.colors.push_back({static_cast<std::uint8_t>(i), 2, 3, 4});
  }
  std::uint64_t state = 12345;
  auto random = [&state] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<std::uint32_t>(state >> 33);
  };
  std::size_t accepted = 0, rejected = 0;
  for (bool ascii : {false, true}) {
    WriteOptions options;
    options.ascii = ascii;
    write_mesh(dir / "whole.ply", mesh, options);
    const std::string whole = read_bytes(dir / "whole.ply");
    for (int round = 0; round < 600; ++round) {
      std::string bytes = whole;
      const int changes = 1 + static_cast<int>(random() % 3);
      for (int c = 0; c < changes; ++c) {
        const char replacements[] = {'0', '9', ' ', '\n', '-', '.', 'e', '\0', '\xff', '\x03'};
        bytes[random() % bytes.size()] =
            random() % 2 ? replacements[random() % sizeof(replacements)] : static_cast<char>(random());
      }
      write_bytes(dir / "mutant.ply", bytes);
      try {
        const IndexedMesh read = read_mesh(dir / "mutant.ply");
        ++accepted;
        for (const Triangle& t : read.triangles) {
          for (Index i : t) ASSERT_LT(i, read.positions.size());
        }
      } catch (const Error& e) {
        ++rejected;
        EXPECT_NE(std::string(e.what()).find("mutant.ply"), std::string::npos) << e.what();
      }
    }
  }
  // Both outcomes happen: changed coordinates still read; broken structure does not.
  EXPECT_GT(accepted, 0u);
  EXPECT_GT(rejected, 0u);
}

}  // namespace
}  // namespace ocsimp
