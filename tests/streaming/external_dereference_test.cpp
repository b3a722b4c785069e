// Out-of-core dereferencing (external_dereference.h): with a vertex budget far below the mesh, every format
// it covers must deliver exactly the corners the in-memory reader resolves, in the same order, leave no file
// behind, and report bad input as the plain reader does.
#include "ocsimp/streaming/external_dereference.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>

#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "io_test_util.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

// Points TMPDIR at a test folder for the scope, so the test can see what the dereferencing leaves there.
struct ScopedTmpdir {
  std::string old;
  bool had = false;
  explicit ScopedTmpdir(const std::string& dir) {
    if (const char* value = std::getenv("TMPDIR")) {
      old = value;
      had = true;
    }
    ::setenv("TMPDIR", dir.c_str(), 1);
  }
  ~ScopedTmpdir() {
    if (had) {
      ::setenv("TMPDIR", old.c_str(), 1);
    } else {
      ::unsetenv("TMPDIR");
    }
  }
};

// A test's folder, with TMPDIR pointed at its "tmp" subfolder (`work`) for the test's scope.
struct TestFolders {
  test::TempDir dir;
  std::string work = dir / "tmp";
  std::optional<ScopedTmpdir> tmpdir;
  TestFolders() {
    std::filesystem::create_directories(work);
    tmpdir.emplace(work);
  }
};

std::size_t entries(const std::string& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir)) ++n;
  return n;
}

// A bumpy grid with every vertex at a distinct position, its vertex ids shuffled so that the faces reference
// them out of order (as scans do), which spreads each batch over every partition.
IndexedMesh shuffled_grid(int n) {
  IndexedMesh grid = test::grid_square(n);
  const std::size_t count = grid.positions.size();
  std::vector<Index> slot(count);
  for (std::size_t i = 0; i < count; ++i) slot[i] = static_cast<Index>((i * 7919) % count);
  IndexedMesh mesh;
  mesh.positions.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    Vec3f p = grid.positions[i];
    p.z() = 0.01f * static_cast<float>((i * 31) % 17);
    mesh.positions[slot[i]] = p;
  }
  for (const Triangle& t : grid.triangles) mesh.triangles.push_back({slot[t[0]], slot[t[1]], slot[t[2]]});
  return mesh;
}

std::vector<std::array<Vec3f, 3>> drain_corners(TriangleStream& stream) {
  std::vector<std::array<Vec3f, 3>> corners;
  TriangleBatch batch;
  while (stream.next(batch)) {
    EXPECT_TRUE(batch.triangles.empty());
    corners.insert(corners.end(), batch.corners.begin(), batch.corners.end());
  }
  return corners;
}

void expect_same_corners(const std::string& path, std::uint64_t budget) {
  SCOPED_TRACE(path);
  const IndexedMesh mesh = read_mesh(path);
  ReadOptions options;
  options.memory_budget = budget;
  options.batch_capacity = 1000;  // many batches
  std::unique_ptr<TriangleStream> stream = open_dereferenced_stream(path, options);
  ASSERT_TRUE(dereferenced_out_of_core(*stream));
  EXPECT_FALSE(stream->indexed());
  EXPECT_EQ(stream->triangles_hint(), mesh.face_count());
  const Box3 bounds = stream->bounds();
  EXPECT_EQ(bounds.lo, mesh.bounds().lo);
  EXPECT_EQ(bounds.hi, mesh.bounds().hi);
  const auto corners = drain_corners(*stream);
  ASSERT_EQ(corners.size(), mesh.face_count());
  for (std::size_t f = 0; f < corners.size(); ++f) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(corners[f][k], mesh.positions[mesh.triangles[f][k]]) << "face " << f << " corner " << k;
    }
  }
}

// A stream's vertex array, read back whole, against the direct read's: bit for bit.
void expect_same_arrays(const IndexedMesh& got, const IndexedMesh& want) {
  EXPECT_EQ(got.positions, want.positions);
  EXPECT_EQ(got.normals, want.normals);
  EXPECT_EQ(got.uvs, want.uvs);
  EXPECT_EQ(got.colors, want.colors);
  EXPECT_EQ(got.triangles, want.triangles);
}

// Which vertex attributes a dereferenced stream's corners carry.
struct Carried {
  bool normals = false, colors = false, uvs = false;
};

