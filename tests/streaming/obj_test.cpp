#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include "io_test_util.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

using test::TempDir;

IndexedMesh read_text(const TempDir& dir, const std::string& text, const std::string& name = "m.obj") {
  test::write_file_bytes(dir / name, text);
  return read_mesh(dir / name);
}

// A plain reading of an OBJ of "f v/vt v/vt v/vt" triangles (as spot's): its vt records, and each face
// corner's (v, vt), 0-based.
std::pair<std::vector<Vec2f>, std::vector<std::pair<int, int>>> corner_uvs(const std::string& path) {
  std::istringstream in(test::read_file_bytes(path));
  std::vector<Vec2f> vt;
  std::vector<std::pair<int, int>> corners;
  for (std::string line; std::getline(in, line);) {
    std::istringstream words(line);
    std::string keyword;
    words >> keyword;
    if (keyword == "vt") {
      float u, v;
      words >> u >> v;
      vt.emplace_back(u, v);
    } else if (keyword == "f") {
      for (std::string corner; words >> corner;) {
        const auto slash = corner.find('/');
        corners.emplace_back(std::stoi(corner.substr(0, slash)) - 1, std::stoi(corner.substr(slash + 1)) - 1);
      }
    }
  }
  return {vt, corners};
}

// Reading `text` must fail with one error at line `line` whose reason contains `reason`.
void expect_error_at_line(const TempDir& dir, const std::string& text, std::uint64_t line,
                          const std::string& reason) {
  test::write_file_bytes(dir / "bad.obj", text);
  try {
    read_mesh(dir / "bad.obj");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.position().kind, FilePosition::Kind::line) << e.what();
    EXPECT_EQ(e.position().value, line) << e.what();
    EXPECT_NE(e.reason().find(reason), std::string::npos) << e.what();
  }
}

TEST(Obj, RoundTripKeepsEveryAttributeExactly) {
  TempDir dir;
  const IndexedMesh mesh = test::attributed_sphere(3);
  write_mesh(dir / "s.obj", mesh);
  const IndexedMesh back = read_mesh(dir / "s.obj");
  ASSERT_EQ(back.vertex_count(), mesh.vertex_count());
  EXPECT_EQ(back.triangles, mesh.triangles);
  EXPECT_EQ(back.positions, mesh.positions);  // shortest round-trip text reads back bit for bit
  EXPECT_EQ(back.normals, mesh.normals);
  EXPECT_EQ(back.uvs, mesh.uvs);
  EXPECT_EQ(back.colors, mesh.colors);  // alpha is 255 in the source, and OBJ reads alpha as 255
}

TEST(Obj, RoundTripWithoutAttributesWritesPlainFaces) {
  TempDir dir;
  const IndexedMesh mesh = test::cube(3);
  write_mesh(dir / "c.obj", mesh);
  const std::string text = test::read_file_bytes(dir / "c.obj");
  EXPECT_EQ(text.find('/'), std::string::npos);
  EXPECT_EQ(text.find("vn"), std::string::npos);
  const IndexedMesh back = read_mesh(dir / "c.obj");
  EXPECT_EQ(back.positions, mesh.positions);
  EXPECT_EQ(back.triangles, mesh.triangles);
  EXPECT_FALSE(back.has_normals() || back.has_uvs() || back.has_colors());
}

TEST(Obj, EveryIndexForm) {
  TempDir dir;
  const IndexedMesh m = read_text(dir,
                                  "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
                                  "vt 0.25 0.5\nvt 0.75 0.5 0\n"
                                  "vn 0 0 1\nvn 0 1 0\n"
                                  "f 1 2 3\n"
                                  "f 1/1 3/2 4/1\n"
                                  "f 5//1 6//2 7//1\n"
                                  "f 5/2/2 7/1/1 8/2/2\n");
  ASSERT_EQ(m.vertex_count(), 8u);
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {0, 2, 3}, {4, 5, 6}, {4, 6, 7}}));
  ASSERT_TRUE(m.has_uvs());
  ASSERT_TRUE(m.has_normals());
  // First corner referencing a position gives it its attributes; unreferenced ones stay zero.
  EXPECT_EQ(m.uvs[0], Vec2f(0.25f, 0.5f));
  EXPECT_EQ(m.uvs[2], Vec2f(0.75f, 0.5f));
  EXPECT_EQ(m.uvs[3], Vec2f(0.25f, 0.5f));
  EXPECT_EQ(m.uvs[1], Vec2f::Zero());
  EXPECT_EQ(m.uvs[4], Vec2f(0.75f, 0.5f));
  EXPECT_EQ(m.normals[4], Vec3f(0, 0, 1));
  EXPECT_EQ(m.normals[5], Vec3f(0, 1, 0));
  EXPECT_EQ(m.normals[7], Vec3f(0, 1, 0));
  EXPECT_EQ(m.normals[0], Vec3f::Zero());
}

