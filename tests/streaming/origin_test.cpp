// Coordinates far from zero (IndexedMesh::origin): files that hold them more precisely than floats are read
// relative to their first vertex, and the writers put the origin back, so a georeferenced scan keeps detail
// that floats at its coordinates could not hold (float spacing is 0.25 at 4e6).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "io_test_util.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/mesh_stream.h"
#include "test_support.h"

namespace ocsimp {
namespace {

using test::TempDir;

const Vec3d kFar(652'113.25, 4'210'775.5, 312.125);

// A 0.5 x 0.5 grid of 20 x 20 quads with 1 mm bumps, in true (double) coordinates around `at`.
struct TrueMesh {
  std::vector<Vec3d> points;
  std::vector<Triangle> triangles;
};
TrueMesh bumpy_tile(const Vec3d& at) {
  TrueMesh mesh;
  const IndexedMesh grid = test::grid_square(20);
  for (const Vec3f& p : grid.positions) {
    const double bump = 0.001 * std::sin(40.0 * p.x()) * std::cos(40.0 * p.y());
    mesh.points.push_back(at + Vec3d(0.5 * p.x(), 0.5 * p.y(), bump));
  }
  mesh.triangles = grid.triangles;
  return mesh;
}

// A binary PLY with x y z of `type` (double or int), written by hand so the reader is tested on its own.
std::string binary_ply(const TrueMesh& mesh, const std::string& type) {
  std::string out = "ply\nformat binary_little_endian 1.0\nelement vertex " +
                    std::to_string(mesh.points.size()) + "\nproperty " + type + " x\nproperty " + type +
                    " y\nproperty " + type + " z\nelement face " + std::to_string(mesh.triangles.size()) +
                    "\nproperty list uchar int vertex_indices\nend_header\n";
  auto put = [&out](const auto& value) {
    char bytes[sizeof value];
    std::memcpy(bytes, &value, sizeof value);
    out.append(bytes, sizeof value);
  };
  for (const Vec3d& p : mesh.points) {
    for (int k = 0; k < 3; ++k) {
      if (type == "double") put(p[k]);
      if (type == "float") put(static_cast<float>(p[k]));
      if (type == "int") put(static_cast<std::int32_t>(std::lround(p[k])));
    }
  }
  for (const Triangle& t : mesh.triangles) {
    put(std::uint8_t{3});
    for (Index v : t) put(static_cast<std::int32_t>(v));
  }
  return out;
}

std::string obj_text(const TrueMesh& mesh) {
  std::string out;
  char line[128];
  for (const Vec3d& p : mesh.points) {
    std::snprintf(line, sizeof line, "v %.17g %.17g %.17g\n", p.x(), p.y(), p.z());
    out += line;
  }
  for (const Triangle& t : mesh.triangles)
    out += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) +
           "\n";
  return out;
}

// Largest distance between the mesh's true positions (origin + position, in double) and `truth`.
double largest_error(const IndexedMesh& mesh, const TrueMesh& truth) {
  EXPECT_EQ(mesh.positions.size(), truth.points.size());
  double worst = 0;
  for (std::size_t i = 0; i < truth.points.size() && i < mesh.positions.size(); ++i)
    worst = std::max(worst, (mesh.origin + mesh.positions[i].cast<double>() - truth.points[i]).norm());
  return worst;
}

TEST(Origin, DoublePlyFarFromZeroIsReadRelativeToItsFirstVertex) {
  TempDir dir;
  const TrueMesh truth = bumpy_tile(kFar);
  test::write_file_bytes(dir / "far.ply", binary_ply(truth, "double"));
  const IndexedMesh mesh = read_mesh(dir / "far.ply");
  EXPECT_EQ(mesh.origin, truth.points[0]);
  EXPECT_EQ(mesh.positions[0], Vec3f::Zero());
  // Positions within 0.5 of the origin: float spacing there is 3e-8, where at 4e6 it would be 0.25.
  EXPECT_LT(largest_error(mesh, truth), 1e-7);
  EXPECT_EQ(mesh.triangles, truth.triangles);
}

TEST(Origin, IntegerCoordinatesFarFromZeroToo) {
  TempDir dir;
  TrueMesh truth = bumpy_tile(Vec3d::Zero());
  for (Vec3d& p : truth.points)
    p = Vec3d(123'456'789, 987'654'321, 0) + (1000.0 * p).array().round().matrix();
  test::write_file_bytes(dir / "int.ply", binary_ply(truth, "int"));
  const IndexedMesh mesh = read_mesh(dir / "int.ply");
  EXPECT_EQ(mesh.origin, truth.points[0]);
  EXPECT_EQ(largest_error(mesh, truth), 0.0);  // integers up to 500 apart are exact floats
}

TEST(Origin, FilesNearZeroAndFloatFilesKeepAZeroOrigin) {
  TempDir dir;
  // Near zero, a double file reads as before: each coordinate rounded once to float.
  const TrueMesh near = bumpy_tile(Vec3d(3, -2, 1000));
  test::write_file_bytes(dir / "near.ply", binary_ply(near, "double"));
  const IndexedMesh mesh = read_mesh(dir / "near.ply");
  EXPECT_EQ(mesh.origin, Vec3d::Zero());
  for (std::size_t i = 0; i < near.points.size(); ++i)
    EXPECT_EQ(mesh.positions[i], near.points[i].cast<float>()) << "vertex " << i;
  // A float file far from zero holds no more than floats do: nothing to keep.
  test::write_file_bytes(dir / "float.ply", binary_ply(bumpy_tile(kFar), "float"));
  EXPECT_EQ(read_mesh(dir / "float.ply").origin, Vec3d::Zero());
}

TEST(Origin, ObjTextFarFromZero) {
  TempDir dir;
  const TrueMesh truth = bumpy_tile(kFar);
  test::write_file_bytes(dir / "far.obj", obj_text(truth));
  const IndexedMesh mesh = read_mesh(dir / "far.obj");
  EXPECT_EQ(mesh.origin, truth.points[0]);
  EXPECT_LT(largest_error(mesh, truth), 1e-7);
  // Near zero, OBJ text is still rounded straight to float.
  const TrueMesh near = bumpy_tile(Vec3d(0.1, 0.2, 0.3));
  test::write_file_bytes(dir / "near.obj", obj_text(near));
  const IndexedMesh near_mesh = read_mesh(dir / "near.obj");
  EXPECT_EQ(near_mesh.origin, Vec3d::Zero());
  for (std::size_t i = 0; i < near.points.size(); ++i)
    EXPECT_EQ(near_mesh.positions[i], near.points[i].cast<float>()) << "vertex " << i;
}

TEST(Origin, PlyAndObjWritersPutTheOriginBack) {
  TempDir dir;
  const TrueMesh truth = bumpy_tile(kFar);
  test::write_file_bytes(dir / "far.ply", binary_ply(truth, "double"));
  const IndexedMesh mesh = read_mesh(dir / "far.ply");
  for (const char* name : {"out.ply", "out.obj"}) {
    for (bool ascii : {false, true}) {
      WriteOptions options;
      options.ascii = ascii;
      write_mesh(dir / name, mesh, options);
      const IndexedMesh back = read_mesh(dir / name);
      EXPECT_LT(largest_error(back, truth), 1e-7) << name << (ascii ? " ascii" : "");
    }
  }
  EXPECT_NE(test::file_bytes(dir / "out.ply").find("property double x"), std::string::npos);
  // Without an origin the PLY stays float.
  write_mesh(dir / "zero.ply", test::grid_square(2));
  EXPECT_NE(test::file_bytes(dir / "zero.ply").find("property float x"), std::string::npos);
}

TEST(Origin, StlGetsTheNearestFloatsToTheTruePositions) {
  TempDir dir;
  const TrueMesh truth = bumpy_tile(kFar);
  test::write_file_bytes(dir / "far.ply", binary_ply(truth, "double"));
  write_mesh(dir / "out.stl", read_mesh(dir / "far.ply"));
  const IndexedMesh back = read_mesh(dir / "out.stl");
  EXPECT_EQ(back.origin, Vec3d::Zero());
  // STL holds floats, 0.5 apart at y = 4.2e6: each corner is the float nearest a true vertex (so some true
  // vertices fall on the same float and are welded).
  std::vector<Vec3f> rounded;
  for (const Vec3d& p : truth.points) rounded.push_back(nearest_float(p));
  for (const Vec3f& p : back.positions)
    EXPECT_NE(std::find(rounded.begin(), rounded.end(), p), rounded.end()) << p.transpose();
  EXPECT_EQ(back.triangles.size(), truth.triangles.size());
}

TEST(Origin, OutOfCoreReadsAndSoupStreamsKeepIt) {
  TempDir dir;
  const TrueMesh truth = bumpy_tile(kFar);
  test::write_file_bytes(dir / "far.ply", binary_ply(truth, "double"));
  test::write_file_bytes(dir / "far.obj", obj_text(truth));
  for (const char* name : {"far.ply", "far.obj"}) {
    ReadOptions options;
    options.memory_budget = 1200;  // 100 of the 441 vertices: the faces are dereferenced on disk
    auto stream = open_triangle_stream(dir / name, options);
    ASSERT_TRUE(dereferenced_out_of_core(*stream)) << name;
    EXPECT_EQ(stream->vertices().origin, truth.points[0]) << name;
    const IndexedMesh welded = read_mesh(*stream);
    EXPECT_EQ(welded.origin, truth.points[0]) << name;
    EXPECT_EQ(welded.triangles.size(), truth.triangles.size()) << name;
  }
  IndexedMesh mesh = read_mesh(dir / "far.ply");
  const auto soup = make_mesh_stream(mesh, /*as_soup=*/true);
  EXPECT_EQ(soup->vertices().origin, truth.points[0]);
  EXPECT_EQ(make_mesh_stream(mesh)->vertices().origin, truth.points[0]);
}

}  // namespace
}  // namespace ocsimp