// Drains a dereferenced stream and checks corner k of its face f against vertex direct.triangles[f][k], bit
// for bit: its position, and each attribute in `carried`; the corners carry no other attribute.
void expect_corners_carry(TriangleStream& stream, const IndexedMesh& direct, Carried carried) {
  TriangleBatch batch;
  std::size_t f = 0;
  while (stream.next(batch)) {
    const std::size_t n = batch.corners.size();
    ASSERT_EQ(batch.corner_normals.size(), carried.normals ? n : 0);
    ASSERT_EQ(batch.corner_colors.size(), carried.colors ? n : 0);
    ASSERT_EQ(batch.corner_uvs.size(), carried.uvs ? n : 0);
    for (std::size_t i = 0; i < n; ++i, ++f) {
      ASSERT_LT(f, direct.face_count());
      for (int k = 0; k < 3; ++k) {
        const Index v = direct.triangles[f][k];
        ASSERT_EQ(batch.corners[i][k], direct.positions[v]) << "face " << f;
        if (carried.normals) {
          ASSERT_EQ(batch.corner_normals[i][k], direct.normals[v]) << "face " << f;
        }
        if (carried.colors) {
          ASSERT_EQ(batch.corner_colors[i][k], direct.colors[v]) << "face " << f;
        }
        if (carried.uvs) {
          ASSERT_EQ(batch.corner_uvs[i][k], direct.uvs[v]) << "face " << f;
        }
      }
    }
  }
  EXPECT_EQ(f, direct.face_count());
}

TEST(ExternalDereference, BinaryAndAsciiPlyGiveTheInMemoryCorners) {
  const TestFolders folders;
  const test::TempDir& dir = folders.dir;
  const std::string& work = folders.work;
  const IndexedMesh mesh = shuffled_grid(60);  // 3,721 vertices, 7,200 triangles
  const std::string binary = dir / "binary.ply", ascii = dir / "ascii.ply";
  write_mesh(binary, mesh);
  WriteOptions text;
  text.ascii = true;
  write_mesh(ascii, mesh, text);
  // 100 vertices a partition: 38 partitions.
  expect_same_corners(binary, 1200);
  expect_same_corners(ascii, 1200);
  // A budget below 12 bytes: partitions of a 64th of the vertices (see the next test).
  expect_same_corners(binary, 1);
  EXPECT_EQ(entries(work), 0u);
}

