// Coordinates far from zero (IndexedMesh::origin): files that hold them more precisely than floats are read
// relative to a point of their own (the median of their first vertices), and the writers put the origin back,
// so a georeferenced scan keeps detail that floats at its coordinates could not hold (float spacing is 0.25
// at 4e6).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
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

// Decimal text that reads back as exactly `value` (17 significant digits).
std::string decimal(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

std::string obj_text(const TrueMesh& mesh) {
  std::string out;
  for (const Vec3d& p : mesh.points)
    out += "v " + decimal(p.x()) + " " + decimal(p.y()) + " " + decimal(p.z()) + "\n";
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

// The origin lies among the vertices: within the tile, whose corner is `at`.
void expect_origin_in_tile(const IndexedMesh& mesh, const Vec3d& at) {
  const Vec3d from_corner = mesh.origin - at;
  EXPECT_TRUE(from_corner.x() >= 0 && from_corner.x() <= 0.5 && from_corner.y() >= 0 &&
              from_corner.y() <= 0.5 && std::abs(from_corner.z()) <= 0.001)
      << from_corner.transpose();
}

TEST(Origin, DoublePlyFarFromZeroIsReadRelativeToAPointOfItsOwn) {
  TempDir dir;
  const TrueMesh truth = bumpy_tile(kFar);
  test::write_file_bytes(dir / "far.ply", binary_ply(truth, "double"));
  const IndexedMesh mesh = read_mesh(dir / "far.ply");
  expect_origin_in_tile(mesh, kFar);
  // Positions within 0.5 of the origin: float spacing there is 3e-8, where at 4e6 it would be 0.25.
  EXPECT_LT(largest_error(mesh, truth), 1e-7);
  EXPECT_EQ(mesh.triangles, truth.triangles);
}

// A stray first vertex (a georeference marker, an outlier) does not choose the origin: the median of the
// first vertices does, so the rest keep their precision, and near zero they read exactly as floats.
TEST(Origin, AStrayFirstVertexDoesNotChooseIt) {
  TempDir dir;
  for (const Vec3d& tile_at : {kFar, Vec3d(0.25, 0.5, 0)}) {
    for (const Vec3d& stray : {Vec3d(1e30, 0, 0), Vec3d(-3e5, 7e6, 10), Vec3d(0, 0, 0)}) {
      TrueMesh truth = bumpy_tile(tile_at);
      truth.points.insert(truth.points.begin(), stray);  // unreferenced
      for (Triangle& t : truth.triangles) {
        for (Index& v : t) ++v;
      }
      test::write_file_bytes(dir / "stray.ply", binary_ply(truth, "double"));
      test::write_file_bytes(dir / "stray.obj", obj_text(truth));
      for (const char* name : {"stray.ply", "stray.obj"}) {
        SCOPED_TRACE(std::string(name) + " stray at " + std::to_string(stray.x()));
        const IndexedMesh mesh = read_mesh(dir / name);
        if (tile_at == kFar) {
          expect_origin_in_tile(mesh, kFar);
        } else {
          EXPECT_EQ(mesh.origin, Vec3d::Zero());
        }
        double worst = 0;
        for (std::size_t i = 1; i < truth.points.size(); ++i) {
          const Vec3d at = mesh.origin + mesh.positions[i].cast<double>();
          worst = std::max(worst, (at - truth.points[i]).norm());
          if (tile_at != kFar) {
            // Each number rounded once, straight to float: from the double (PLY) or from the text (OBJ).
            Vec3f expected = truth.points[i].cast<float>();
            if (std::string(name) == "stray.obj") {
              for (int k = 0; k < 3; ++k)
                expected[k] = std::strtof(decimal(truth.points[i][k]).c_str(), nullptr);
            }
            EXPECT_EQ(mesh.positions[i], expected) << i;
          }
        }
        EXPECT_LT(worst, 1e-7);
      }
    }
  }
}

// Floats at +-3e38 are each in range, but not 6e38 apart: the one that cannot be held relative to the origin
// is named with its byte offset.
TEST(Origin, AVertexBeyondFloatRangeFromTheOriginIsAnError) {
  TempDir dir;
  TrueMesh mesh;
  mesh.points = {{3e38, 0, 0}, {-3e38, 0, 0}, {3e38, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  const std::string bytes = binary_ply(mesh, "double");
  test::write_file_bytes(dir / "wide.ply", bytes);
  try {
    read_mesh(dir / "wide.ply");
    ADD_FAILURE() << "read";
  } catch (const Error& e) {
    const std::size_t vertex_1 = bytes.find("end_header\n") + 11 + 24;  // after one x y z of doubles
    EXPECT_EQ(e.position().value, vertex_1);
    EXPECT_NE(std::string(e.what()).find("vertex 1 lies beyond the float range"), std::string::npos)
        << e.what();
  }
}

// Held for the origin's sample, such a vertex is still the error reported when a later one is bad too.
TEST(Origin, TheFirstBadVertexInTheFileIsTheOneReported) {
  TempDir dir;
  TrueMesh mesh;
  for (int i = 0; i < 20; ++i) mesh.points.emplace_back(3e38, i % 7, i % 5);
  mesh.points[5] = {-3e38, 0, 0};
  mesh.points[12] = {std::nan(""), 0, 0};
  mesh.triangles = {{0, 1, 2}};
  const std::string bytes = binary_ply(mesh, "double");
  test::write_file_bytes(dir / "bad.ply", bytes);
  test::write_file_bytes(dir / "bad.obj", obj_text(mesh));
  for (const char* name : {"bad.ply", "bad.obj"}) {
    try {
      read_mesh(dir / name);
      ADD_FAILURE() << name << " read";
    } catch (const Error& e) {
      const bool ply = std::string(name) == "bad.ply";
      EXPECT_EQ(e.position().value, ply ? bytes.find("end_header\n") + 11 + 5 * 24 : 6) << name;
      EXPECT_NE(std::string(e.what()).find(ply ? "vertex 5 lies beyond" : "vertex 6 lies beyond"),
                std::string::npos)
          << e.what();
    }
  }
}

TEST(Origin, IntegerCoordinatesFarFromZeroToo) {
  TempDir dir;
  TrueMesh truth = bumpy_tile(Vec3d::Zero());
  for (Vec3d& p : truth.points)
    p = Vec3d(123'456'789, 987'654'321, 0) + (1000.0 * p).array().round().matrix();
  test::write_file_bytes(dir / "int.ply", binary_ply(truth, "int"));
  const IndexedMesh mesh = read_mesh(dir / "int.ply");
  EXPECT_NE(mesh.origin, Vec3d::Zero());
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
  expect_origin_in_tile(mesh, kFar);
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
  // A non-finite origin went into every coordinate, and the readers refused the file written.
  IndexedMesh lost = test::grid_square(2);
  lost.origin.x() = std::numeric_limits<double>::quiet_NaN();
  for (const char* name : {"nan.ply", "nan.obj", "nan.stl"}) {
    EXPECT_THROW(write_mesh(dir / name, lost), Error) << name;
    EXPECT_FALSE(std::filesystem::exists(dir / name)) << name;
  }
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
    const Vec3d origin = stream->vertices().origin;
    EXPECT_EQ(origin, read_mesh(dir / name).origin) << name;  // as read in memory
    const IndexedMesh welded = read_mesh(*stream);
    EXPECT_EQ(welded.origin, origin) << name;
    EXPECT_EQ(welded.triangles.size(), truth.triangles.size()) << name;
    // Welded from the corners: every vertex is a true one, to float precision around the origin.
    for (const Vec3f& p : welded.positions) {
      double nearest = 1e300;
      for (const Vec3d& q : truth.points) nearest = std::min(nearest, (origin + p.cast<double>() - q).norm());
      EXPECT_LT(nearest, 1e-7) << name;
    }
  }
  IndexedMesh mesh = read_mesh(dir / "far.ply");
  const auto soup = make_mesh_stream(mesh, /*as_soup=*/true);
  EXPECT_EQ(soup->vertices().origin, mesh.origin);
  EXPECT_EQ(make_mesh_stream(mesh)->vertices().origin, mesh.origin);
}

}  // namespace
}  // namespace ocsimp
