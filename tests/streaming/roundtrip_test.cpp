// Every format written and read back, then every pair of formats chained (mesh -> A -> B), on a mesh that has
// every attribute: counts exact, positions within each format's precision, attributes kept wherever both
// formats of a chain store them.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <unordered_set>
#include <vector>

#include "io_test_util.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

using test::TempDir;

struct Format {
  FileFormat format;
  const char* extension;
  bool exact;  // positions and float attributes come back bit for bit
  bool normals, colors, uvs;
};

const Format kFormats[] = {
    {FileFormat::ply, "ply", true, true, true, true},
    {FileFormat::obj, "obj", true, true, true, true},  // colors without alpha: the test mesh has alpha 255
    {FileFormat::stl, "stl", true, false, false, false},
    {FileFormat::drc, "drc", false, true, true, true},
};

// Draco at the default 16 bits; everything else is exact.
double position_tolerance(const IndexedMesh& mesh, const std::vector<Format>& chain) {
  double tolerance = 0;
  for (const Format& f : chain)
    if (!f.exact) tolerance += mesh.bounds().diagonal() / std::ldexp(1.0, 16 - 1);
  return tolerance;
}

// `got` went through `chain`; compare it with `want`.
void expect_equivalent(const IndexedMesh& want, const IndexedMesh& got, const std::vector<Format>& chain) {
  ASSERT_EQ(got.vertex_count(), want.vertex_count());
  ASSERT_EQ(got.face_count(), want.face_count());
  bool exact = true, normals = true, colors = true, uvs = true;
  for (const Format& f : chain) {
    exact = exact && f.exact;
    normals = normals && f.normals;
    colors = colors && f.colors;
    uvs = uvs && f.uvs;
  }
  const std::vector<Index> map = test::match_vertices(want, got, position_tolerance(want, chain));
  test::expect_same_faces(want, got, map);
  EXPECT_EQ(got.has_normals(), normals);
  EXPECT_EQ(got.has_colors(), colors);
  EXPECT_EQ(got.has_uvs(), uvs);
  for (std::size_t i = 0; i < got.vertex_count(); ++i) {
    const Index j = map[i];
    if (exact) {
      ASSERT_EQ(got.positions[i], want.positions[j]) << i;
    }
    if (normals) {
      if (exact) {
        ASSERT_EQ(got.normals[i], want.normals[j]) << i;
      } else {
        ASSERT_GT(got.normals[i].normalized().dot(want.normals[j]), 0.9999f) << i;
      }
    }
    if (uvs) {
      if (exact) {
        ASSERT_EQ(got.uvs[i], want.uvs[j]) << i;
      } else {
        ASSERT_LT((got.uvs[i] - want.uvs[j]).cwiseAbs().maxCoeff(), 1e-4f) << i;
      }
    }
    if (colors) {
      ASSERT_EQ(got.colors[i], want.colors[j]) << i;
    }
  }
}

std::string chain_name(const std::vector<Format>& chain) {
  std::string name;
  for (const Format& f : chain) name += std::string(name.empty() ? "" : " -> ") + f.extension;
  return name;
}

TEST(RoundTrip, EveryFormat) {
  TempDir dir;
  const IndexedMesh mesh = test::attributed_sphere(3);
  for (const Format& f : kFormats) {
    SCOPED_TRACE(f.extension);
    const std::string path = dir / (std::string("m.") + f.extension);
    write_mesh(path, mesh);
    EXPECT_EQ(detect_format(path), f.format);
    expect_equivalent(mesh, read_mesh(path), {f});
  }
}

// A progress callback that throws (a cancelled write) leaves no file, in every format: the PLY writer made
// its last report after the rename, so the file was complete but the caller was told the write failed.
TEST(RoundTrip, AWriteCancelledFromItsProgressLeavesNoFile) {
  TempDir dir;
  const IndexedMesh mesh = test::attributed_sphere(2);
  WriteOptions options;
  options.progress = [](std::string_view, std::uint64_t, std::uint64_t) { throw Error("cancelled"); };
  for (const Format& f : kFormats) {
    SCOPED_TRACE(f.extension);
    const std::string path = dir / (std::string("cancelled.") + f.extension);
    EXPECT_THROW(write_mesh(path, mesh, options), Error);
    EXPECT_FALSE(std::filesystem::exists(path));
  }
  // A format outside the enum wrote nothing and returned as if it had.
  WriteOptions odd;
  odd.format = static_cast<FileFormat>(9);
  EXPECT_THROW(write_mesh(dir / "odd.ply", mesh, odd), Error);
}

TEST(RoundTrip, EveryPairOfFormats) {
  TempDir dir;
  const IndexedMesh mesh = test::attributed_sphere(2);
  for (const Format& a : kFormats) {
    const std::string first = dir / (std::string("a.") + a.extension);
    write_mesh(first, mesh);
    const IndexedMesh via_a = read_mesh(first);
    for (const Format& b : kFormats) {
      SCOPED_TRACE(chain_name({a, b}));
      const std::string second = dir / (std::string("b.") + b.extension);
      write_mesh(second, via_a);
      expect_equivalent(mesh, read_mesh(second), {a, b});
    }
  }
}

TEST(RoundTrip, AsciiVariants) {
  TempDir dir;
  const IndexedMesh mesh = test::attributed_sphere(2);
  WriteOptions options;
  options.ascii = true;
  write_mesh(dir / "a.stl", mesh, options);
  expect_equivalent(mesh, read_mesh(dir / "a.stl"), {kFormats[2]});
  write_mesh(dir / "a.ply", mesh, options);
  expect_equivalent(mesh, read_mesh(dir / "a.ply"), {kFormats[0]});
}

// A real scan through every format: the face count survives; STL welds back to the distinct referenced
// positions; OBJ and PLY keep every vertex.
TEST(RoundTrip, SharedBunnyThroughEveryFormat) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "bunny.ply");
  const IndexedMesh bunny = read_mesh(path);
  TempDir dir;
  struct Key {
    std::size_t operator()(const Vec3f& p) const {
      return std::hash<float>()(p.x()) ^ (std::hash<float>()(p.y()) << 1) ^ (std::hash<float>()(p.z()) << 2);
    }
  };
  std::unordered_set<Vec3f, Key> distinct;
  for (const Triangle& t : bunny.triangles)
    for (Index v : t) distinct.insert(bunny.positions[v]);
  for (const Format& f : kFormats) {
    SCOPED_TRACE(f.extension);
    const std::string out = dir / (std::string("bunny.") + f.extension);
    write_mesh(out, bunny);
    const IndexedMesh back = read_mesh(out);
    EXPECT_EQ(back.face_count(), bunny.face_count());
    if (f.format == FileFormat::stl) {
      EXPECT_EQ(back.vertex_count(), distinct.size());
    }
    if (f.format == FileFormat::obj || f.format == FileFormat::ply) {
      EXPECT_EQ(back.positions, bunny.positions);
      EXPECT_EQ(back.triangles, bunny.triangles);
    }
    const double tolerance = f.exact ? 0.0 : bunny.bounds().diagonal() / std::ldexp(1.0, 15);
    EXPECT_LE((back.bounds().lo - bunny.bounds().lo).norm(), tolerance);
    EXPECT_LE((back.bounds().hi - bunny.bounds().hi).norm(), tolerance);
  }
}

}  // namespace
}  // namespace ocsimp