// Each partition costs a scan of the faces file, so however small the budget there are at most 64: with one
// partition per 12 bytes of budget, a 3 M-triangle scan under a 1 KiB limit ran for minutes.
TEST(ExternalDereference, ATinyBudgetTakesAtMost64Partitions) {
  test::TempDir dir;
  const std::string path = dir / "grid.ply";
  write_mesh(path, shuffled_grid(60));  // 3,721 vertices
  std::uint64_t partitions = 0;
  ReadOptions options;
  options.memory_budget = 12;
  options.progress = [&](std::string_view phase, std::uint64_t, std::uint64_t total) {
    if (phase == "dereference") partitions = total;
  };
  std::unique_ptr<TriangleStream> stream = open_dereferenced_stream(path, options);
  ASSERT_TRUE(dereferenced_out_of_core(*stream));
  EXPECT_EQ(drain_corners(*stream).size(), 7'200u);
  EXPECT_EQ(partitions, 64u);
}

TEST(ExternalDereference, ObjWithPolygonsAttributesAndRelativeIndices) {
  const TestFolders folders;
  const test::TempDir& dir = folders.dir;
  const std::string& work = folders.work;
  const std::string path = dir / "mixed.obj";
  // The pentagon is convex: out of core its fan is all there is (the positions are on disk, not at hand to
  // cut a concave polygon in its plane, as the in-memory reader does).
  std::ofstream(path) << "# quads, a pentagon, uvs, normals, negative indices, vertices after faces\n"
                         "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
                         "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
                         "v 2 0 0.5\nv 2 1 0.5\nv 3 0.5 1\n"
                         "f 2 -3 -1 -2 3\n"
                         "f 2//1 5//1 6//1\n"
                         "v 4 4 4\nf 8 7 6\n";
  expect_same_corners(path, 24);  // two vertices a partition
  EXPECT_EQ(entries(work), 0u);
}

TEST(ExternalDereference, FacesBeforeVerticesInPly) {
  test::TempDir dir;
  const std::string path = dir / "faces-first.ply";
  std::ofstream(path)
      << "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int vertex_indices\n"
         "element vertex 4\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
         "3 3 1 0\n4 0 1 2 3\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n";
  expect_same_corners(path, 12);
}

TEST(ExternalDereference, StaysIndexedWhenTheVerticesFit) {
  test::TempDir dir;
  const std::string path = dir / "small.obj";
  write_mesh(path, shuffled_grid(10));
  ReadOptions options;
  options.memory_budget = 1 << 20;
  std::unique_ptr<TriangleStream> stream = open_dereferenced_stream(path, options);
  EXPECT_FALSE(dereferenced_out_of_core(*stream));
  ASSERT_TRUE(stream->indexed());
  const IndexedMesh direct = read_mesh(path);
  const IndexedMesh through = read_mesh(*stream);
  EXPECT_EQ(through.positions, direct.positions);
  EXPECT_EQ(through.triangles, direct.triangles);
}

TEST(ExternalDereference, OpenTriangleStreamChoosesByTheBudget) {
  test::TempDir dir;
  const std::string path = dir / "grid.ply";
  write_mesh(path, shuffled_grid(20));  // 441 vertices: 5,292 bytes of positions
  ReadOptions options;
  options.memory_budget = 5292;
  EXPECT_FALSE(dereferenced_out_of_core(*open_triangle_stream(path, options)));
  EXPECT_TRUE(open_triangle_stream(path, options)->indexed());
  options.memory_budget = 5291;
  EXPECT_TRUE(dereferenced_out_of_core(*open_triangle_stream(path, options)));
  options.memory_budget = 0;
  EXPECT_FALSE(dereferenced_out_of_core(*open_triangle_stream(path, options)));

  // Held in memory a vertex's attributes take room too: with normals and colors, 28 bytes a vertex. A budget
  // that the positions alone fit once sent such a file through in core, and a 20 M-triangle scan with
  // --memory-limit 400M peaked at 677 MiB.
  IndexedMesh attributed = shuffled_grid(20);
  attributed.normals.assign(attributed.vertex_count(), Vec3f(0, 0, 1));
  attributed.colors.assign(attributed.vertex_count(), Color{1, 2, 3, 255});
  const std::string with_attributes = dir / "attributed.ply";
  write_mesh(with_attributes, attributed);
  options.memory_budget = 441 * 28;
  EXPECT_FALSE(dereferenced_out_of_core(*open_triangle_stream(with_attributes, options)));
  options.memory_budget = 441 * 28 - 1;
  EXPECT_TRUE(dereferenced_out_of_core(*open_triangle_stream(with_attributes, options)));

  // Texture coordinates per face corner are judged as an OBJ's are: the budget is for what the out-of-core
  // reader would hold (the positions), and a file whose positions fit is read in core, where its corners'
  // uvs become the vertices' own (8 bytes a vertex more).
  const IndexedMesh grid = shuffled_grid(20);
  std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(grid.vertex_count()) +
      "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
      std::to_string(grid.face_count()) +
      "\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n";
  auto put = [&](const void* bytes, std::size_t n) { ply.append(static_cast<const char*>(bytes), n); };
  for (const Vec3f& p : grid.positions) put(p.data(), 12);
  for (const Triangle& t : grid.triangles) {
    const std::uint8_t three = 3, six = 6;
    put(&three, 1);
    put(t.data(), 12);
    put(&six, 1);
    for (Index v : t) put(grid.positions[v].data(), 8);
  }
  const std::string textured = dir / "textured.ply";
  test::write_file_bytes(textured, ply);
  options.memory_budget = 441 * 12;
  EXPECT_FALSE(dereferenced_out_of_core(*open_triangle_stream(textured, options)));
  EXPECT_TRUE(open_triangle_stream(textured, options)->vertices().has_uvs());
  options.memory_budget = 441 * 12 - 1;
  const auto out_of_core = open_triangle_stream(textured, options);
  EXPECT_TRUE(dereferenced_out_of_core(*out_of_core));
  EXPECT_EQ(out_of_core->attributes_left_out(), "texture coordinates");
}

TEST(ExternalDereference, BadInputGivesTheReadersErrorAndLeavesNothing) {
  const TestFolders folders;
  const test::TempDir& dir = folders.dir;
  const std::string& work = folders.work;
  const std::string bad = dir / "bad.ply";
  std::ofstream(bad)
      << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
         "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 7\n";
  ReadOptions options;
  options.memory_budget = 12;
  try {
    open_dereferenced_stream(bad, options);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("bad.ply"), std::string::npos) << what;
    EXPECT_NE(what.find("line 14"), std::string::npos) << what;
    EXPECT_NE(what.find("out of range"), std::string::npos) << what;
  }
  const std::string truncated = dir / "truncated.obj";
  std::ofstream(truncated) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n";
  try {
    open_dereferenced_stream(truncated, options);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("truncated.obj"), std::string::npos) << what;
    EXPECT_NE(what.find("line 4"), std::string::npos) << what;
  }
  EXPECT_EQ(entries(work), 0u);
}

