#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "io_test_util.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

using test::TempDir;

// Quantizing to `bits` over the largest extent moves a point by at most half a step per axis, which is well
// inside diagonal / 2^(bits-1).
double quantization_bound(const IndexedMesh& mesh, int bits) {
  return mesh.bounds().diagonal() / std::ldexp(1.0, bits - 1);
}

TEST(Drc, RoundTripKeepsAttributesWithinQuantization) {
  TempDir dir;
  const IndexedMesh mesh = test::attributed_sphere(3);
  write_mesh(dir / "s.drc", mesh);
  const IndexedMesh back = read_mesh(dir / "s.drc");
  ASSERT_EQ(back.vertex_count(), mesh.vertex_count());
  ASSERT_EQ(back.face_count(), mesh.face_count());
  ASSERT_TRUE(back.has_normals() && back.has_uvs() && back.has_colors());
  const std::vector<Index> map = test::match_vertices(mesh, back, quantization_bound(mesh, 16));
  test::expect_same_faces(mesh, back, map);
  for (std::size_t i = 0; i < back.vertex_count(); ++i) {
    const Index j = map[i];
    EXPECT_GT(back.normals[i].normalized().dot(mesh.normals[j]), 0.9999f) << i;  // 12-bit octahedral normals
    EXPECT_LT((back.uvs[i] - mesh.uvs[j]).cwiseAbs().maxCoeff(), 1e-4f) << i;    // 16 bits over a unit range
    EXPECT_EQ(back.colors[i], mesh.colors[j]) << i;                              // bytes stay bytes
  }
}

TEST(Drc, FewerPositionBitsGiveLargerErrorsAndSmallerFiles) {
  TempDir dir;
  const IndexedMesh mesh = test::sphere(4, 10.0f);
  double previous_error = 0;
  std::uintmax_t previous_size = 0;
  for (int bits : {20, 14, 10, 7}) {
    WriteOptions options;
    options.draco_position_bits = bits;
    const std::string path = dir / ("s" + std::to_string(bits) + ".drc");
    write_mesh(path, mesh, options);
    const IndexedMesh back = read_mesh(path);
    ASSERT_EQ(back.vertex_count(), mesh.vertex_count()) << bits;
    double error = 0;
    const std::vector<Index> map = test::match_vertices(mesh, back, quantization_bound(mesh, bits), &error);
    test::expect_same_faces(mesh, back, map);
    const std::uintmax_t size = std::filesystem::file_size(path);
    if (previous_size != 0) {
      EXPECT_GT(error, previous_error) << bits;
      EXPECT_LT(size, previous_size) << bits;
    }
    previous_error = error;
    previous_size = size;
  }
}

TEST(Drc, EveryCompressionLevelRoundTrips) {
  TempDir dir;
  const IndexedMesh mesh = test::attributed_sphere(2);
  for (int level : {0, 3, 7, 10}) {
    WriteOptions options;
    options.draco_compression_level = level;
    write_mesh(dir / "s.drc", mesh, options);
    const IndexedMesh back = read_mesh(dir / "s.drc");
    ASSERT_EQ(back.vertex_count(), mesh.vertex_count()) << level;
    test::expect_same_faces(mesh, back, test::match_vertices(mesh, back, quantization_bound(mesh, 16)));
  }
}

TEST(Drc, PositionsOnly) {
  TempDir dir;
  const IndexedMesh mesh = test::cube(3);
  write_mesh(dir / "c.drc", mesh);
  const IndexedMesh back = read_mesh(dir / "c.drc");
  EXPECT_FALSE(back.has_normals() || back.has_uvs() || back.has_colors());
  test::expect_same_faces(mesh, back, test::match_vertices(mesh, back, quantization_bound(mesh, 16)));
  EXPECT_EQ(analyze_topology(back).boundary_edges, 0u);
}