TEST(Obj, FirstCornerWinsOnSeams) {
  TempDir dir;
  const IndexedMesh m = read_text(dir,
                                  "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 0.5 0.5\n"
                                  "f 1/1 2/2 3/3\nf 1/4 3/4 2/4\n");
  EXPECT_EQ(m.uvs, (std::vector<Vec2f>{{0, 0}, {1, 0}, {0, 1}}));
}

// Four vertices whose corners disagree: vertex 1 on three uvs (two of them equal) and two normals, vertices
// 2 and 3 on two uvs each; vertex 4 agrees.
constexpr const char* kSeamsObj =
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 0.5 0.5\nvt 0 0\n"
    "vt 1 1\nvn 0 0 1\nvn 0 1 0\n"
    "f 1/1/1 2/2/1 3/3/1\nf 1/4/2 3/4/1 2/4/1\nf 2/2/1 4/6/1 3/3/1\nf 1/5/2 2/2/1 4/6/1\n";

// The vertices whose corners disagree are counted once each, by value (two vt records of the same value do
// not make a seam), and told through ReadOptions::warn in one message; a file whose corners agree says
// nothing.
TEST(Obj, SaysHowManyVerticesItsCornersDisagreeOn) {
  TempDir dir;
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  test::write_file_bytes(dir / "seams.obj", kSeamsObj);
  const IndexedMesh m = read_mesh(dir / "seams.obj", options);
  EXPECT_EQ(m.uvs, (std::vector<Vec2f>{{0, 0}, {1, 0}, {0, 1}, {1, 1}}));
  EXPECT_EQ(m.normals[0], Vec3f(0, 0, 1));
  ASSERT_EQ(told.size(), 1u);
  EXPECT_EQ(
      told[0],
      "3 vertices on texture seams (face corners giving different texture coordinates) keep their first "
      "corner's in this command (convert keeps a vertex per side, as decimate, simplify and lod do without "
      "--no-weld); 1 vertex on hard edges (face corners giving different normals) keeps its first corner's "
      "normal");
  told.clear();
  test::write_file_bytes(dir / "agreeing.obj",
                         "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 0 0\n"
                         "f 1/1 2/2 3/3\nf 1/4 3/3 2/2\n");
  EXPECT_EQ(read_mesh(dir / "agreeing.obj", options).uvs, (std::vector<Vec2f>{{0, 0}, {1, 0}, {0, 1}}));
  EXPECT_TRUE(told.empty()) << told[0];
}

// Vertex colors span [0, 1]; a file on a 0..255 scale came out all white without a word. They are still
// clamped, and the reader says how many vertices had a channel outside.
TEST(Obj, SaysHowManyVertexColorsItClamps) {
  TempDir dir;
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  test::write_file_bytes(dir / "c.obj", "v 0 0 0 200 50 25\nv 1 0 0 0 0.5 1\nv 0 1 0 0 0 0\nf 1 2 3\n");
  const IndexedMesh m = read_mesh(dir / "c.obj", options);
  EXPECT_EQ(m.colors, (std::vector<Color>{{255, 255, 255, 255}, {0, 128, 255, 255}, {0, 0, 0, 255}}));
  ASSERT_EQ(told.size(), 1u);
  EXPECT_EQ(told[0],
            "1 vertex has a floating-point color channel outside 0..1, clamped to it (are the colors on a "
            "0..255 scale?)");
}

// An OBJ's materials went missing from every output without a word, as did its polylines and points.
TEST(Obj, SaysWhatItDoesNotRead) {
  TempDir dir;
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  test::write_file_bytes(dir / "m.obj",
                         "mtllib the mats.mtl  # a library\no part\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                         "usemtl red\nf 1 2 3\nusemtl blue\nf 2 4 3\nusemtl red\nl 1 2\np 3\nl 2 3\n");
  const IndexedMesh m = read_mesh(dir / "m.obj", options);
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {1, 3, 2}}));
  ASSERT_EQ(told.size(), 1u);
  EXPECT_EQ(
      told[0],
      "not read, so no output keeps them (ocsimp reads triangles and their vertices' positions, normals, "
      "colors and texture coordinates): material library the mats.mtl; materials red, blue; geometry "
      "other than faces: polylines (l), points (p)");
  // A file that then fails gets its error alone: it is said once every face is read.
  told.clear();
  test::write_file_bytes(dir / "bad.obj", "mtllib the mats.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
  EXPECT_THROW(read_mesh(dir / "bad.obj", options), Error);
  EXPECT_TRUE(told.empty()) << told[0];
  told.clear();
  test::write_file_bytes(dir / "plain.obj", "o part\ng side\ns 1\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  read_mesh(dir / "plain.obj", options);
  EXPECT_TRUE(told.empty()) << told[0];
}

// Where only some faces give vt or vn, the vertices no such corner references get (0, 0) and zero normals,
// which simplification blends into the real ones: the reader says how many. A vertex that some corner gives a
// value is not counted, whichever corner comes first.
TEST(Obj, SaysHowManyVerticesOnlyFacesWithoutAttributesUse) {
  TempDir dir;
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  test::write_file_bytes(dir / "half.obj",
                         "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\nvt 0.5 0.5\nvn 0 0 1\n"
                         "f 2 4 3\nf 1/1/1 2/1/1 3/1/1\nf 2 5 4\n");
  const IndexedMesh m = read_mesh(dir / "half.obj", options);
  EXPECT_EQ(m.uvs, (std::vector<Vec2f>{{0.5f, 0.5f}, {0.5f, 0.5f}, {0.5f, 0.5f}, {0, 0}, {0, 0}}));
  EXPECT_EQ(m.normals[1], Vec3f(0, 0, 1));
  EXPECT_EQ(m.normals[4], Vec3f::Zero());
  ASSERT_EQ(told.size(), 1u);
  EXPECT_EQ(
      told[0],
      "2 vertices are used only by faces without texture coordinates (vt) and get (0, 0); 2 vertices are "
      "used only by faces without normals (vn) and get a zero normal");
  told.clear();
  test::write_file_bytes(dir / "normals_only.obj",
                         "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 2 4 3\n");
  read_mesh(dir / "normals_only.obj", options);
  ASSERT_EQ(told.size(), 1u);
  EXPECT_EQ(told[0], "1 vertex is used only by faces without normals (vn) and gets a zero normal");
}

TEST(Obj, NegativeIndicesCountBackFromTheLine) {
  TempDir dir;
  const IndexedMesh m = read_text(dir,
                                  "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf -3/-1 -2/-1 -1/-1\n"
                                  "v 5 5 5\nvt 1 1\nf -4 -1 -2\n");
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {0, 3, 2}}));
  EXPECT_EQ(m.uvs[3], Vec2f::Zero());
  EXPECT_EQ(m.uvs[0], Vec2f::Zero());
}