// A temporary folder without room for the corners' positions (here: a file size limit below them, which
// fails the reservation as a full disk would) is reported before the partitions are resolved, with the way
// out, and leaves nothing behind.
TEST(ExternalDereference, NoRoomForTheCornersFailsBeforeResolvingAndSaysWhy) {
  const TestFolders folders;
  const test::TempDir& dir = folders.dir;
  const std::string& work = folders.work;
  const std::string path = dir / "grid.ply";
  write_mesh(path, shuffled_grid(60));  // 3,721 vertices (44,652 bytes), 7,200 triangles (259,200 bytes)
  {
    // A file system that cannot reserve space is written as before, failing only when it is full.
    const std::string probe = work + "/probe";
    const int fd = ::open(probe.c_str(), O_CREAT | O_WRONLY, 0600);
    ASSERT_GE(fd, 0);
    const bool reserves = ::fallocate(fd, 0, 0, 4096) == 0;
    ::close(fd);
    std::filesystem::remove(probe);
    if (!reserves) GTEST_SKIP() << "the test folder's file system cannot reserve space";
  }
  rlimit old{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old), 0);
  // Room for the spooled vertices and the coded faces, not for the corners.
  rlimit small = old;
  small.rlim_cur = 100'000;
  if (old.rlim_max != RLIM_INFINITY && old.rlim_max < small.rlim_cur)
    GTEST_SKIP() << "file size limit too low";
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // else going past the limit kills the process
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  bool resolved = false;
  ReadOptions options;
  options.memory_budget = 1200;
  options.progress = [&](std::string_view phase, std::uint64_t, std::uint64_t) {
    if (phase == "dereference") resolved = true;
  };
  std::string what;
  try {
    open_dereferenced_stream(path, options);
  } catch (const Error& e) {
    what = e.what();
  }
  ::setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_NE(what.find("needs 253.1 KiB of temporary space"), std::string::npos) << what;
  EXPECT_NE(what.find("21600 corners"), std::string::npos) << what;
  EXPECT_NE(what.find("TMPDIR"), std::string::npos) << what;
  EXPECT_FALSE(resolved);
  EXPECT_EQ(entries(work), 0u);
}

// An OBJ has no vertex count up front, so a large enough file is read in sink mode (positions only) until its
// vertices turn out to fit. The stream then used to deliver positions alone: simplify --memory-limit dropped
// the normals and texture coordinates of a mesh it held in memory anyway, without a word.
TEST(ExternalDereference, AnObjThatFitsAfterAllKeepsItsAttributes) {
  const TestFolders folders;
  const std::string path = folders.dir / "textured.obj";
  {
    std::ofstream out(path);
    out << "# a square of 2 triangles with colors, uvs and normals, padded with comments\n";
    for (int i = 0; i < 200; ++i) out << "# padding padding padding padding padding padding\n";
    out << "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\n"
           "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
           "f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n";
  }
  ReadOptions options;
  options.memory_budget = 1000;  // the file's size could hold more vertices than that; its 4 take 48 bytes
  std::unique_ptr<TriangleStream> stream = open_dereferenced_stream(path, options);
  ASSERT_FALSE(dereferenced_out_of_core(*stream));
  EXPECT_EQ(stream->attributes_left_out(), "");
  const IndexedMesh direct = read_mesh(path);
  ASSERT_FALSE(direct.normals.empty());
  ASSERT_FALSE(direct.uvs.empty());
  ASSERT_FALSE(direct.colors.empty());
  expect_same_arrays(read_mesh(*stream), direct);
}