TEST(Drc, AFanOfManyFacesRoundTrips) {
  // A disk fanned from its centre to 40,000 rim vertices: Draco's edgebreaker coder took time growing with
  // the square of the centre's faces (50 s at 640,000), so such meshes are written with its sequential coder.
  TempDir dir;
  IndexedMesh fan;
  constexpr Index kRim = 40000;
  fan.positions.emplace_back(0, 0, 0);
  for (Index i = 0; i < kRim; ++i) {
    const double angle = 2 * M_PI * i / kRim;
    fan.positions.emplace_back(static_cast<float>(std::cos(angle)), static_cast<float>(std::sin(angle)), 0);
    fan.triangles.push_back({0, i + 1, (i + 1) % kRim + 1});
  }
  write_mesh(dir / "fan.drc", fan);
  const IndexedMesh back = read_mesh(dir / "fan.drc");
  ASSERT_EQ(back.vertex_count(), fan.vertex_count());
  ASSERT_EQ(back.face_count(), fan.face_count());
  // The same disk: one centre on every face, every other vertex on the rim, the rim its only border.
  const double bound = quantization_bound(fan, 16);
  std::vector<Index> faces_at(back.vertex_count(), 0);
  for (const Triangle& t : back.triangles) {
    for (Index v : t) ++faces_at[v];
  }
  const auto centre =
      static_cast<Index>(std::max_element(faces_at.begin(), faces_at.end()) - faces_at.begin());
  EXPECT_EQ(faces_at[centre], kRim);
  EXPECT_LT(back.positions[centre].norm(), bound);
  for (Index v = 0; v < back.vertex_count(); ++v) {
    if (v != centre) {
      EXPECT_NEAR(back.positions[v].norm(), 1.0, bound) << v;
    }
  }
  for (const Triangle& t : back.triangles) EXPECT_TRUE(t[0] == centre || t[1] == centre || t[2] == centre);
  EXPECT_EQ(analyze_topology(back).boundary_edges, kRim);
}

TEST(Drc, StreamServesTheDecodedFacesInBatches) {
  TempDir dir;
  const IndexedMesh mesh = test::sphere(3);
  write_mesh(dir / "s.drc", mesh);
  ReadOptions options;
  options.batch_capacity = 100;
  auto stream = open_triangle_stream(dir / "s.drc", options);
  ASSERT_TRUE(stream->indexed());
  EXPECT_EQ(stream->vertices().vertex_count(), mesh.vertex_count());
  EXPECT_EQ(stream->triangles_hint(), mesh.face_count());
  const Box3 box = stream->bounds();
  EXPECT_LT((box.lo - mesh.bounds().lo).norm(), quantization_bound(mesh, 16));
  EXPECT_LT((box.hi - mesh.bounds().hi).norm(), quantization_bound(mesh, 16));
  TriangleBatch batch;
  std::size_t total = 0;
  while (stream->next(batch)) {
    EXPECT_LE(batch.size(), 100u);
    for (const Triangle& t : batch.triangles)
      for (Index v : t) EXPECT_LT(v, mesh.vertex_count());
    total += batch.size();
  }
  EXPECT_EQ(total, mesh.face_count());
  EXPECT_EQ(stream->bytes_read(), stream->bytes_total());
}

TEST(Drc, RejectsBadOptionsWithoutWriting) {
  TempDir dir;
  const IndexedMesh mesh = test::cube(1);
  for (auto [bits, level] : {std::pair{0, 7}, {kMaxDracoPositionBits + 1, 7}, {16, -1}, {16, 11}}) {
    WriteOptions options;
    options.draco_position_bits = bits;
    options.draco_compression_level = level;
    EXPECT_THROW(write_mesh(dir / "c.drc", mesh, options), Error) << bits << " " << level;
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path));
}