TEST(Obj, AByteOrderMarkIsNotPartOfTheFirstLine) {
  // The mark hid the first vertex statement, so every index pointed one vertex too far.
  TempDir dir;
  const IndexedMesh m = read_text(dir, "\xEF\xBB\xBFv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.positions[0], Vec3f(0, 0, 0));
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {0, 1, 3}}));
}

TEST(Obj, PolygonsAreFanTriangulated) {
  TempDir dir;
  const IndexedMesh m =
      read_text(dir, "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf 1 2 3 4 5\nf 1 2 3 4\n");
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 1, 2}, {0, 2, 3}}));
  // A corner repeating the one before it (a triangle written as a quad, the last corner twice) adds no
  // triangle without area; a polygon of fewer than three distinct corners keeps them all.
  const IndexedMesh repeated =
      read_text(dir,
                "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 3\nf 1 1 2 3\nf 4 1 2 4\nf 1 2 2 3 3 4\n"
                "f 1 1 1 1\n");
  EXPECT_EQ(
      repeated.triangles,
      (std::vector<Triangle>{{0, 1, 2}, {0, 1, 2}, {0, 1, 3}, {0, 1, 2}, {0, 2, 3}, {0, 0, 0}, {0, 0, 0}}));
  // Also where the repeat names another texture coordinate, as the commands that decimate read it (one
  // vertex per uv): the copies are one point.
  test::write_file_bytes(dir / "uv.obj",
                         "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt .9 .9\n"
                         "f 1/1 2/2 3/3 3/4\n");
  ReadOptions split;
  split.split_corner_attributes = true;
  EXPECT_EQ(read_mesh(dir / "uv.obj", split).triangles.size(), 1u);
}

// Above 65,536 corners (kMaxClippedCorners) a concave polygon is fanned, as ear clipping could take
// quadratic time; the fan covers ground outside it (a comb of 4,098 corners, 850 times its area), and the
// reader says so, once, with the count. Neither a concave polygon small enough to clip nor a large convex one
// draws the note (a float outline of more corners than that is never quite convex). A comb of 20,002 corners
// is clipped (above 4,096 it was fanned, and decimating such a fan took minutes), to exactly its area.
TEST(Obj, ConcavePolygonsTooLargeToClipAreFannedWithAWarning) {
  // A comb of `teeth` teeth (4 corners each) on a spine (2 more), as one face; or a convex n-gon.
  // snprintf rather than string concatenation, which GCC 12's -Wrestrict misreads.
  auto vertex = [](std::string& text, double x, double y) {
    char line[64];
    std::snprintf(line, sizeof line, "v %.17g %.17g 0\n", x, y);
    text += line;
  };
  auto face = [](std::string& text, std::size_t n) {
    text += "f";
    for (std::size_t i = 1; i <= n; ++i) {
      text += ' ';
      text += std::to_string(i);
    }
    text += '\n';
  };
  auto comb = [&](std::size_t teeth) {
    std::string text;
    for (std::size_t i = 0; i < teeth; ++i) {
      const double x = static_cast<double>(i);
      vertex(text, x, 0), vertex(text, x, 10), vertex(text, x + 0.5, 10), vertex(text, x + 0.5, 0);
    }
    vertex(text, static_cast<double>(teeth), -1), vertex(text, 0, -1);
    face(text, 4 * teeth + 2);
    return text;
  };
  auto round = [&](std::size_t n) {
    std::string text;
    for (std::size_t i = 0; i < n; ++i) {
      const double a = 2 * M_PI * static_cast<double>(i) / static_cast<double>(n);
      vertex(text, std::cos(a), std::sin(a));
    }
    face(text, n);
    return text;
  };
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  TempDir dir;
  for (const auto& [text, fanned] :
       {std::pair{comb(16400), true}, std::pair{comb(5000), false}, std::pair{round(4106), false}}) {
    told.clear();
    test::write_file_bytes(dir / "p.obj", text);
    const IndexedMesh m = read_mesh(dir / "p.obj", options);
    EXPECT_EQ(m.face_count(), m.vertex_count() - 2);
    if (fanned) {
      EXPECT_EQ(told, std::vector<std::string>{
                          "1 concave polygon has more than 65536 corners and was fanned from "
                          "the first corner: some triangles cover ground outside the polygon"});
    } else {
      EXPECT_TRUE(told.empty()) << told[0];
    }
    if (m.vertex_count() == 4 * 5000 + 2) {
      double area = 0;
      for (const Triangle& t : m.triangles) {
        const Vec3d a = m.positions[t[0]].cast<double>();
        area +=
            0.5 * (m.positions[t[1]].cast<double>() - a).cross(m.positions[t[2]].cast<double>() - a).norm();
      }
      // Teeth of 0.5 x 10 on a spine 1 deep, less the half square its last corner cuts off.
      EXPECT_NEAR(area, 6.0 * 5000 - 0.25, 1e-6 * 6.0 * 5000);
    }
  }
}