// Without normals or texture coordinates, an OBJ whose vertices turn out to fit needs no second read: the
// spooled records are its vertex array, with their colors, and the reader goes on with the faces. Its
// progress then runs once from start to end (a second read started it over). With normals it is read again
// to keep them, and that read reports a phase of its own.
TEST(ExternalDereference, AnObjThatFitsAfterAllIsReadAgainOnlyForItsCornerAttributes) {
  const TestFolders folders;
  for (const bool normals : {false, true}) {
    SCOPED_TRACE(normals ? "with normals" : "without normals");
    const std::string path = folders.dir / (normals ? "normals.obj" : "coloured.obj");
    {
      std::ofstream out(path);
      const int side = 400;  // 160 k vertices, 318 k triangles: about 11 MB, past the 8 MB progress step
      for (int y = 0; y < side; ++y)
        for (int x = 0; x < side; ++x) out << "v " << x << ' ' << y << " 0 " << (x % 2) << " 0.5 1\n";
      if (normals) out << "vn 0 0 1\n";
      const char* corner = normals ? "//1 " : " ";
      for (int y = 0; y + 1 < side; ++y) {
        for (int x = 0; x + 1 < side; ++x) {
          const int a = y * side + x + 1;
          out << "f " << a << corner << a + 1 << corner << a + side + 1 << corner << "\nf " << a << corner
              << a + side + 1 << corner << a + side << corner << '\n';
        }
      }
    }
    std::vector<std::string> phases;
    std::vector<std::uint64_t> done;  // of each phase, in turn
    ReadOptions options;
    options.memory_budget = 4u << 20;  // the size could hold 1.4 M vertices; the 160 k take 2.5 MB
    options.progress = [&](std::string_view phase, std::uint64_t at, std::uint64_t) {
      if (phases.empty() || phases.back() != phase) phases.emplace_back(phase);
      done.push_back(at + (phases.size() - 1) * (std::uint64_t{1} << 40));
    };
    std::unique_ptr<TriangleStream> stream = open_dereferenced_stream(path, options);
    ASSERT_FALSE(dereferenced_out_of_core(*stream));
    EXPECT_EQ(stream->attributes_left_out(), "");
    expect_same_arrays(read_mesh(*stream), read_mesh(path));
    const std::vector<std::string> expected_phases =
        normals ? std::vector<std::string>{"read", "read again"} : std::vector<std::string>{"read"};
    EXPECT_EQ(phases, expected_phases);
    ASSERT_GE(done.size(), 2u);
    EXPECT_EQ(std::adjacent_find(done.begin(), done.end(), std::greater_equal<>()), done.end());
  }
}