TEST(Drc, RefusesValuesSpanningMoreThanAFloat) {
  // Draco quantizes over each axis's span, a float difference inside the encoder: -2e38 to 2e38 overflows it
  // (the encoder crashed). Such a mesh is refused with a message; huge normals are normalized and encode.
  TempDir dir;
  IndexedMesh wide = test::cube(1);
  wide.positions[0].x() = -2e38f;
  wide.positions[1].x() = 2e38f;
  try {
    write_mesh(dir / "wide.drc", wide);
    ADD_FAILURE() << "a mesh wider than a float was written";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("along axis x"), std::string::npos) << e.what();
  }
  // Too narrow a span overflows the quantization scale instead (the encoder wrote every vertex at one
  // point, or crashed at level 10).
  IndexedMesh narrow = test::sphere(2, 1e-35f);
  try {
    write_mesh(dir / "narrow.drc", narrow);
    ADD_FAILURE() << "a mesh too narrow to quantize was written";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("too little"), std::string::npos) << e.what();
  }
  WriteOptions coarse;
  coarse.draco_position_bits = 4;  // 15 / 2e-35 fits a float
  write_mesh(dir / "narrow4.drc", narrow, coarse);
  const IndexedMesh narrow_back = read_mesh(dir / "narrow4.drc");
  EXPECT_LE(narrow_back.bounds().extent().maxCoeff(), 2.01e-35);
  EXPECT_GE(narrow_back.bounds().extent().maxCoeff(), 1.99e-35);
  std::filesystem::remove(dir / "narrow4.drc");
  IndexedMesh uvs = test::attributed_sphere(2);
  uvs.uvs[0].x() = -3e38f;
  uvs.uvs[1].x() = 3e38f;
  EXPECT_THROW(write_mesh(dir / "uvs.drc", uvs), Error);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path));

  IndexedMesh normals = test::attributed_sphere(2);
  normals.normals[0] = Vec3f(3e38f, 3e38f, 0);
  write_mesh(dir / "normals.drc", normals);
  const IndexedMesh back = read_mesh(dir / "normals.drc");
  ASSERT_EQ(back.vertex_count(), normals.vertex_count());
  // Draco may reorder the points: the huge normal is the one at the first vertex's position.
  std::size_t at = 0;
  for (std::size_t i = 0; i < back.vertex_count(); ++i) {
    if ((back.positions[i] - normals.positions[0]).norm() <
        (back.positions[at] - normals.positions[0]).norm())
      at = i;
  }
  EXPECT_NEAR(back.normals[at].x(), std::sqrt(0.5f), 1e-3);
  EXPECT_NEAR(back.normals[at].y(), std::sqrt(0.5f), 1e-3);
}

TEST(Drc, TruncatedFileIsAnError) {
  TempDir dir;
  write_mesh(dir / "s.drc", test::sphere(3));
  const std::string bytes = test::read_file_bytes(dir / "s.drc");
  for (std::size_t keep : {bytes.size() / 2, bytes.size() - 1, std::size_t(12)}) {
    test::write_file_bytes(dir / "t.drc", bytes.substr(0, keep));
    try {
      read_mesh(dir / "t.drc");
      ADD_FAILURE() << "a file cut to " << keep << " bytes was read";
    } catch (const Error& e) {
      EXPECT_EQ(e.file(), dir / "t.drc");
      EXPECT_EQ(e.position().kind, FilePosition::Kind::byte) << e.what();
      EXPECT_LE(e.position().value, keep) << e.what();
      EXPECT_FALSE(e.reason().empty());
    }
  }
}

// One case per file of tests/data/malformed/drc.
const std::vector<test::MalformedCase> kMalformed = {
    {"point_cloud.drc", FilePosition::Kind::byte, 7, "point cloud"},
    {"header_only.drc", FilePosition::Kind::byte, 5, "Draco header cut short (5 of 11 bytes)"},
    {"bad_version.drc", FilePosition::Kind::byte, 5, "Draco version 99.1 is newer"},
    {"unknown_method.drc", FilePosition::Kind::byte, 8, "unknown Draco mesh encoding method 7"},
    {"truncated.drc", FilePosition::Kind::byte, 29, "Draco: Failed to decode"},
};

class DrcMalformed : public ::testing::TestWithParam<test::MalformedCase> {};
TEST_P(DrcMalformed, NamesFilePlaceAndReason) {
  test::expect_malformed("drc", GetParam());
}
INSTANTIATE_TEST_SUITE_P(Corpus, DrcMalformed, ::testing::ValuesIn(kMalformed), test::case_name);
TEST(DrcMalformedCorpus, EveryFileHasACase) {
  test::expect_all_covered("drc", kMalformed);
}

}  // namespace
}  // namespace ocsimp
