// Helpers for the format tests. Meshes that went through a file may come back reordered (STL welding,
// Draco's traversal) and moved a little (quantization), so they are matched vertex to vertex by position.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include <filesystem>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp::test {

// For each vertex of `got`, the nearest vertex of `want`; fails the test unless every distance is at most
// `tolerance` and no two vertices of `got` pick the same one. Brute force: test meshes are small.
inline std::vector<Index> match_vertices(const IndexedMesh& want, const IndexedMesh& got, double tolerance,
                                         double* max_distance = nullptr) {
  std::vector<Index> map(got.positions.size(), std::numeric_limits<Index>::max());
  std::vector<bool> taken(want.positions.size(), false);
  double worst = 0;
  for (std::size_t i = 0; i < got.positions.size(); ++i) {
    double best = std::numeric_limits<double>::infinity();
    Index best_j = 0;
    for (std::size_t j = 0; j < want.positions.size(); ++j) {
      const double d = (got.positions[i].cast<double>() - want.positions[j].cast<double>()).norm();
      if (d < best) {
        best = d;
        best_j = static_cast<Index>(j);
      }
    }
    worst = std::max(worst, best);
    EXPECT_LE(best, tolerance) << "vertex " << i << " is " << best << " from the nearest original vertex";
    EXPECT_FALSE(taken[best_j]) << "two vertices match original vertex " << best_j;
    taken[best_j] = true;
    map[i] = best_j;
  }
  if (max_distance) *max_distance = worst;
  return map;
}

// A triangle rotated so its smallest index comes first: same orientation, one spelling.
inline Triangle canonical(Triangle t) {
  const auto first = std::min_element(t.begin(), t.end()) - t.begin();
  std::rotate(t.begin(), t.begin() + first, t.end());
  return t;
}

// Expects `got`'s faces, through `map` (got vertex -> want vertex), to be exactly `want`'s faces with the
// same orientation (as a multiset; order may differ).
inline void expect_same_faces(const IndexedMesh& want, const IndexedMesh& got,
                              const std::vector<Index>& map) {
  ASSERT_EQ(got.triangles.size(), want.triangles.size());
  std::vector<Triangle> a, b;
  for (const Triangle& t : want.triangles) a.push_back(canonical(t));
  for (const Triangle& t : got.triangles) b.push_back(canonical({map[t[0]], map[t[1]], map[t[2]]}));
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  EXPECT_TRUE(a == b) << "faces differ after matching vertices";
}

inline std::string read_file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

inline void write_file_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// A sphere with every attribute: outward normals, a longitude/latitude uv and a color from the position.
inline IndexedMesh attributed_sphere(int subdivisions) {
  IndexedMesh mesh = sphere(subdivisions);
  for (const Vec3f& p : mesh.positions) {
    mesh.normals.push_back(p.normalized());
    mesh.uvs.emplace_back(0.5f + std::atan2(p.y(), p.x()) / 6.2831853f,
                          0.5f + std::asin(std::clamp(p.z(), -1.0f, 1.0f)) / 3.1415927f);
    auto channel = [](float x) { return static_cast<std::uint8_t>(std::lround((x + 1.0f) * 127.5f)); };
    mesh.colors.push_back({channel(p.x()), channel(p.y()), channel(p.z()), 255});
  }
  return mesh;
}

// One file of tests/data/malformed/<format>/ and what reading it must report.
struct MalformedCase {
  const char* file;
  FilePosition::Kind kind;  // byte or line
  std::uint64_t where;
  const char* reason;  // a fragment of the reason
};

inline std::string malformed_path(const std::string& format, const std::string& file) {
  return std::string(OCSIMP_TEST_DATA) + "/malformed/" + format + "/" + file;
}

// read_mesh() must throw one Error naming the file, the expected place and the reason.
inline void expect_malformed(const std::string& format, const MalformedCase& c) {
  const std::string path = malformed_path(format, c.file);
  ASSERT_TRUE(std::filesystem::exists(path)) << path;
  try {
    read_mesh(path);
    ADD_FAILURE() << path << " was read without error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.file(), path);
    EXPECT_EQ(what.rfind(path, 0), 0u) << what;
    EXPECT_EQ(e.position().kind, c.kind) << what;
    EXPECT_EQ(e.position().value, c.where) << what;
    EXPECT_NE(e.reason().find(c.reason), std::string::npos) << "expected '" << c.reason << "' in: " << what;
  }
}

// Every file of the malformed folder must have a case, so that a file added without one fails.
inline void expect_all_covered(const std::string& format, const std::vector<MalformedCase>& cases) {
  std::set<std::string> listed;
  for (const MalformedCase& c : cases) listed.insert(c.file);
  std::size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(malformed_path(format, ""))) {
    ++files;
    EXPECT_TRUE(listed.count(entry.path().filename().string())) << entry.path() << " has no test case";
  }
  EXPECT_EQ(files, cases.size());
}

inline std::string case_name(const ::testing::TestParamInfo<MalformedCase>& info) {
  std::string name = std::filesystem::path(info.param.file).stem().string();
  for (char& ch : name)
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  return name;
}

}  // namespace ocsimp::test
