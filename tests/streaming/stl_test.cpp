#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "io_test_util.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

using test::TempDir;

// The corners of every face, in order: what an STL file holds.
std::vector<std::array<Vec3f, 3>> soup(const IndexedMesh& mesh) {
  std::vector<std::array<Vec3f, 3>> corners;
  for (const Triangle& t : mesh.triangles)
    corners.push_back({mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]});
  return corners;
}

void expect_same_soup(const IndexedMesh& a, const IndexedMesh& b) {
  const auto x = soup(a), y = soup(b);
  ASSERT_EQ(x.size(), y.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    for (int k = 0; k < 3; ++k) ASSERT_EQ(x[i][k], y[i][k]) << "face " << i << " corner " << k;
}

TEST(Stl, BinaryCubeWeldsBackToTheCube) {
  TempDir dir;
  const IndexedMesh mesh = test::cube(4);
  write_mesh(dir / "c.stl", mesh);
  const std::string bytes = test::read_file_bytes(dir / "c.stl");
  ASSERT_EQ(bytes.size(), 84 + 50 * mesh.face_count());
  EXPECT_NE(bytes.substr(0, 5), "solid");  // would make readers guess ASCII
  const IndexedMesh back = read_mesh(dir / "c.stl");
  EXPECT_EQ(back.vertex_count(), 6u * 4 * 4 + 2);  // a closed n x n x n cube: 6 n^2 + 2 lattice points
  EXPECT_EQ(back.face_count(), mesh.face_count());
  EXPECT_FALSE(back.has_normals() || back.has_colors() || back.has_uvs());
  expect_same_soup(mesh, back);  // same corners, in order, bit for bit
  const std::vector<Index> map = test::match_vertices(mesh, back, 0.0);
  test::expect_same_faces(mesh, back, map);
  const MeshTopology t = analyze_topology(back);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.components, 1u);
}

TEST(Stl, BinaryFacetNormalsAreComputed) {
  TempDir dir;
  IndexedMesh mesh = test::cube(2);
  mesh.positions.emplace_back(5, 5, 5);
  const Index last = static_cast<Index>(mesh.positions.size() - 1);
  mesh.triangles.push_back({last, last, last});  // zero area: normal 0
  write_mesh(dir / "n.stl", mesh);
  const std::string bytes = test::read_file_bytes(dir / "n.stl");
  for (std::size_t f = 0; f < mesh.face_count(); ++f) {
    float v[12];
    std::memcpy(v, bytes.data() + 84 + 50 * f, sizeof v);
    const Vec3f n(v[0], v[1], v[2]), a(v[3], v[4], v[5]), b(v[6], v[7], v[8]), c(v[9], v[10], v[11]);
    const Vec3f expected = (b - a).cross(c - a);
    if (expected.norm() == 0) {
      EXPECT_EQ(n, Vec3f::Zero());
      continue;
    }
    EXPECT_NEAR(n.norm(), 1.0f, 1e-6f);
    EXPECT_GT(n.dot(expected.normalized()), 0.99999f);
    // Cube faces point along an axis, away from the center.
    EXPECT_NEAR(n.cwiseAbs().maxCoeff(), 1.0f, 1e-6f);
    EXPECT_GT(n.dot((a + b + c) / 3 - Vec3f(0.5f, 0.5f, 0.5f)), 0.0f);
  }
  // The zero-area triangle stays in the stream and in the mesh.
  EXPECT_EQ(read_mesh(dir / "n.stl").face_count(), mesh.face_count());
}

TEST(Stl, AsciiRoundTripIsExact) {
  TempDir dir;
  const IndexedMesh mesh = test::sphere(2, 3.7f);
  WriteOptions options;
  options.ascii = true;
  write_mesh(dir / "s.stl", mesh, options);
  EXPECT_EQ(test::read_file_bytes(dir / "s.stl").substr(0, 6), "solid ");
  const IndexedMesh back = read_mesh(dir / "s.stl");
  EXPECT_EQ(back.vertex_count(), mesh.vertex_count());
  expect_same_soup(mesh, back);
  test::expect_same_faces(mesh, back, test::match_vertices(mesh, back, 0.0));
}

TEST(Stl, AsciiAfterAByteOrderMarkIsStillAscii) {
  // Read as binary, its first bytes made a triangle count of about 1.8 billion.
  TempDir dir;
  const IndexedMesh mesh = test::sphere(1);
  WriteOptions options;
  options.ascii = true;
  write_mesh(dir / "s.stl", mesh, options);
  test::write_file_bytes(dir / "s.stl", "\xEF\xBB\xBF" + test::read_file_bytes(dir / "s.stl"));
  const IndexedMesh back = read_mesh(dir / "s.stl");
  expect_same_soup(mesh, back);
}

