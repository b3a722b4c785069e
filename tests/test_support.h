// Helpers shared by the tests: where the shared meshes are, temporary folders, small mesh builders.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "ocsimp/core/mesh.h"

namespace ocsimp::test {

// Path of a mesh in ../shared/data, or "" when that folder is absent (callers GTEST_SKIP()).
inline std::string shared_mesh(const std::string& name) {
  const std::filesystem::path path = std::filesystem::path(OCSIMP_SHARED_DATA) / name;
  return std::filesystem::exists(path) ? path.string() : std::string();
}

#define OCSIMP_REQUIRE_SHARED_MESH(var, name)                \
  const std::string var = ::ocsimp::test::shared_mesh(name); \
  if (var.empty()) GTEST_SKIP() << "../shared/data/" << (name) << " is absent"

// A fresh empty folder under the build tree, removed when the object dies.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path = std::filesystem::path(OCSIMP_BINARY_DIR) / "test-tmp" /
           (std::string(info ? info->test_suite_name() : "suite") + "." + (info ? info->name() : "test"));
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

// A regular grid of (n+1)^2 vertices and 2 n^2 triangles on the unit square in the z = 0 plane, facing +z.
inline IndexedMesh grid_square(int n) {
  IndexedMesh mesh;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) mesh.positions.emplace_back(float(i) / float(n), float(j) / float(n), 0.0f);
  auto id = [n](int i, int j) { return static_cast<Index>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      mesh.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      mesh.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return mesh;
}

// The built `ocsimp` binary run through the shell with `args` (shell-quoted), stdout and stderr captured in
// files under `dir`.
struct CommandResult {
  int exit_code = -1;  // -1 when it did not exit normally (killed by a signal)
  std::string out, err;
};
CommandResult run_ocsimp(const std::string& args, const TempDir& dir);

// A whole file's bytes ("" when it cannot be read).
std::string file_bytes(const std::string& path);

// A closed, outward-facing sphere of radius r: the subdivided octahedron, each level projected to the sphere.
IndexedMesh sphere(int subdivisions, float radius = 1.0f);
// A closed, outward-facing axis-aligned cube [0,1]^3 with each face a grid of n x n quads.
IndexedMesh cube(int n);
// A long thin flat strip [0, 100] x [0, 0.1] in the z = 0 plane, facing +z: 400 x 2 cells of 0.25 x 0.05,
// each split in two (1,600 faces). Every collapse along it leaves a sliver; one cube cell spans its width.
IndexedMesh thin_strip();
// The same faces with every one its own three vertices (and their attributes), as some exporters write a
// mesh.
IndexedMesh triangle_soup(const IndexedMesh& mesh);

}  // namespace ocsimp::test
