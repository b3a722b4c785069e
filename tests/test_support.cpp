#include "test_support.h"

#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <utility>

namespace ocsimp::test {

std::string file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

CommandResult run_ocsimp(const std::string& args, const TempDir& dir) {
  const std::string out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string command =
      std::string(OCSIMP_BINARY_DIR) + "/bin/ocsimp " + args + " >" + out + " 2>" + err;
  const int status = std::system(command.c_str());
  CommandResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = file_bytes(out);
  r.err = file_bytes(err);
  return r;
}

IndexedMesh sphere(int subdivisions, float radius) {
  IndexedMesh mesh;
  mesh.positions = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  mesh.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (int level = 0; level < subdivisions; ++level) {
    std::map<std::pair<Index, Index>, Index> midpoint;
    auto mid = [&](Index a, Index b) {
      const auto key = std::minmax(a, b);
      auto [it, inserted] = midpoint.try_emplace(key, static_cast<Index>(mesh.positions.size()));
      if (inserted) mesh.positions.push_back((mesh.positions[a] + mesh.positions[b]).normalized());
      return it->second;
    };
    std::vector<Triangle> next;
    for (const Triangle& t : mesh.triangles) {
      const Index ab = mid(t[0], t[1]), bc = mid(t[1], t[2]), ca = mid(t[2], t[0]);
      next.push_back({t[0], ab, ca});
      next.push_back({ab, t[1], bc});
      next.push_back({ca, bc, t[2]});
      next.push_back({ab, bc, ca});
    }
    mesh.triangles = std::move(next);
  }
  for (Vec3f& p : mesh.positions) p = p.normalized() * radius;
  return mesh;
}

IndexedMesh triangle_soup(const IndexedMesh& mesh) {
  IndexedMesh soup;
  for (const Triangle& t : mesh.triangles) {
    const Index first = static_cast<Index>(soup.positions.size());
    for (Index v : t) {
      soup.positions.push_back(mesh.positions[v]);
      if (!mesh.normals.empty()) soup.normals.push_back(mesh.normals[v]);
      if (!mesh.colors.empty()) soup.colors.push_back(mesh.colors[v]);
      if (!mesh.uvs.empty()) soup.uvs.push_back(mesh.uvs[v]);
    }
    soup.triangles.push_back({first, first + 1, first + 2});
  }
  return soup;
}

IndexedMesh thin_strip() {
  IndexedMesh strip;
  constexpr int kCells = 400;
  for (int j = 0; j <= 2; ++j)
    for (int i = 0; i <= kCells; ++i) strip.positions.emplace_back(0.25f * float(i), 0.05f * float(j), 0.0f);
  auto id = [](int i, int j) { return static_cast<Index>(j * (kCells + 1) + i); };
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < kCells; ++i) {
      strip.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      strip.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return strip;
}

IndexedMesh cube(int n) {
  IndexedMesh mesh;
  std::map<std::array<int, 3>, Index> index_of;  // integer lattice point -> vertex, so faces share edges
  auto vertex = [&](std::array<int, 3> q) {
    auto [it, inserted] = index_of.try_emplace(q, static_cast<Index>(mesh.positions.size()));
    if (inserted)
      mesh.positions.emplace_back(float(q[0]) / float(n), float(q[1]) / float(n), float(q[2]) / float(n));
    return it->second;
  };
  // For each axis and side, walk the face's (u, v) lattice; orientation chosen so normals point outward.
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          auto corner = [&](int di, int dj) {
            std::array<int, 3> q{};
            q[axis] = side * n;
            q[u] = i + di;
            q[v] = j + dj;
            return vertex(q);
          };
          const Index a = corner(0, 0), b = corner(1, 0), c = corner(1, 1), d = corner(0, 1);
          if (side == 1) {
            mesh.triangles.push_back({a, b, c});
            mesh.triangles.push_back({a, c, d});
          } else {
            mesh.triangles.push_back({a, c, b});
            mesh.triangles.push_back({a, d, c});
          }
        }
    }
  }
  return mesh;
}

}  // namespace ocsimp::test