// A concave polygon's fan covers ground outside it: an L's fan from its inner corner's neighbour reached over
// the notch. Ear clipping keeps every triangle inside the outline, turning as the polygon does.
TEST(Obj, ConcavePolygonsAreCutInsideTheirOutline) {
  using Vec2d = Eigen::Vector2d;
  // Outlines in the plane z = 0: an L, a comb with three notches, and the comb wound the other way.
  const std::vector<std::vector<Vec2d>> outlines = {
      {{2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}, {0, 0}},
      {{0, 0}, {7, 0}, {7, 3}, {6, 3}, {6, 1}, {5, 1}, {5, 3}, {4, 3}, {4, 1}, {3, 1}, {3, 3}, {0, 3}},
      {{0, 3}, {3, 3}, {3, 1}, {4, 1}, {4, 3}, {5, 3}, {5, 1}, {6, 1}, {6, 3}, {7, 3}, {7, 0}, {0, 0}},
  };
  auto signed_area = [](const std::vector<Vec2d>& q) {
    double a = 0;
    for (std::size_t i = 0; i < q.size(); ++i) {
      const Vec2d& p = q[i];
      const Vec2d& r = q[(i + 1) % q.size()];
      a += p.x() * r.y() - r.x() * p.y();
    }
    return a / 2;
  };
  // Even-odd test for a point strictly inside.
  auto inside = [](const std::vector<Vec2d>& q, const Vec2d& p) {
    bool in = false;
    for (std::size_t i = 0, j = q.size() - 1; i < q.size(); j = i++) {
      if ((q[i].y() > p.y()) != (q[j].y() > p.y()) &&
          p.x() < (q[j].x() - q[i].x()) * (p.y() - q[i].y()) / (q[j].y() - q[i].y()) + q[i].x())
        in = !in;
    }
    return in;
  };
  // Each outline also tilted out of its plane, so the cut happens in a plane no axis is normal to.
  const Eigen::Matrix3d tilt = (Eigen::AngleAxisd(0.7, Vec3d(1, 2, 0.5).normalized())).toRotationMatrix();
  for (const auto& outline : outlines) {
    for (bool tilted : {false, true}) {
      std::string text;
      for (const Vec2d& p : outline) {
        const Vec3d q = tilted ? Vec3d(tilt * Vec3d(p.x(), p.y(), 0)) : Vec3d(p.x(), p.y(), 0);
        char line[96];
        std::snprintf(line, sizeof line, "v %.17g %.17g %.17g\n", q.x(), q.y(), q.z());
        text += line;
      }
      text += "f";
      for (std::size_t i = 1; i <= outline.size(); ++i) {
        text += ' ';
        text += std::to_string(i);
      }
      text += '\n';
      TempDir dir;
      const IndexedMesh m = read_text(dir, text);
      ASSERT_EQ(m.face_count(), outline.size() - 2);
      const double area = signed_area(outline);
      double total = 0;
      for (const Triangle& t : m.triangles) {
        // Back in the outline's plane, from the file's corners.
        const std::vector<Vec2d> corners = {outline[t[0]], outline[t[1]], outline[t[2]]};
        const double a = signed_area(corners);
        EXPECT_GT(a * area, 0) << "a triangle turns against its polygon";
        total += a;
        EXPECT_TRUE(inside(outline, (corners[0] + corners[1] + corners[2]) / 3)) << "a triangle outside";
      }
      EXPECT_NEAR(total, area, 1e-9) << "the triangles do not tile the polygon";
    }
  }
  // A polygon that crosses itself has no proper cut; it still gives n - 2 triangles.
  TempDir dir;
  const IndexedMesh bow =
      read_text(dir, "v 0 0 0\nv 2 2 0\nv 2 0 0\nv 0 2 0\nv 1 3 0\nv -1 1 0\nf 1 2 3 4 5 6\n");
  EXPECT_EQ(bow.face_count(), 4u);
}

