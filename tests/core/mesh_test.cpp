#include "ocsimp/core/mesh.h"

#include <gtest/gtest.h>

#include "ocsimp/core/error.h"
#include "test_support.h"

namespace ocsimp {
namespace {

TEST(MeshTopology, ClosedSphereIsOneManifoldComponent) {
  const IndexedMesh mesh = test::sphere(3);
  const MeshTopology t = analyze_topology(mesh);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.non_manifold_edges, 0u);
  EXPECT_EQ(t.non_manifold_vertices, 0u);
  EXPECT_EQ(t.inconsistent_edges, 0u);
  // Euler: V - E + F = 2.
  EXPECT_EQ(static_cast<long>(mesh.vertex_count()) - static_cast<long>(t.edges) +
                static_cast<long>(mesh.face_count()),
            2);
}

TEST(MeshTopology, SquareHasABoundaryLoop) {
  const MeshTopology t = analyze_topology(test::grid_square(4));
  EXPECT_EQ(t.boundary_edges, 16u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.non_manifold_vertices, 0u);
}

TEST(MeshTopology, CountsDefects) {
  IndexedMesh mesh = test::grid_square(1);  // 4 vertices, 2 triangles
  mesh.positions.emplace_back(5, 5, 5);     // unreferenced
  mesh.positions.emplace_back(6, 5, 5);
  mesh.triangles.push_back({0, 0, 1});  // degenerate
  mesh.triangles.push_back({3, 1, 0});  // duplicate corner set of face 0, reversed
  const MeshTopology t = analyze_topology(mesh);
  EXPECT_EQ(t.degenerate_faces, 1u);
  EXPECT_EQ(t.duplicate_faces, 1u);
  EXPECT_EQ(t.unreferenced_vertices, 2u);
  EXPECT_GE(t.non_manifold_edges + t.inconsistent_edges, 1u);
}

TEST(MeshTopology, BowtieVertexIsNonManifold) {
  IndexedMesh mesh;
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
  mesh.triangles = {{0, 1, 2}, {0, 3, 4}};
  const MeshTopology t = analyze_topology(mesh);
  EXPECT_EQ(t.non_manifold_vertices, 1u);
  EXPECT_EQ(t.components, 1u);
}

TEST(Mesh, CubeHelperIsClosedAndOutward) {
  const IndexedMesh mesh = test::cube(3);
  const MeshTopology t = analyze_topology(mesh);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.inconsistent_edges, 0u);
  EXPECT_EQ(mesh.vertex_count(), 8u + 12u * 2u + 6u * 4u);
  // Outward: the signed volume is +1.
  double volume = 0;
  for (const Triangle& f : mesh.triangles) {
    volume += mesh.positions[f[0]].cast<double>().dot(
                  mesh.positions[f[1]].cast<double>().cross(mesh.positions[f[2]].cast<double>())) /
              6.0;
  }
  EXPECT_NEAR(volume, 1.0, 1e-6);
}

// Code that indexes a mesh's arrays by its faces checks them first: a corner past the vertex array or a
// short attribute array read out of bounds (a segmentation fault from a corner of 0x7fffffff).
TEST(Mesh, IndicesPastTheArraysAreAnError) {
  IndexedMesh far_corner = test::grid_square(2);
  far_corner.triangles.push_back({0, 1, 0x7fffffff});
  IndexedMesh short_normals = test::grid_square(2);
  short_normals.normals.assign(3, Vec3f(0, 0, 1));
  for (const IndexedMesh* bad : {&far_corner, &short_normals}) {
    EXPECT_THROW(check_indices(*bad, "test: "), Error);
    EXPECT_THROW(face_quadrics_per_vertex(*bad), Error);
    EXPECT_THROW(analyze_topology(*bad), Error);
  }
  try {
    check_indices(far_corner, "test: ");
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), "test: face 8 uses vertex 2147483647 but the mesh has 9 vertices");
  }
  EXPECT_NO_THROW(check_indices(test::grid_square(2), "test: "));
}

TEST(Mesh, FaceQuadricsVanishOnTheSurface) {
  const IndexedMesh mesh = test::sphere(2);
  const std::vector<Quadric> q = face_quadrics_per_vertex(mesh);
  ASSERT_EQ(q.size(), mesh.vertex_count());
  for (std::size_t v = 0; v < q.size(); ++v)
    EXPECT_NEAR(q[v].evaluate(mesh.positions[v].cast<double>()), 0.0, 1e-9);
}

}  // namespace
}  // namespace ocsimp