TEST(Stl, BinaryHeaderSayingSolidIsStillBinary) {
  TempDir dir;
  const IndexedMesh mesh = test::cube(2);
  write_mesh(dir / "c.stl", mesh);
  std::string bytes = test::read_file_bytes(dir / "c.stl");
  const std::string header = "solid cube exported by a CAD tool";
  bytes.replace(0, header.size(), header);
  test::write_file_bytes(dir / "c.stl", bytes);
  const IndexedMesh back = read_mesh(dir / "c.stl");
  EXPECT_EQ(back.face_count(), mesh.face_count());
  expect_same_soup(mesh, back);
}

TEST(Stl, BinaryIgnoresBytesAfterTheLastTriangle) {
  TempDir dir;
  const IndexedMesh mesh = test::cube(1);
  write_mesh(dir / "c.stl", mesh);
  test::write_file_bytes(dir / "c.stl", test::read_file_bytes(dir / "c.stl") + std::string(17, '\0'));
  EXPECT_EQ(read_mesh(dir / "c.stl").face_count(), 12u);
}

// Streaming writers may leave the header's count at 0 (or a first batch's): the whole triangles that follow
// are read, with a warning, where they were dropped without one. Bytes that are not whole triangles are
// still ignored, and named.
TEST(Stl, BinaryReadsWholeTrianglesPastTheHeadersCount) {
  TempDir dir;
  const IndexedMesh mesh = test::cube(1);
  write_mesh(dir / "c.stl", mesh);
  const std::string bytes = test::read_file_bytes(dir / "c.stl");
  std::vector<std::string> warnings;
  ReadOptions options;
  options.warn = [&](const std::string& message) { warnings.push_back(message); };
  for (std::uint32_t claimed : {0u, 5u}) {
    std::string edited = bytes;
    std::memcpy(edited.data() + 80, &claimed, 4);
    test::write_file_bytes(dir / "c.stl", edited);
    warnings.clear();
    const IndexedMesh back = read_mesh(dir / "c.stl", options);
    EXPECT_EQ(back.face_count(), 12u) << claimed;
    expect_same_soup(mesh, back);
    ASSERT_EQ(warnings.size(), 1u) << claimed;
    EXPECT_EQ(warnings[0], "the binary STL header claims " + std::to_string(claimed) +
                               " triangles, but the file holds 12; all 12 are read");
  }
  test::write_file_bytes(dir / "c.stl", bytes + std::string(17, '\0'));
  warnings.clear();
  EXPECT_EQ(read_mesh(dir / "c.stl", options).face_count(), 12u);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("the 17 bytes after the 12 triangles"), std::string::npos) << warnings[0];
}

TEST(Stl, AsciiToleratesCaseBlanksLineEndingsAndSeveralSolids) {
  TempDir dir;
  const std::string text =
      "  SOLID first part\r\n"
      "facet normal nan nan nan\r\n"  // writers put NaN normals on degenerate facets; normals are ignored
      "\tOuter   Loop\r\n"
      "   VERTEX 0 0 0\r\n"
      "vertex\t1e0  0 0\r\n"
      "vertex 0 1 0   \r\n"
      "EndLoop\r\n"
      "endfacet\r\n"
      "\r\n"
      "endsolid first part\r\n"
      "solid second\n"
      "facet normal 0 0 1\n"
      "outer loop\n"
      "vertex 1 0 0\nvertex 1 1 0\nvertex 0.5 1.5 0\nvertex 0 1 0\n"  // a quad: fanned into two triangles
      "endloop\n"
      "endfacet\n"
      "endsolid";  // without a line end
  test::write_file_bytes(dir / "two.stl", text);
  const IndexedMesh m = read_mesh(dir / "two.stl");
  EXPECT_EQ(m.face_count(), 3u);
  EXPECT_EQ(m.vertex_count(), 5u);  // (1,0,0) and (0,1,0) are shared between the solids
  EXPECT_EQ(m.bounds().hi, Vec3d(1, 1.5, 0));
}

TEST(Stl, AsciiLinesMayEndInACarriageReturnAlone) {
  test::TempDir dir;
  test::write_file_bytes(
      dir / "mac.stl",
      "solid mac\rfacet normal 0 0 1\router loop\rvertex 0 0 0\rvertex 1 0 0\rvertex 0 1 0\r"
      "endloop\rendfacet\rendsolid mac\r");
  const IndexedMesh m = read_mesh(dir / "mac.stl");
  EXPECT_EQ(m.face_count(), 1u);
  EXPECT_EQ(m.positions[1], Vec3f(1, 0, 0));
}