TEST(Obj, VerticesMayFollowTheFaces) {
  TempDir dir;
  const IndexedMesh m = read_text(dir, "f 1 2 3\nf 3 2 4\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n");
  EXPECT_EQ(m.vertex_count(), 4u);
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {2, 1, 3}}));
  EXPECT_EQ(m.positions[3], Vec3f(1, 1, 0));
}

TEST(Obj, IgnoresStatementsItDoesNotUse) {
  TempDir dir;
  const IndexedMesh m =
      read_text(dir,
                "# comment\r\nmtllib a.mtl\r\no thing\r\ng group one\r\ns 1\r\nusemtl red\r\n"
                "v 0 0 0\r\nv 1 0 0 1.0\r\nv 0 1 0\r\n\r\n   \r\nvp 0.5\r\nl 1 2\r\np 1\r\n"
                "curv 0 1 1 2\r\nfuture_statement whatever 1 2\r\n\tf\t1 2\t3 \r\n");
  EXPECT_EQ(m.vertex_count(), 3u);
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}}));
  EXPECT_EQ(m.positions[1], Vec3f(1, 0, 0));  // w ignored
}

TEST(Obj, LineContinuation) {
  TempDir dir;
  const IndexedMesh m =
      read_text(dir, "# saved to C:\\models\\\nv 0 0 0\nv 1 \\\n 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 \\\n3 \\\n4\n");
  EXPECT_EQ(m.vertex_count(), 4u);  // a comment's trailing '\' does not continue it
  EXPECT_EQ(m.positions[1], Vec3f(1, 0, 0));
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {0, 2, 3}}));
}

// Comments at the end of statements, as some exporters and hand edits leave them, are dropped like comment
// lines; a '\\' inside a comment continues nothing.
TEST(Obj, CommentsAfterStatements) {
  TempDir dir;
  const IndexedMesh m = read_text(dir,
                                  "v 0 0 0 # origin\nv 1 0 0#x\nv 0 1 \\\n 0 # y, continued\nvt 0 1 # uv\n"
                                  "v 1 1 0 # a path C:\\dir\\\nf 1 2 3 # first\nf 2 4 3#\n");
  EXPECT_EQ(m.vertex_count(), 4u);
  EXPECT_EQ(m.positions[1], Vec3f(1, 0, 0));
  EXPECT_EQ(m.positions[2], Vec3f(0, 1, 0));
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {1, 3, 2}}));
}

TEST(Obj, VertexColorsAndLenientNumbers) {
  TempDir dir;
  const IndexedMesh m = read_text(dir, "v 0 0 0\nv +1e0 0 0 1 0 0.5\nv 0 1. .0 1 0 0 1\nf 1 2 3\n");
  ASSERT_TRUE(m.has_colors());
  EXPECT_EQ(m.colors[0], (Color{255, 255, 255, 255}));  // before the first colored vertex: white
  EXPECT_EQ(m.colors[1], (Color{255, 0, 128, 255}));
  EXPECT_EQ(m.colors[2], (Color{0, 0, 255, 255}));  // x y z w r g b
  EXPECT_EQ(m.positions[1], Vec3f(1, 0, 0));
  EXPECT_EQ(m.positions[2], Vec3f(0, 1, 0));
}

TEST(Obj, StreamsBatchesOfBoundedSize) {
  TempDir dir;
  std::string text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv -1 0 -2\nv 0 3 0\n";
  // A convex pentagon (a fan from its first corner, whose triangles all start at vertex 0): 3 triangles each.
  for (int i = 0; i < 10; ++i) text += "f 1 2 3 6 4\n";
  test::write_file_bytes(dir / "p.obj", text);
  ReadOptions options;
  options.batch_capacity = 4;
  auto stream = open_triangle_stream(dir / "p.obj", options);
  ASSERT_TRUE(stream->indexed());
  EXPECT_EQ(stream->vertices().vertex_count(), 6u);
  EXPECT_EQ(stream->triangles_hint(), 10u);
  const Box3 box = stream->bounds();
  EXPECT_EQ(box.lo, Vec3d(-1, 0, -2));
  EXPECT_EQ(box.hi, Vec3d(1, 3, 0));
  TriangleBatch batch;
  std::size_t total = 0, batches = 0;
  while (stream->next(batch)) {
    EXPECT_LE(batch.size(), 4u);
    EXPECT_TRUE(batch.corners.empty());
    for (const Triangle& t : batch.triangles) EXPECT_EQ(t[0], 0u);
    total += batch.size();
    ++batches;
  }
  EXPECT_EQ(total, 30u);
  EXPECT_EQ(batches, 8u);
  EXPECT_EQ(stream->bytes_read(), stream->bytes_total());
}

