#include "ocsimp/core/mesh.h"

#include <algorithm>
#include <limits>
#include <numeric>
#include <string>

#include "ocsimp/core/error.h"

namespace ocsimp {

Box3 IndexedMesh::bounds() const {
  Box3 box;
  for (const Vec3f& p : positions) box.add(p);
  return box;
}

Vec3d far_origin(std::vector<Vec3d> first) {
  if (first.empty()) return Vec3d::Zero();
  Vec3d median;
  const auto middle = first.begin() + static_cast<std::ptrdiff_t>((first.size() - 1) / 2);
  for (int axis = 0; axis < 3; ++axis) {
    std::nth_element(first.begin(), middle, first.end(),
                     [axis](const Vec3d& a, const Vec3d& b) { return a[axis] < b[axis]; });
    median[axis] = (*middle)[axis];
  }
  const double largest = median.cwiseAbs().maxCoeff();
  // Past float's range the readers refuse a vertex; an origin there would hide it.
  return largest > kFarFromOrigin && largest <= std::numeric_limits<float>::max() ? median : Vec3d::Zero();
}

void check_indices(const IndexedMesh& mesh, const std::string& who) {
  const std::size_t n = mesh.positions.size();
  auto check_size = [&](std::size_t size, const char* what) {
    if (size != 0 && size != n) {
      throw Error(who + what + " has " + std::to_string(size) + " entries for " + std::to_string(n) +
                  " vertices");
    }
  };
  check_size(mesh.normals.size(), "the normal array");
  check_size(mesh.colors.size(), "the color array");
  check_size(mesh.uvs.size(), "the uv array");
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (Index v : mesh.triangles[f]) {
      if (v >= n) {
        throw Error(who + "face " + std::to_string(f) + " uses vertex " + std::to_string(v) +
                    " but the mesh has " + std::to_string(n) + " vertices");
      }
    }
  }
}

std::vector<Quadric> face_quadrics_per_vertex(const IndexedMesh& mesh) {
  check_indices(mesh, "face quadrics: ");
  std::vector<Quadric> quadrics(mesh.positions.size());
  for (const Triangle& t : mesh.triangles) {
    const Quadric q =
        Quadric::triangle(mesh.positions[t[0]].cast<double>(), mesh.positions[t[1]].cast<double>(),
                          mesh.positions[t[2]].cast<double>());
    for (Index v : t) quadrics[v] += q;
  }
  return quadrics;
}

namespace {

struct DisjointSets {
  std::vector<Index> parent;
  explicit DisjointSets(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), Index{0}); }
  Index find(Index x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  }
  void unite(Index a, Index b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

}  // namespace

MeshTopology analyze_topology(const IndexedMesh& mesh) {
  check_indices(mesh, "topology: ");
  MeshTopology topo;
  const std::size_t n = mesh.positions.size();

  // Directed half-edges sorted by their undirected key; runs of equal keys are one edge.
  struct HalfEdge {
    Index lo, hi;
    bool forward;  // lo -> hi
    Index face;
  };
  std::vector<HalfEdge> half_edges;
  half_edges.reserve(mesh.triangles.size() * 3);
  std::vector<std::array<Index, 3>> sorted_faces;
  sorted_faces.reserve(mesh.triangles.size());
  std::vector<bool> used(n, false);
  DisjointSets sets(n);
  for (Index f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    if (has_repeated_corner(t)) {
      ++topo.degenerate_faces;
      continue;
    }
    std::array<Index, 3> s = t;
    std::sort(s.begin(), s.end());
    sorted_faces.push_back(s);
    for (int k = 0; k < 3; ++k) {
      const Index a = t[k], b = t[(k + 1) % 3];
      half_edges.push_back({std::min(a, b), std::max(a, b), a < b, f});
      used[a] = true;
      sets.unite(a, b);
    }
  }
  std::sort(sorted_faces.begin(), sorted_faces.end());
  for (std::size_t i = 1; i < sorted_faces.size(); ++i) {
    if (sorted_faces[i] == sorted_faces[i - 1]) ++topo.duplicate_faces;
  }
  std::sort(half_edges.begin(), half_edges.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.lo != y.lo ? x.lo < y.lo : x.hi != y.hi ? x.hi < y.hi : x.face < y.face;
  });

  // Per-vertex fan counting: a vertex is manifold when its incident faces, linked through shared manifold
  // edges, form one fan. Count face-groups per vertex with a union-find over (vertex, face) incidences.
  std::vector<std::size_t> first_incidence(n + 1, 0);
  for (const Triangle& t : mesh.triangles) {
    if (has_repeated_corner(t)) continue;
    for (Index v : t) ++first_incidence[v + 1];
  }
  std::partial_sum(first_incidence.begin(), first_incidence.end(), first_incidence.begin());
  std::vector<Index> incident_faces(first_incidence[n]);
  {
    std::vector<std::size_t> cursor(first_incidence.begin(), first_incidence.end() - 1);
    for (Index f = 0; f < mesh.triangles.size(); ++f) {
      const Triangle& t = mesh.triangles[f];
      if (has_repeated_corner(t)) continue;
      for (Index v : t) incident_faces[cursor[v]++] = f;
    }
  }
  DisjointSets fans(incident_faces.size());
  auto slot = [&](Index v, Index f) {
    const auto begin = incident_faces.begin() + static_cast<std::ptrdiff_t>(first_incidence[v]);
    const auto end = incident_faces.begin() + static_cast<std::ptrdiff_t>(first_incidence[v + 1]);
    return static_cast<Index>(std::lower_bound(begin, end, f) - incident_faces.begin());
  };

  for (std::size_t i = 0; i < half_edges.size();) {
    std::size_t j = i;
    while (j < half_edges.size() && half_edges[j].lo == half_edges[i].lo &&
           half_edges[j].hi == half_edges[i].hi) {
      ++j;
    }
    const std::size_t count = j - i;
    ++topo.edges;
    if (count == 1) ++topo.boundary_edges;
    if (count >= 3) ++topo.non_manifold_edges;
    if (count == 2) {
      if (half_edges[i].forward == half_edges[i + 1].forward) ++topo.inconsistent_edges;
      const Index f0 = half_edges[i].face, f1 = half_edges[i + 1].face;
      for (Index v : {half_edges[i].lo, half_edges[i].hi}) fans.unite(slot(v, f0), slot(v, f1));
    }
    i = j;
  }

  std::vector<bool> root_seen(n, false);
  for (Index v = 0; v < n; ++v) {
    if (!used[v]) {
      ++topo.unreferenced_vertices;
      continue;
    }
    const Index root = sets.find(v);
    if (!root_seen[root]) {
      root_seen[root] = true;
      ++topo.components;
    }
    std::size_t groups = 0;
    for (std::size_t k = first_incidence[v]; k < first_incidence[v + 1]; ++k) {
      if (fans.find(static_cast<Index>(k)) == k) ++groups;
    }
    if (groups > 1) ++topo.non_manifold_vertices;
  }
  return topo;
}

}  // namespace ocsimp