TEST(Stl, AsciiPolygonFacetsSplitAcrossBatches) {
  TempDir dir;
  test::write_file_bytes(dir / "p.stl",
                         "solid p\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 2 1 0\n"
                         "vertex 1 2 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid p\n");
  ReadOptions options;
  options.batch_capacity = 2;
  auto stream = open_triangle_stream(dir / "p.stl", options);
  TriangleBatch batch;
  std::vector<std::array<Vec3f, 3>> corners;
  while (stream->next(batch)) {
    EXPECT_LE(batch.size(), 2u);
    corners.insert(corners.end(), batch.corners.begin(), batch.corners.end());
  }
  ASSERT_EQ(corners.size(), 3u);  // the pentagon's fan around its first vertex
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(corners[i][0], Vec3f(0, 0, 0));
    EXPECT_EQ(corners[i][2], i + 1 < 3 ? corners[i + 1][1] : Vec3f(0, 1, 0));
  }
}

TEST(Stl, EmptySolidHasNoFaces) {
  TempDir dir;
  test::write_file_bytes(dir / "e.stl", "solid empty\nendsolid empty\n");
  EXPECT_THROW(read_mesh(dir / "e.stl"), Error);
}

TEST(Stl, StreamsCornersAndBoundsLeaveTheStreamAlone) {
  TempDir dir;
  const IndexedMesh mesh = test::sphere(2, 2.0f);
  for (bool ascii : {false, true}) {
    WriteOptions options;
    options.ascii = ascii;
    write_mesh(dir / "s.stl", mesh, options);
    ReadOptions read_options;
    read_options.batch_capacity = 7;
    auto stream = open_triangle_stream(dir / "s.stl", read_options);
    EXPECT_FALSE(stream->indexed());
    EXPECT_EQ(stream->triangles_hint(), ascii ? 0u : mesh.face_count());
    TriangleBatch batch;
    std::vector<std::array<Vec3f, 3>> corners;
    ASSERT_TRUE(stream->next(batch));
    corners.insert(corners.end(), batch.corners.begin(), batch.corners.end());
    const Box3 box = stream->bounds();  // a pre-scan in the middle of the stream
    EXPECT_EQ(box.lo, mesh.bounds().lo);
    EXPECT_EQ(box.hi, mesh.bounds().hi);
    while (stream->next(batch)) {
      EXPECT_LE(batch.size(), 7u);
      EXPECT_TRUE(batch.triangles.empty());
      corners.insert(corners.end(), batch.corners.begin(), batch.corners.end());
    }
    EXPECT_TRUE(corners == soup(mesh)) << (ascii ? "ascii" : "binary");
    EXPECT_EQ(stream->bytes_read(), stream->bytes_total());
  }
}

TEST(Stl, WriterRefusesNonFinitePositions) {
  TempDir dir;
  IndexedMesh mesh = test::cube(1);
  mesh.positions[3].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(write_mesh(dir / "x.stl", mesh), Error);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path));
}

// One case per file of tests/data/malformed/stl.
const std::vector<test::MalformedCase> kMalformed = {
    {"binary_count_too_large.stl", FilePosition::Kind::byte, 80, "claims 1000 triangles"},
    {"binary_short.stl", FilePosition::Kind::byte, 40, "shorter than its 84-byte header"},
    {"binary_nan.stl", FilePosition::Kind::byte, 112, "NaN or infinite"},
    {"ascii_bad_number.stl", FilePosition::Kind::line, 5, "not a number: 'x'"},
    {"ascii_missing_outer_loop.stl", FilePosition::Kind::line, 3, "expected 'outer loop'"},
    {"ascii_two_vertices.stl", FilePosition::Kind::line, 13, "a facet needs 3 vertices (found 2)"},
    {"ascii_truncated.stl", FilePosition::Kind::line, 12, "ends inside a facet"},
    {"ascii_no_endsolid.stl", FilePosition::Kind::line, 8, "the file ends before 'endsolid'"},
    {"ascii_solid_only.stl", FilePosition::Kind::line, 1, "the file ends before 'endsolid'"},
    {"ascii_garbage_in_solid.stl", FilePosition::Kind::line, 2, "expected 'facet' or 'endsolid'"},
    {"ascii_inf_vertex.stl", FilePosition::Kind::line, 5, "NaN or infinite"},
    {"ascii_extra_token.stl", FilePosition::Kind::line, 4, "unexpected '4'"},
    {"ascii_missing_endfacet.stl", FilePosition::Kind::line, 8, "expected 'endfacet'"},
    {"ascii_nul_in_name.stl", FilePosition::Kind::byte, 80,
     "begins like an ASCII STL, but byte 7 is not text"},
};

class StlMalformed : public ::testing::TestWithParam<test::MalformedCase> {};
TEST_P(StlMalformed, NamesFilePlaceAndReason) {
  test::expect_malformed("stl", GetParam());
}
INSTANTIATE_TEST_SUITE_P(Corpus, StlMalformed, ::testing::ValuesIn(kMalformed), test::case_name);
TEST(StlMalformedCorpus, EveryFileHasACase) {
  test::expect_all_covered("stl", kMalformed);
}

}  // namespace
}  // namespace ocsimp