TEST(Obj, ReportsTheLineOfAFaceError) {
  TempDir dir;
  expect_error_at_line(dir, "v 0 0 0\nv 1 0 0\nv 0 1 0\n# fine so far\nf 1 2 3\nf 1 2 4\n", 6,
                       "vertex index 4 out of range (the file has 3)");
}

// Classic Mac OS ended lines with a CR alone; such a file reads like any other, and errors name the right
// line.
TEST(Obj, CarriageReturnAloneEndsALine) {
  TempDir dir;
  const IndexedMesh m = read_text(dir, "# old Mac\rv 0 0 0\rv 1 0 0\rv 0 1 0\rv 1 1 0\r\rf 1 2 3\rf 2 4 3");
  EXPECT_EQ(m.vertex_count(), 4u);
  EXPECT_EQ(m.positions[3], Vec3f(1, 1, 0));
  EXPECT_EQ(m.triangles, (std::vector<Triangle>{{0, 1, 2}, {1, 3, 2}}));

  // A stray CR in a file of LF lines, and CR CR LF endings, still read line by line at the LFs.
  const IndexedMesh stray =
      read_text(dir, "# made\rby hand\r\r\nv 0 0 0\r\r\nv 1 0 0\nv 0 1 0\r\nf 1 2 3\r\r\n");
  EXPECT_EQ(stray.vertex_count(), 3u);
  EXPECT_EQ(stray.triangles, (std::vector<Triangle>{{0, 1, 2}}));

  expect_error_at_line(dir, "v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\rf 1 2 4\r", 5,
                       "vertex index 4 out of range");
}

TEST(Obj, RejectsALineLongerThanTheBuffer) {
  TempDir dir;
  std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\n# ";
  text.append(5u << 20, 'x');
  text += "\nf 1 2 3\n";
  expect_error_at_line(dir, text, 4, "line longer than");
}

TEST(Obj, WriterRefusesBrokenMeshesAndLeavesNoFile) {
  TempDir dir;
  IndexedMesh mesh = test::cube(1);
  mesh.triangles.push_back({0, 1, 99});
  EXPECT_THROW(write_mesh(dir / "x.obj", mesh), Error);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.obj"));
  mesh = test::cube(1);
  mesh.normals.resize(2);
  EXPECT_THROW(write_mesh(dir / "x.obj", mesh), Error);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path));
}

// Shared meshes: counts from the files' own v and f records; topology facts of the real models.
TEST(ObjShared, StanfordBunnyMatchesThePly) {
  OCSIMP_REQUIRE_SHARED_MESH(obj, "stanford-bunny.obj");
  const IndexedMesh m = read_mesh(obj);
  EXPECT_EQ(m.vertex_count(), 35947u);
  EXPECT_EQ(m.face_count(), 69451u);
  EXPECT_FALSE(m.has_normals() || m.has_uvs() || m.has_colors());
  OCSIMP_REQUIRE_SHARED_MESH(ply, "bunny.ply");
  IndexedMesh p;
  try {
    p = read_mesh(ply);
  } catch (const Error& e) {
    GTEST_SKIP() << "PLY reader not available yet: " << e.what();
  }
  EXPECT_EQ(p.face_count(), m.face_count());
  EXPECT_EQ(p.vertex_count(), m.vertex_count());
  const Box3 a = m.bounds(), b = p.bounds();
  EXPECT_LT((a.lo - b.lo).norm(), 1e-5);
  EXPECT_LT((a.hi - b.hi).norm(), 1e-5);
}

TEST(ObjShared, FandiskIsClosed) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "fandisk.obj");
  const IndexedMesh m = read_mesh(path);
  EXPECT_EQ(m.vertex_count(), 6475u);
  EXPECT_EQ(m.face_count(), 12946u);
  const MeshTopology t = analyze_topology(m);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.non_manifold_edges, 0u);
  EXPECT_EQ(t.components, 1u);
}

TEST(ObjShared, SpotTakesEachPositionsUvFromItsFirstCorner) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "spot.obj");
  const IndexedMesh m = read_mesh(path);
  EXPECT_EQ(m.vertex_count(), 2930u);
  EXPECT_EQ(m.face_count(), 5856u);
  ASSERT_TRUE(m.has_uvs());
  EXPECT_FALSE(m.has_normals());
  // The same rule by a plain independent reading.
  const auto [vt, corners] = corner_uvs(path);
  std::vector<bool> seen(m.vertex_count(), false), seam(m.vertex_count(), false);
  std::size_t checked = 0, seams = 0;
  for (auto [v, t] : corners) {
    if (seen[v]) {
      if (!seam[v] && vt[t] != m.uvs[v]) {
        seam[v] = true;
        ++seams;
      }
      continue;
    }
    seen[v] = true;
    ASSERT_EQ(m.uvs[v], vt[t]) << "vertex " << v;
    ++checked;
  }
  EXPECT_EQ(checked, m.vertex_count());
  // The warning counts the same vertices on seams.
  ASSERT_GT(seams, 0u);
  std::string told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told += message; };
  read_mesh(path, options);
  EXPECT_EQ(told.rfind(std::to_string(seams) + " vertices on texture seams", 0), 0u) << told;
  const MeshTopology topology = analyze_topology(m);
  EXPECT_EQ(topology.boundary_edges, 0u);  // uv seams split attributes, never positions
  EXPECT_EQ(topology.unreferenced_vertices, 0u);
}