// An OBJ's vertex colors are optional per line. Out of core they ride when a vertex of the first chunk of
// 65,536 has them (the others then white, as in core); colors that first appear later cannot join the
// spooled records, and the stream names them as left out instead of dropping them silently.
TEST(ExternalDereference, OutOfCoreObjColorsFromTheFirstChunkOnRideWithTheirPositions) {
  const TestFolders folders;
  const std::size_t n = 70'000;  // past the first chunk
  auto write_strip = [&](const std::string& path, std::size_t colored_from) {
    std::string text;
    for (std::size_t i = 0; i < n; ++i) {
      text += "v " + std::to_string(i % 2) + " " + std::to_string(i / 2) + " 0";
      if (i >= colored_from) text += " 1 0 0.5";
      text += "\n";
    }
    for (std::size_t i = 0; i + 2 < n; ++i)
      text += "f " + std::to_string(i + 1) + " " + std::to_string(i + 2) + " " + std::to_string(i + 3) + "\n";
    test::write_file_bytes(path, text);
  };
  ReadOptions options;
  options.memory_budget = 4096;
  for (const auto& [colored_from, left_out] :
       {std::pair<std::size_t, std::string>{1, ""}, {65'536, "colors"}}) {
    SCOPED_TRACE(colored_from);
    const std::string path = folders.dir / ("strip_" + std::to_string(colored_from) + ".obj");
    write_strip(path, colored_from);
    std::unique_ptr<TriangleStream> stream = open_dereferenced_stream(path, options);
    ASSERT_TRUE(dereferenced_out_of_core(*stream));
    EXPECT_EQ(stream->attributes_left_out(), left_out);
    const IndexedMesh welded = read_mesh(*stream);
    ASSERT_EQ(welded.vertex_count(), n);
    if (!left_out.empty()) {
      EXPECT_TRUE(welded.colors.empty());
      continue;
    }
    ASSERT_EQ(welded.colors.size(), n);
    for (std::size_t v = 0; v < n; ++v) {
      // Welded vertices are numbered by first use: position (i % 2, i / 2) is vertex i of the file.
      const Vec3f p = welded.positions[v];
      const auto i = static_cast<std::size_t>(2 * p.y() + p.x());
      const Color expected = i >= colored_from ? Color{255, 0, 128, 255} : Color{255, 255, 255, 255};
      ASSERT_EQ(welded.colors[v], expected) << "file vertex " << i;
    }
  }
}

// Out of core a PLY's corners carry its vertices' normals, colors and texture coordinates, bit for bit, in
// binary and ASCII files alike, and an OBJ's its vertex colors. An OBJ indexes its normals and texture
// coordinates per corner, which the out-of-core pass does not follow: its stream says what it leaves out,
// for the warning.
TEST(ExternalDereference, OutOfCorePlyCornersCarryTheVertexAttributes) {
  const TestFolders folders;
  IndexedMesh mesh = shuffled_grid(30);
  const std::size_t n = mesh.vertex_count();
  mesh.normals.resize(n);
  mesh.colors.resize(n);
  mesh.uvs.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    mesh.normals[i] = Vec3f(static_cast<float>(i % 5), static_cast<float>(i % 7), 10).normalized();
    mesh.colors[i] = {static_cast<std::uint8_t>(i), static_cast<std::uint8_t>(3 * i), 7, 255};
    mesh.uvs[i] = mesh.positions[i].head<2>() * 3;
  }
  const std::string binary = folders.dir / "attributes.ply", ascii = folders.dir / "attributes_ascii.ply",
                    obj = folders.dir / "attributes.obj", plain = folders.dir / "plain.ply";
  write_mesh(binary, mesh);
  WriteOptions text;
  text.ascii = true;
  write_mesh(ascii, mesh, text);
  write_mesh(obj, mesh);
  write_mesh(plain, shuffled_grid(20));
  ReadOptions options;
  options.memory_budget = 600;  // 16 to 25 vertices a partition, by the records' size
  options.batch_capacity = 500;
  for (const std::string& path : {binary, ascii}) {
    SCOPED_TRACE(path);
    const IndexedMesh direct = read_mesh(path);
    ASSERT_EQ(direct.normals.size(), n);
    std::unique_ptr<TriangleStream> stream = open_dereferenced_stream(path, options);
    ASSERT_TRUE(dereferenced_out_of_core(*stream));
    EXPECT_EQ(stream->attributes_left_out(), "");
    ASSERT_NO_FATAL_FAILURE(expect_corners_carry(*stream, direct, {true, true, true}));
    // Welded back into a mesh, the vertices get their attributes again.
    std::unique_ptr<TriangleStream> again = open_dereferenced_stream(path, options);
    const IndexedMesh welded = read_mesh(*again);
    ASSERT_EQ(welded.vertex_count(), n);
    ASSERT_EQ(welded.colors.size(), n);
    for (std::size_t f2 = 0; f2 < welded.face_count(); ++f2) {
      for (int k = 0; k < 3; ++k) {
        ASSERT_EQ(welded.colors[welded.triangles[f2][k]], direct.colors[direct.triangles[f2][k]]);
        ASSERT_EQ(welded.uvs[welded.triangles[f2][k]], direct.uvs[direct.triangles[f2][k]]);
      }
    }
  }
  // An OBJ's colors belong to its positions and ride with them, its normals and uvs do not.
  const IndexedMesh direct_obj = read_mesh(obj);
  ASSERT_EQ(direct_obj.colors.size(), n);
  std::unique_ptr<TriangleStream> from_obj = open_dereferenced_stream(obj, options);
  EXPECT_TRUE(dereferenced_out_of_core(*from_obj));
  EXPECT_EQ(from_obj->attributes_left_out(), "normals and texture coordinates");
  ASSERT_NO_FATAL_FAILURE(expect_corners_carry(*from_obj, direct_obj, {false, true, false}));
  TriangleBatch batch;
  std::unique_ptr<TriangleStream> from_plain = open_dereferenced_stream(plain, options);
  EXPECT_TRUE(dereferenced_out_of_core(*from_plain));
  EXPECT_EQ(from_plain->attributes_left_out(), "");
  ASSERT_TRUE(from_plain->next(batch));
  EXPECT_TRUE(batch.corner_normals.empty() && batch.corner_colors.empty() && batch.corner_uvs.empty());
}

}  // namespace
}  // namespace ocsimp
