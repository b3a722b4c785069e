#include "ocsimp/tools/generate.h"

#include <gtest/gtest.h>

#include <tbb/global_control.h>
#include <cmath>
#include <filesystem>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

GenerateOptions small(std::uint64_t triangles, std::uint64_t seed = 7) {
  GenerateOptions options;
  options.triangles = triangles;
  options.seed = seed;
  return options;
}

TEST(Generate, ClosedManifoldWithPredictedCounts) {
  const IndexedMesh mesh = generate_scan_mesh(small(50'000));
  const GeneratedCounts counts = generated_counts(small(50'000));
  EXPECT_EQ(counts.faces, 12 * counts.lattice * counts.lattice);
  EXPECT_EQ(counts.vertices, 6 * counts.lattice * counts.lattice + 2);
  EXPECT_EQ(mesh.face_count(), counts.faces);
  EXPECT_EQ(mesh.vertex_count(), counts.vertices);
  EXPECT_NEAR(static_cast<double>(counts.faces), 50'000.0, 0.05 * 50'000);
  const MeshTopology topo = analyze_topology(mesh);
  EXPECT_EQ(topo.boundary_edges, 0u);
  EXPECT_EQ(topo.non_manifold_edges, 0u);
  EXPECT_EQ(topo.non_manifold_vertices, 0u);
  EXPECT_EQ(topo.inconsistent_edges, 0u);
  EXPECT_EQ(topo.components, 1u);
  EXPECT_EQ(topo.degenerate_faces, 0u);
  EXPECT_EQ(topo.unreferenced_vertices, 0u);
}

TEST(Generate, FacesPointOutward) {
  const IndexedMesh mesh = generate_scan_mesh(small(20'000));
  double volume = 0;
  for (const Triangle& f : mesh.triangles) {
    const Vec3d a = mesh.positions[f[0]].cast<double>(), b = mesh.positions[f[1]].cast<double>(),
                c = mesh.positions[f[2]].cast<double>();
    volume += a.dot(b.cross(c)) / 6.0;
  }
  // A displaced unit sphere: volume near 4/3 pi, positive when faces point outward.
  EXPECT_GT(volume, 2.5);
  EXPECT_LT(volume, 6.0);
}

TEST(Generate, SameSeedSameMeshAnyThreadCount) {
  GenerateOptions one = small(30'000, 11);
  one.threads = 1;
  GenerateOptions two = one;
  two.threads = 2;
  const IndexedMesh a = generate_scan_mesh(one), b = generate_scan_mesh(two);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.triangles, b.triangles);
  const IndexedMesh c = generate_scan_mesh(small(30'000, 12));
  EXPECT_NE(a.positions, c.positions);
}

// The streaming generator writes PLY bytes: under another name every reader took them for that format and
// refused them.
TEST(Generate, StreamsOnlyToAPlyName) {
  test::TempDir dir;
  for (const char* name : {"scan.obj", "scan.stl", "scan.drc", "scan"}) {
    EXPECT_THROW(generate_scan_ply(dir / name, small(2'000, 1)), Error) << name;
    EXPECT_FALSE(std::filesystem::exists(dir / name)) << name;
  }
  const GeneratedCounts written = generate_scan_ply(dir / "scan.PLY", small(2'000, 1));
  EXPECT_EQ(written.faces, read_mesh(dir / "scan.PLY").face_count());
}

TEST(Generate, HolesOpenBordersAndKeepTheMeshClean) {
  GenerateOptions options = small(40'000);
  options.holes = 6;
  const IndexedMesh mesh = generate_scan_mesh(options);
  const GeneratedCounts counts = generated_counts(options);
  EXPECT_EQ(mesh.face_count(), counts.faces);
  EXPECT_EQ(mesh.vertex_count(), counts.vertices);
  EXPECT_LT(counts.faces, 12 * counts.lattice * counts.lattice);
  const MeshTopology topo = analyze_topology(mesh);
  EXPECT_GT(topo.boundary_edges, 0u);
  EXPECT_EQ(topo.non_manifold_edges, 0u);
  EXPECT_EQ(topo.non_manifold_vertices, 0u);
  EXPECT_EQ(topo.unreferenced_vertices, 0u);
  EXPECT_EQ(topo.components, 1u);
  // Each hole leaves one boundary loop: V - E + F = 2 - holes for a sphere with that many holes.
  EXPECT_EQ(static_cast<long>(mesh.vertex_count()) - static_cast<long>(topo.edges) +
                static_cast<long>(mesh.face_count()),
            2 - 6);
}

TEST(Generate, SeveralComponents) {
  GenerateOptions options = small(30'000);
  options.components = 3;
  options.holes = 2;
  const IndexedMesh mesh = generate_scan_mesh(options);
  const MeshTopology topo = analyze_topology(mesh);
  EXPECT_EQ(topo.components, 3u);
  EXPECT_EQ(topo.non_manifold_edges, 0u);
  EXPECT_EQ(topo.unreferenced_vertices, 0u);
}

TEST(Generate, AttributesWhenAsked) {
  GenerateOptions options = small(5'000);
  options.normals = true;
  options.colors = true;
  const IndexedMesh mesh = generate_scan_mesh(options);
  ASSERT_EQ(mesh.normals.size(), mesh.vertex_count());
  ASSERT_EQ(mesh.colors.size(), mesh.vertex_count());
  // Smooth-surface normals point roughly away from the blob's centre.
  std::size_t outward = 0;
  for (std::size_t v = 0; v < mesh.vertex_count(); ++v) {
    EXPECT_NEAR(mesh.normals[v].norm(), 1.0f, 1e-4f);
    if (mesh.normals[v].dot(mesh.positions[v]) > 0) ++outward;
  }
  EXPECT_GT(outward, mesh.vertex_count() * 95 / 100);
}

TEST(Generate, NoiseIsScannerScale) {
  // Noise moves vertices by at most `noise` mean edge lengths along the radius: the surface stays smooth.
  GenerateOptions quiet = small(20'000);
  quiet.noise = 0;
  GenerateOptions noisy = quiet;
  noisy.noise = 0.5;
  const IndexedMesh a = generate_scan_mesh(quiet), b = generate_scan_mesh(noisy);
  const double edge = 0.5 * M_PI / static_cast<double>(generated_counts(quiet).lattice);
  double largest = 0;
  for (std::size_t v = 0; v < a.vertex_count(); ++v)
    largest = std::max(largest, double((a.positions[v] - b.positions[v]).norm()));
  EXPECT_GT(largest, 0.1 * edge);
  EXPECT_LE(largest, 0.5 * edge + 1e-6);
}

// A georeferenced mesh keeps its detail in the file's doubles up to an offset of 1e9 (1.2e-7 apart there);
// beyond, the offset is refused: at 1e15 a blob had 18 distinct x values and hundreds of degenerate faces.
TEST(Generate, OffsetsStayWhereDoublesHoldTheDetail) {
  test::TempDir dir;
  GenerateOptions far = small(200'000);
  far.offset = Vec3d(-kMostOffset, 0.5 * kMostOffset, 3);
  generate_scan_ply(dir / "far.ply", far);
  const IndexedMesh mesh = read_mesh(dir / "far.ply");
  EXPECT_NEAR(mesh.origin.x(), -kMostOffset, 2.0);
  EXPECT_EQ(analyze_topology(mesh).degenerate_faces, 0u);
  std::size_t flat = 0;
  for (const Triangle& t : mesh.triangles) {
    const Vec3f& p = mesh.positions[t[0]];
    flat += (mesh.positions[t[1]] - p).cross(mesh.positions[t[2]] - p).squaredNorm() == 0;
  }
  EXPECT_EQ(flat, 0u);
  for (const double beyond : {1.5 * kMostOffset, -1e15, std::numeric_limits<double>::infinity()}) {
    far.offset = Vec3d(3, beyond, 0);
    EXPECT_THROW(generate_scan_mesh(far), Error) << beyond;
  }
}

}  // namespace
}  // namespace ocsimp