// With ReadOptions::split_corner_attributes, a vertex whose corners disagree becomes one vertex per
// distinct texture coordinate and normal, at the same position: every corner then reads exactly what the
// file gives it, and nothing is said.
TEST(Obj, SplitsCornersThatDisagreeOnRequest) {
  TempDir dir;
  std::vector<std::string> told;
  ReadOptions options;
  options.warn = [&](const std::string& message) { told.push_back(message); };
  options.split_corner_attributes = true;
  test::write_file_bytes(dir / "seams.obj", kSeamsObj);
  const IndexedMesh m = read_mesh(dir / "seams.obj", options);
  EXPECT_TRUE(told.empty()) << told[0];
  const std::vector<Vec2f> vt = {{0, 0}, {1, 0}, {0, 1}, {0.5, 0.5}, {0, 0}, {1, 1}};
  const std::vector<Vec3f> vn = {{0, 0, 1}, {0, 1, 0}};
  const std::vector<Vec3f> v = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  // Corners as the file gives them: (v, vt, vn), 0-based.
  const int corners[4][3][3] = {{{0, 0, 0}, {1, 1, 0}, {2, 2, 0}},
                                {{0, 3, 1}, {2, 3, 0}, {1, 3, 0}},
                                {{1, 1, 0}, {3, 5, 0}, {2, 2, 0}},
                                {{0, 4, 1}, {1, 1, 0}, {3, 5, 0}}};
  ASSERT_EQ(m.face_count(), 4u);
  for (int f = 0; f < 4; ++f) {
    for (int k = 0; k < 3; ++k) {
      const Index at = m.triangles[f][k];
      EXPECT_EQ(m.positions[at], v[corners[f][k][0]]) << f << " " << k;
      EXPECT_EQ(m.uvs[at], vt[corners[f][k][1]]) << f << " " << k;
      EXPECT_EQ(m.normals[at], vn[corners[f][k][2]]) << f << " " << k;
    }
  }
  // The file's 4 vertices, then one copy per distinct disagreeing (uv, normal): vertex 1 at uv (0.5, 0.5)
  // with normal (0, 1, 0), vertex 1 at its own uv (0, 0) with normal (0, 1, 0), vertex 2 at (0.5, 0.5) and
  // vertex 3 at (0.5, 0.5).
  EXPECT_EQ(m.vertex_count(), 8u);
}

// The copies a split reading makes (or the decimator writes along a seam) share one `v` line again: the
// file has the input's 4 positions and is closed where it was, while every corner keeps its own uv and
// normal.
TEST(Obj, SeamCopiesShareTheirPositionLine) {
  TempDir dir;
  ReadOptions split;
  split.split_corner_attributes = true;
  test::write_file_bytes(dir / "seams.obj", kSeamsObj);
  const IndexedMesh m = read_mesh(dir / "seams.obj", split);
  ASSERT_EQ(m.vertex_count(), 8u);
  write_mesh(dir / "out.obj", m);
  const std::string text = test::read_file_bytes(dir / "out.obj");
  std::size_t v_lines = 0;
  for (std::size_t at = text.find("\nv "); at != std::string::npos; at = text.find("\nv ", at + 1)) ++v_lines;
  EXPECT_EQ(v_lines, 4u);
  const IndexedMesh plain = read_mesh(dir / "out.obj");
  EXPECT_EQ(plain.vertex_count(), 4u);
  const IndexedMesh back = read_mesh(dir / "out.obj", split);
  ASSERT_EQ(back.face_count(), m.face_count());
  for (std::size_t f = 0; f < m.face_count(); ++f) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(back.positions[back.triangles[f][k]], m.positions[m.triangles[f][k]]) << f << " " << k;
      EXPECT_EQ(back.uvs[back.triangles[f][k]], m.uvs[m.triangles[f][k]]) << f << " " << k;
      EXPECT_EQ(back.normals[back.triangles[f][k]], m.normals[m.triangles[f][k]]) << f << " " << k;
    }
  }
}

// Two vertices at one position with the same uv are not the sides of a seam but a crack in the mesh: the
// writer keeps it, and the copies with another uv join the first of them.
TEST(Obj, CopiesWithEqualAttributesKeepLinesOfTheirOwn) {
  TempDir dir;
  IndexedMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}};
  m.uvs = {{0, 0}, {1, 0}, {0, 1}, {1, 0}, {0, 1}, {1, 1}, {0.5f, 0}};
  m.triangles = {{0, 1, 2}, {3, 5, 4}, {6, 5, 3}};
  write_mesh(dir / "crack.obj", m);
  const IndexedMesh plain = read_mesh(dir / "crack.obj");
  // Vertices 3 and 4 repeat 1 and 2 with their uvs: 6 lines; vertex 6 (another uv at 1's position) joins
  // the group of 3, the latest at that position.
  ASSERT_EQ(plain.vertex_count(), 6u);
  EXPECT_EQ(plain.triangles[0], (Triangle{0, 1, 2}));
  EXPECT_EQ(plain.triangles[1], (Triangle{3, 5, 4}));
  EXPECT_EQ(plain.triangles[2][0], 3u);
}

// spot's uv seams, split: every corner reads its own vt, and the copies sit exactly on their vertex, so
// the surface is as closed as before once positions are taken as one.
TEST(ObjShared, SpotSplitGivesEveryCornerItsOwnUv) {
  OCSIMP_REQUIRE_SHARED_MESH(path, "spot.obj");
  ReadOptions options;
  options.split_corner_attributes = true;
  const IndexedMesh m = read_mesh(path, options);
  const IndexedMesh merged = read_mesh(path);
  ASSERT_EQ(m.face_count(), merged.face_count());
  EXPECT_GT(m.vertex_count(), merged.vertex_count());
  const auto [vt, corners] = corner_uvs(path);
  ASSERT_EQ(corners.size(), 3 * m.face_count());
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const Index at = m.triangles[c / 3][c % 3];
    ASSERT_EQ(m.uvs[at], vt[corners[c].second]) << "corner " << c;
    ASSERT_EQ(m.positions[at], merged.positions[merged.triangles[c / 3][c % 3]]) << "corner " << c;
  }
}

TEST(ObjShared, OtherModels) {
  struct Model {
    const char* name;
    std::size_t vertices, faces;
  };
  for (const Model& model : {Model{"teapot.obj", 3644, 6320}, Model{"homer.obj", 6002, 12000},
                             Model{"rocker-arm.obj", 10044, 20088}}) {
    const std::string path = test::shared_mesh(model.name);
    if (path.empty()) continue;
    const IndexedMesh m = read_mesh(path);
    EXPECT_EQ(m.vertex_count(), model.vertices) << model.name;
    EXPECT_EQ(m.face_count(), model.faces) << model.name;
    for (const Triangle& t : m.triangles)
      for (Index v : t) ASSERT_LT(v, m.vertex_count());
  }
}

// One case per file of tests/data/malformed/obj.
const std::vector<test::MalformedCase> kMalformed = {
    {"zero_index.obj", FilePosition::Kind::line, 5, "vertex index 0"},
    {"index_out_of_range.obj", FilePosition::Kind::line, 4, "vertex index 7 out of range (the file has 3)"},
    {"huge_index.obj", FilePosition::Kind::line, 4, "vertex index 99999999999999999999999 out of range"},
    {"relative_before_first.obj", FilePosition::Kind::line, 4, "reaches before the first vertex"},
    {"face_two_corners.obj", FilePosition::Kind::line, 5, "at least 3 corners (found 2)"},
    {"face_no_corners.obj", FilePosition::Kind::line, 4, "at least 3 corners (found 0)"},
    {"non_numeric_vertex.obj", FilePosition::Kind::line, 2, "not a number: 'abc'"},
    {"number_with_suffix.obj", FilePosition::Kind::line, 3, "not a number: '0.5mm'"},
    {"nan_vertex.obj", FilePosition::Kind::line, 3, "NaN or infinite"},
    {"inf_normal.obj", FilePosition::Kind::line, 4, "NaN or infinite"},
    {"overflow_vertex.obj", FilePosition::Kind::line, 1, "beyond the float range"},
    {"vertex_two_coords.obj", FilePosition::Kind::line, 2, "a vertex needs x y z"},
    {"vertex_too_many_numbers.obj", FilePosition::Kind::line, 1, "too many numbers"},
    {"normal_two_coords.obj", FilePosition::Kind::line, 4, "a normal needs x y z"},
    {"texcoord_empty.obj", FilePosition::Kind::line, 4, "a texture coordinate needs u"},
    {"malformed_corner.obj", FilePosition::Kind::line, 4, "malformed face corner '1/1/1/1'"},
    {"corner_letters.obj", FilePosition::Kind::line, 4, "malformed face corner 'a'"},
    {"texcoord_out_of_range.obj", FilePosition::Kind::line, 5, "texture coordinate index 2 out of range"},
    {"normal_index_zero.obj", FilePosition::Kind::line, 5, "normal index 0"},
    {"continued_error.obj", FilePosition::Kind::line, 4, "vertex index 9 out of range"},
    {"text_not_obj.obj", FilePosition::Kind::line, 3,
     "'These' is no OBJ statement, and the file has no vertex"},
};

class ObjMalformed : public ::testing::TestWithParam<test::MalformedCase> {};
TEST_P(ObjMalformed, NamesFileLineAndReason) {
  test::expect_malformed("obj", GetParam());
}
INSTANTIATE_TEST_SUITE_P(Corpus, ObjMalformed, ::testing::ValuesIn(kMalformed), test::case_name);
TEST(ObjMalformedCorpus, EveryFileHasACase) {
  test::expect_all_covered("obj", kMalformed);
}

}  // namespace
}  // namespace ocsimp
