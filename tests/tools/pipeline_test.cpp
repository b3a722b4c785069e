#include "ocsimp/tools/pipeline.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <string_view>
#include <tuple>
#include <vector>

#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/error.h"
#include "ocsimp/decimate/decimate.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/mesh_stream.h"
#include "ocsimp/tools/compare.h"
#include "ocsimp/tools/generate.h"
#include "test_support.h"

namespace ocsimp {
namespace {

// Options that cluster first, to `intermediate` times the face target, whatever the memory.
SimplifyOptions two_stage_to(std::uint64_t faces, double intermediate) {
  SimplifyOptions options;
  options.target_faces = faces;
  options.two_stage = true;
  options.intermediate = intermediate;
  return options;
}

std::string write_scan(const test::TempDir& dir, std::uint64_t triangles, int holes = 0) {
  GenerateOptions options;
  options.triangles = triangles;
  options.seed = 5;
  options.holes = holes;
  const std::string path = dir / "scan.ply";
  generate_scan_ply(path, options);
  return path;
}

TEST(Pipeline, InCoreReachesTheExactCount) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 60'000, 2);  // open borders: any count is reachable
  SimplifyOptions options;
  options.target_faces = 5'001;
  const SimplifyResult result = simplify(path, options);
  EXPECT_FALSE(result.clustered);
  EXPECT_EQ(result.mesh.face_count(), 5'001u);
  EXPECT_TRUE(result.decimate.target_reached);
}

// A limit the in-core decimation would pass, but by less than clustering first: decimated directly, with a
// warning of what it expects to take. A 2 M-triangle scan to 1.5 M faces under a 300 MB limit was clustered,
// at 757 MiB where decimating directly took 297 MiB.
TEST(Pipeline, OverTheLimitEitherWayTheSmallerPathIsTaken) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 200'000);
  SimplifyOptions options;
  options.target_faces = 150'000;
  options.memory_limit = 30u << 20;  // decimating 200 k faces in core is planned at about 33 MB
  std::vector<std::string> warnings;
  options.warn = [&](const std::string& text) { warnings.push_back(text); };
  const SimplifyResult result = simplify(path, options);
  EXPECT_FALSE(result.clustered);
  EXPECT_EQ(result.mesh.face_count(), 150'000u);
  EXPECT_GT(result.memory_needed, options.memory_limit);
  ASSERT_FALSE(warnings.empty());
  EXPECT_NE(warnings[0].find("decimating in core is expected to take about"), std::string::npos)
      << warnings[0];
  EXPECT_NE(warnings[0].find("which clustering first would exceed further"), std::string::npos)
      << warnings[0];
}

TEST(Pipeline, TwoStageReachesTheExactCountAndRecordsPhases) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 60'000, 2);
  SimplifyOptions options;
  options.target_faces = 3'000;
  options.two_stage = true;
  options.intermediate = 4;
  const SimplifyResult result = simplify(path, options);
  EXPECT_TRUE(result.clustered);
  EXPECT_EQ(result.mesh.face_count(), 3'000u);
  EXPECT_GT(result.intermediate_faces, 3'000u);
  EXPECT_LE(result.intermediate_faces, 4u * 3'000u);
  ASSERT_GE(result.phases.size(), 2u);
  EXPECT_EQ(result.phases[result.phases.size() - 2].name, "cluster");
  EXPECT_EQ(result.phases.back().name, "decimate");
  EXPECT_EQ(result.phases.back().triangles_out, 3'000u);
}

TEST(Pipeline, NeverAboveTheTarget) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 30'000);  // closed: faces stay even
  SimplifyOptions options;
  options.target_faces = 2'001;
  options.two_stage = true;
  options.intermediate = 8;
  const SimplifyResult result = simplify(path, options);
  ASSERT_TRUE(result.clustered);
  // The clustered intermediate need not be a closed manifold, so 2,001 may be reachable; above never.
  EXPECT_LE(result.mesh.face_count(), 2'001u);
  EXPECT_GE(result.mesh.face_count(), 2'000u);
}

// A multiple too large for the input asks for all of it; one that is not a number is refused. The product of
// 1e30 and the target once overflowed the face count, and the octree was asked for 4 faces.
TEST(Pipeline, AnIntermediateBeyondTheInputKeepsTheWholeInput) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 5'000, 1);
  SimplifyOptions options;
  options.target_faces = 100;
  options.two_stage = true;
  options.intermediate = 1e30;
  const SimplifyResult result = simplify(path, options);
  ASSERT_TRUE(result.clustered);
  EXPECT_GT(result.intermediate_faces, 1'000u);
  EXPECT_EQ(result.mesh.face_count(), 100u);
  EXPECT_TRUE(result.decimate.target_reached) << result.decimate.reason;

  for (double bad :
       {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN(), 0.5}) {
    options.intermediate = bad;
    EXPECT_THROW(simplify(path, options), Error) << bad;
  }
}

// A file's face count is of polygons: 2,400 quads capped an --intermediate of 4,500 (1.5 times a target of
// 3,000) at 2,400 faces, under the target. The quads and their triangulation now give the same output.
TEST(Pipeline, AnIntermediateCountsTrianglesNotPolygons) {
  test::TempDir dir;
  const int n = 60, m = 40;
  std::string obj;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      const double a = 2 * M_PI * i / n, b = 2 * M_PI * j / m;
      char line[96];
      std::snprintf(line, sizeof line, "v %.9f %.9f %.9f\n", (1 + 0.4 * std::cos(b)) * std::cos(a),
                    (1 + 0.4 * std::cos(b)) * std::sin(a), 0.4 * std::sin(b));
      obj += line;
    }
  }
  auto id = [&](int i, int j) { return std::to_string((i % n) * m + (j % m) + 1); };
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j)
      obj += "f " + id(i, j) + " " + id(i + 1, j) + " " + id(i + 1, j + 1) + " " + id(i, j + 1) + "\n";
  }
  std::ofstream(dir / "quads.obj") << obj;
  write_mesh(dir / "triangles.ply", read_mesh(dir / "quads.obj"));
  SimplifyOptions options;
  options.target_faces = 3000;
  options.two_stage = true;
  options.intermediate = 1.5;
  const SimplifyResult quads = simplify(dir / "quads.obj", options);
  const SimplifyResult triangles = simplify(dir / "triangles.ply", options);
  EXPECT_EQ(quads.intermediate_faces, triangles.intermediate_faces);
  EXPECT_GT(quads.intermediate_faces, 3000u);
  EXPECT_EQ(quads.mesh.face_count(), 3000u) << quads.decimate.reason;
  EXPECT_EQ(quads.mesh.triangles, triangles.mesh.triangles);
  EXPECT_EQ(quads.mesh.positions, triangles.mesh.positions);
}

TEST(Pipeline, AnIntermediateBelowTheTargetIsReportedShort) {
  // A thousand separate triangles: the clustering stage's largest face count not above the target merges
  // whole triangles at once and lands well below it, where the decimator has nothing to do. That used to be
  // reported as the target reached.
  test::TempDir dir;
  IndexedMesh pieces;
  for (Index i = 0; i < 1000; ++i) {
    const float x = static_cast<float>(i % 40), y = static_cast<float>(i / 40);
    pieces.positions.insert(pieces.positions.end(), {{x, y, 0}, {x + 0.3f, y, 0}, {x, y + 0.3f, 0.1f}});
    pieces.triangles.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  const std::string path = dir / "pieces.ply";
  write_mesh(path, pieces);
  const SimplifyResult result = simplify(path, two_stage_to(100, 1));
  ASSERT_TRUE(result.clustered);
  EXPECT_LE(result.mesh.face_count(), 100u);
  EXPECT_EQ(result.decimate.target_reached, result.mesh.face_count() == 100u) << result.decimate.reason;
  if (!result.decimate.target_reached) {
    EXPECT_NE(result.decimate.reason.find("clustering stage"), std::string::npos) << result.decimate.reason;
    // The stage was asked for the final target itself: the reason names the option that set it.
    EXPECT_NE(result.decimate.reason.find("which --intermediate kept at the final target"), std::string::npos)
        << result.decimate.reason;
  }
}

TEST(Pipeline, RatioIsOfTheInputFaces) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 40'000, 1);
  SimplifyOptions options;
  options.target_ratio = 0.05;
  const SimplifyResult in_core = simplify(path, options);
  options.two_stage = true;
  options.intermediate = 4;
  const SimplifyResult two_stage = simplify(path, options);
  ASSERT_TRUE(two_stage.clustered);
  const auto expected =
      static_cast<std::size_t>(std::llround(0.05 * static_cast<double>(in_core.input_faces)));
  EXPECT_EQ(in_core.mesh.face_count(), expected);
  EXPECT_EQ(two_stage.mesh.face_count(), expected);
}

TEST(Pipeline, CarriedQuadricsBeatQuadricsRebuiltFromTheIntermediate) {
  // The point of Garland & Shaffer: the decimator's costs measure distance to the original only if the
  // cluster quadrics come along. Here mean-placed clusters round a cube's edges; quadrics rebuilt from that
  // intermediate take the rounding for the truth, while the carried ones still hold the cube's six planes, so
  // the decimator puts the corners back where they were.
  const IndexedMesh original = test::cube(40);
  ClusterOptions cluster_options;
  cluster_options.grid = 12;
  cluster_options.representative = Representative::mean;
  auto stream = make_mesh_stream(original);
  const QuadricMesh intermediate = cluster(*stream, cluster_options);
  ASSERT_EQ(intermediate.quadrics.size(), intermediate.mesh.vertex_count());

  DecimateOptions decimate_options;
  decimate_options.target_faces = 60;
  const IndexedMesh carried = decimate(intermediate, decimate_options).mesh;
  QuadricMesh rebuilt = intermediate;
  rebuilt.quadrics.clear();
  const IndexedMesh forgotten = decimate(std::move(rebuilt), decimate_options).mesh;

  CompareOptions compare;
  compare.samples = 100'000;
  const SurfaceDistance carried_distance = measure_distance(original, carried, compare);
  const SurfaceDistance forgotten_distance = measure_distance(original, forgotten, compare);
  EXPECT_LT(carried_distance.rms, 0.5 * forgotten_distance.rms);
  EXPECT_LT(carried_distance.hausdorff, forgotten_distance.hausdorff);
  // With the planes carried, the vertices that collapses placed lie on the cube's surface again (a vertex
  // no collapse touched keeps its rounded, mean-placed position).
  std::size_t on_surface = 0;
  for (const Vec3f& p : carried.positions) {
    const float gap = std::min({std::abs(p.x()), std::abs(p.y()), std::abs(p.z()), std::abs(1 - p.x()),
                                std::abs(1 - p.y()), std::abs(1 - p.z())});
    on_surface += gap < 1e-4f;
  }
  EXPECT_GE(on_surface, carried.vertex_count() * 8 / 10);
}

TEST(Pipeline, CarriedBordersHoldWhateverTheIntermediateSize) {
  // The border planes the cluster stage carries must weigh what the decimator's own would, not what one fine
  // cell's crossing weighs: else a finer intermediate carries weaker borders and the holes of an open scan
  // widen as the decimator takes it down (the bunny, through a 100x intermediate: RMS 1.21x pure
  // decimation's).
  OCSIMP_REQUIRE_SHARED_MESH(path, "bunny.ply");
  const IndexedMesh original = read_mesh(path);
  SimplifyOptions options;
  options.target_faces = 700;
  const SimplifyResult pure = simplify(path, options);
  ASSERT_FALSE(pure.clustered);
  CompareOptions compare;
  compare.samples = 200'000;
  const double pure_rms = measure_distance(original, pure.mesh, compare).rms;
  options.two_stage = true;
  for (double multiple : {8.0, 100.0}) {
    options.intermediate = multiple;
    const SimplifyResult two_stage = simplify(path, options);
    ASSERT_TRUE(two_stage.clustered);
    const double rms = measure_distance(original, two_stage.mesh, compare).rms;
    EXPECT_LT(rms, 1.06 * pure_rms) << multiple;
  }
}

TEST(Pipeline, TwoStageDecimatesAnInputNoLargerThanItsIntermediateDirectly) {
  // 20 k faces are below the smallest intermediate (2^18 faces): clustering them would merge nothing, so
  // --two-stage without --intermediate gives exactly what pure decimation gives; with it, it clusters.
  test::TempDir dir;
  const std::string path = write_scan(dir, 20'000, 1);
  SimplifyOptions options;
  options.target_faces = 200;
  const SimplifyResult pure = simplify(path, options);
  options.two_stage = true;
  const SimplifyResult whole = simplify(path, options);
  EXPECT_FALSE(whole.clustered);
  EXPECT_EQ(whole.intermediate_faces, 0u);
  EXPECT_EQ(whole.mesh.triangles, pure.mesh.triangles);
  EXPECT_EQ(whole.mesh.positions, pure.mesh.positions);
  options.intermediate = 8;
  const SimplifyResult clustered = simplify(path, options);
  EXPECT_TRUE(clustered.clustered);
  EXPECT_LE(clustered.intermediate_faces, 8u * 200u);
  EXPECT_EQ(clustered.mesh.face_count(), 200u);
}

TEST(Pipeline, OutOfCoreGivesTheInMemorySoupResult) {
  // A budget far below the vertex array (30k vertices, 360 kB) and a target far below the input force
  // external dereferencing; the cluster stage must then see exactly the triangles it sees when the same mesh
  // is streamed from memory as a soup.
  test::TempDir dir;
  const std::string path = write_scan(dir, 60'000, 2);
  SimplifyOptions options;
  options.target_faces = 100;
  options.intermediate = 4;
  options.memory_limit = 256 << 10;
  const SimplifyResult result = simplify(path, options);
  EXPECT_TRUE(result.out_of_core);
  EXPECT_TRUE(result.clustered);
  EXPECT_EQ(result.mesh.face_count(), 100u);
  // The smallest budget of all is no exception (one byte left the reader unbounded).
  SimplifyOptions tiny = options;
  tiny.memory_limit = 1;
  EXPECT_TRUE(simplify(path, tiny).out_of_core);

  ClusterOptions cluster_options;
  cluster_options.octree = true;
  cluster_options.target_faces = 12'000;
  ReadOptions read;
  read.memory_budget = 48 << 10;
  auto external = open_triangle_stream(path, read);
  ASSERT_TRUE(dereferenced_out_of_core(*external));
  ClusterStats external_stats;
  const QuadricMesh from_disk = cluster(*external, cluster_options, &external_stats);
  auto soup = make_mesh_stream(read_mesh(path), /*as_soup=*/true);
  ClusterStats soup_stats;
  const QuadricMesh from_memory = cluster(*soup, cluster_options, &soup_stats);
  EXPECT_EQ(external_stats.input_triangles, soup_stats.input_triangles);
  EXPECT_EQ(from_disk.mesh.positions, from_memory.mesh.positions);
  EXPECT_EQ(from_disk.mesh.triangles, from_memory.mesh.triangles);
  ASSERT_EQ(from_disk.quadrics.size(), from_memory.quadrics.size());
  for (std::size_t i = 0; i < from_disk.quadrics.size(); ++i) {
    EXPECT_EQ(from_disk.quadrics[i].evaluate(Vec3d(0.1, 0.2, 0.3)),
              from_memory.quadrics[i].evaluate(Vec3d(0.1, 0.2, 0.3)));
  }
}

TEST(Pipeline, OutOfCoreReachesTheTargetDespiteAFarUnusedPoint) {
  // Scans often keep outlier points no face uses. Out of core, the cluster stage sees a triangle soup in the
  // box of every vertex; one point 1,000 diagonals away left its grid a few cells over the surface, and
  // bunny.ply so simplified came out with no faces at all.
  test::TempDir dir;
  const std::string scan = write_scan(dir, 60'000);
  const IndexedMesh original = read_mesh(scan);
  IndexedMesh stray = original;
  const Box3 box = original.bounds();
  stray.positions.push_back((box.hi + 1000.0 * (box.hi - box.lo)).cast<float>());
  const std::string path = dir / "stray.ply";
  write_mesh(path, stray);
  SimplifyOptions options;
  options.target_faces = 100;
  options.memory_limit = 256 << 10;
  CompareOptions compare;
  compare.samples = 100'000;
  const SimplifyResult with_point = simplify(path, options);
  EXPECT_TRUE(with_point.out_of_core);
  EXPECT_GE(with_point.mesh.face_count(), 97u);
  EXPECT_LE(with_point.mesh.face_count(), 100u);
  const double rms = measure_distance(original, with_point.mesh, compare).rms;
  const double rms_without = measure_distance(original, simplify(scan, options).mesh, compare).rms;
  EXPECT_LT(rms, 1.5 * rms_without);
}

TEST(Pipeline, KeepsTheVerticesInCoreWhereClusteringThemAsASoupWouldTakeMore) {
  // 30 k vertices (360 kB) under a 256 kB limit. Dereferenced on disk, the faces are clustered as a soup,
  // whose cells take several times the bytes of the indexed pass's: for 3,000 faces (a ratio of 5 %, read
  // from the header) that is more than the vertex array itself, so the vertices stay in core and only the
  // far smaller target goes out of core (it used to at any target whose clustering took half the limit).
  test::TempDir dir;
  const std::string path = write_scan(dir, 60'000, 2);
  SimplifyOptions options;
  options.memory_limit = 256 << 10;
  for (const auto& [faces, ratio, out_of_core] :
       {std::tuple{3'000, 0.0, false}, {0, 0.05, false}, {100, 0.0, true}, {0, 100.0 / 60'000, true}}) {
    SCOPED_TRACE(std::to_string(faces) + " faces, ratio " + std::to_string(ratio));
    options.target_faces = static_cast<std::uint64_t>(faces);
    options.target_ratio = ratio;
    const SimplifyResult result = simplify(path, options);
    EXPECT_EQ(result.out_of_core, out_of_core);
    EXPECT_TRUE(result.clustered);
    const double by_ratio = std::round(ratio * static_cast<double>(result.input_faces));
    EXPECT_EQ(result.mesh.face_count(),
              faces > 0 ? static_cast<std::size_t>(faces) : static_cast<std::size_t>(by_ratio));
  }
}

TEST(Pipeline, WarnsOfAMemoryPlanOverTheLimitBeforeClustering) {
  // A user should learn that the limit will not hold before the long stages, not after them.
  test::TempDir dir;
  const std::string path = write_scan(dir, 60'000, 2);
  std::vector<std::string> events;
  for (const bool lod_chain : {false, true}) {
    SCOPED_TRACE(lod_chain ? "lod" : "simplify");
    events.clear();
    const ProgressFn progress = [&](std::string_view phase, std::uint64_t, std::uint64_t) {
      if (events.empty() || events.back() != phase) events.emplace_back(phase);
    };
    const WarningFn warn = [&](const std::string& message) { events.push_back("warning: " + message); };
    std::uint64_t memory_needed = 0;
    if (lod_chain) {
      LodOptions options;
      options.level_faces = {3'000, 1'000};
      options.memory_limit = 256 << 10;
      options.progress = progress;
      options.warn = warn;
      memory_needed = lod(path, options).memory_needed;
    } else {
      SimplifyOptions options;
      options.target_faces = 3'000;
      options.memory_limit = 256 << 10;
      options.progress = progress;
      options.warn = warn;
      memory_needed = simplify(path, options).memory_needed;
    }
    EXPECT_GT(memory_needed, 256u << 10);
    const auto warning = std::find_if(events.begin(), events.end(),
                                      [](const std::string& e) { return e.starts_with("warning: "); });
    ASSERT_NE(warning, events.end());
    EXPECT_NE(warning->find("expected to take about " + format_bytes(memory_needed)), std::string::npos)
        << *warning;
    EXPECT_EQ(std::count_if(events.begin(), events.end(),
                            [](const std::string& e) { return e.starts_with("warning: "); }),
              1);
    // Nothing of the clustering or the decimation has been reported before it.
    for (auto e = events.begin(); e != warning; ++e) {
      EXPECT_FALSE(e->starts_with("cluster") || e->starts_with("decimate")) << *e;
    }
    EXPECT_TRUE(
        std::any_of(warning, events.end(), [](const std::string& e) { return e.starts_with("cluster"); }));
  }
}

TEST(Pipeline, AMemoryLimitGivesTheSameBytesWhateverTheThreadsAndTheRun) {
  // Under a limit that squeezes the clustering plan (fewer fine cells than the full count), the plan must
  // come from the input and the options alone: the process's own memory grows from one run to the next and
  // with the threads, and a plan that counted it gave different meshes for the same command.
  test::TempDir dir;
  const std::string path = write_scan(dir, 60'000, 2);
  SimplifyOptions options;
  options.target_faces = 3'000;
  options.two_stage = true;
  options.memory_limit = 200u << 20;
  std::vector<IndexedMesh> results;
  for (const int threads : {1, 2, 1, 3}) {
    options.threads = threads;
    results.push_back(simplify(path, options).mesh);
    EXPECT_EQ(results.back().face_count(), 3'000u);
  }
  for (std::size_t i = 1; i < results.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(results[i].positions, results[0].positions);
    EXPECT_EQ(results[i].triangles, results[0].triangles);
  }
}

TEST(Pipeline, TwoStageReachesTheTargetOnPartsFarApart) {
  // Two small scans 5,000 diagonals apart: the box is almost empty, and the octree's fine grid, capped for
  // speed and sized for the box, was refined only until its cells neared a quarter of the vertices. The
  // intermediate came out with no faces, and so did the result.
  test::TempDir dir;
  const IndexedMesh part = read_mesh(write_scan(dir, 2'000));
  IndexedMesh two = part;
  const Box3 box = part.bounds();
  const Vec3f shift = (5'000.0 * (box.hi - box.lo)).cast<float>();
  for (const Vec3f& p : part.positions) two.positions.push_back(p + shift);
  const auto n = static_cast<Index>(part.vertex_count());
  for (const Triangle& t : part.triangles) two.triangles.push_back({t[0] + n, t[1] + n, t[2] + n});
  const std::string path = dir / "two.ply";
  write_mesh(path, two);
  SimplifyOptions options;
  options.target_faces = 200;
  options.two_stage = true;
  for (double intermediate : {1.0, 4.0}) {
    options.intermediate = intermediate;
    const SimplifyResult result = simplify(path, options);
    EXPECT_TRUE(result.clustered) << intermediate;
    // An intermediate of 1x the target is the largest count the octree reaches not above it.
    EXPECT_GE(result.intermediate_faces, 190u) << intermediate;
    EXPECT_GE(result.mesh.face_count(), 190u) << intermediate;
    EXPECT_LE(result.mesh.face_count(), 200u) << intermediate;
    // Both parts are there: about half the faces lie on each side.
    std::size_t far = 0;
    for (const Triangle& t : result.mesh.triangles) {
      if (result.mesh.positions[t[0]].x() > box.hi.x() + 0.5 * shift.x()) ++far;
    }
    EXPECT_GT(far, 80u) << intermediate;
    EXPECT_LT(far, 120u) << intermediate;
  }
}

TEST(Pipeline, AClusteringThatLosesTheFacesGivesWayToDecimatingInCore) {
  // A wavy strip, 1000 long and 0.01 wide: a grid with the cells the target asks for has cells wider than
  // the strip, where every face collapses. Under a memory limit that called for clustering, the result had
  // no face at all.
  test::TempDir dir;
  IndexedMesh strip;
  const Index along = 2'000, across = 3;
  for (Index i = 0; i < along; ++i) {
    const float x = 1000.0f * static_cast<float>(i) / static_cast<float>(along - 1);
    for (Index j = 0; j < across; ++j)
      strip.positions.push_back({x, 0.005f * static_cast<float>(j), std::sin(x / 50)});
  }
  for (Index i = 0; i + 1 < along; ++i) {
    for (Index j = 0; j + 1 < across; ++j) {
      const Index a = i * across + j, b = a + across;
      strip.triangles.push_back({a, b, b + 1});
      strip.triangles.push_back({a, b + 1, a + 1});
    }
  }
  const std::string path = dir / "strip.ply";
  write_mesh(path, strip);
  // Also under a limit that sends the vertices to disk (with a target small enough for that): it wrote a
  // mesh of no face, and exited 0.
  for (const auto& [limit, target] : {std::pair<std::uint64_t, std::uint64_t>{1 << 20, 800}, {1024, 20}}) {
    SimplifyOptions options;
    options.target_faces = target;
    options.memory_limit = limit;
    std::vector<std::string> warnings;
    options.warn = [&](const std::string& w) { warnings.push_back(w); };
    const SimplifyResult result = simplify(path, options);
    EXPECT_FALSE(result.clustered) << limit;
    EXPECT_EQ(result.mesh.face_count(), target) << limit << ": " << result.decimate.reason;
    EXPECT_TRUE(std::any_of(warnings.begin(), warnings.end(), [](const std::string& w) {
      return w.find("clustering kept 0 faces") != std::string::npos;
    })) << limit;
    if (target < 800) continue;  // (a strip decimated to 20 faces gives up some of its length)
    // The whole strip is still there, and nowhere off it.
    const Box3 box = result.mesh.bounds();
    EXPECT_LT(box.lo.x(), 1.0f);
    EXPECT_GT(box.hi.x(), 999.0f);
    EXPECT_GE(box.lo.y(), -1e-4f);
    EXPECT_LE(box.hi.y(), 0.0101f);
  }
  // With an error bound alone, too: there is no count to fall short of, but the output had no face.
  SimplifyOptions bound;
  bound.max_error = 0.01;
  bound.memory_limit = 1024;
  std::vector<std::string> warnings;
  bound.warn = [&](const std::string& w) { warnings.push_back(w); };
  const SimplifyResult result = simplify(path, bound);
  EXPECT_GT(result.mesh.face_count(), 0u);
  EXPECT_LE(result.max_error(), bound.max_error);
  EXPECT_TRUE(std::any_of(warnings.begin(), warnings.end(), [](const std::string& w) {
    return w.find("clustering kept 0 faces") != std::string::npos;
  }));
}

// A hemispherical cup of radius 1 with walls `wall` thick: outer and inner surfaces of n x n/2 quads, the
// rim joining them (a closed manifold).
IndexedMesh thick_cup(int n, float wall) {
  IndexedMesh cup;
  const int rings = n / 2;
  auto shell = [&](float radius) {
    const Index bottom = static_cast<Index>(cup.positions.size());
    cup.positions.push_back({0, 0, -radius});
    for (int j = 1; j <= rings; ++j) {
      const double theta = M_PI / 2 * j / rings;
      for (int i = 0; i < n; ++i) {
        const double phi = 2 * M_PI * i / n;
        cup.positions.push_back(Vec3d(radius * std::sin(theta) * std::cos(phi),
                                      radius * std::sin(theta) * std::sin(phi), -radius * std::cos(theta))
                                    .cast<float>());
      }
    }
    return bottom;
  };
  const Index outer = shell(1.0f), inner = shell(1.0f - wall);
  auto at = [&](Index base, int ring, int i) { return base + 1 + static_cast<Index>(ring * n + (i % n)); };
  auto quad = [&](Index a, Index b, Index c, Index d) {
    cup.triangles.push_back({a, b, c});
    cup.triangles.push_back({a, c, d});
  };
  for (int i = 0; i < n; ++i) {
    cup.triangles.push_back({outer, at(outer, 0, i + 1), at(outer, 0, i)});
    cup.triangles.push_back({inner, at(inner, 0, i), at(inner, 0, i + 1)});
    for (int j = 0; j + 1 < rings; ++j) {
      quad(at(outer, j, i), at(outer, j, i + 1), at(outer, j + 1, i + 1), at(outer, j + 1, i));
      quad(at(inner, j, i), at(inner, j + 1, i), at(inner, j + 1, i + 1), at(inner, j, i + 1));
    }
    quad(at(outer, rings - 1, i), at(outer, rings - 1, i + 1), at(inner, rings - 1, i + 1),
         at(inner, rings - 1, i));
  }
  return cup;
}

// Clustering merges walls thinner than its cells, and the folds it leaves can block the decimator above a
// target the input reaches: a cup of 80 k faces with walls 0.01 thick, through a 4x intermediate to 800
// faces, stopped at 2,023. The input is then read again and decimated in core, as where clustering keeps
// too few faces.
TEST(Pipeline, ADecimationBlockedOnTheClusteredMeshGivesWayToDecimatingInCore) {
  test::TempDir dir;
  const IndexedMesh cup = thick_cup(200, 0.01f);
  ASSERT_EQ(analyze_topology(cup).boundary_edges, 0u);
  const std::string path = dir / "cup.ply";
  write_mesh(path, cup);
  SimplifyOptions options = two_stage_to(800, 4);
  std::vector<std::string> warnings;
  options.warn = [&](const std::string& w) { warnings.push_back(w); };
  const SimplifyResult result = simplify(path, options);
  EXPECT_EQ(result.mesh.face_count(), 800u) << result.decimate.reason;
  EXPECT_TRUE(result.decimate.target_reached);
  EXPECT_FALSE(result.clustered);
  EXPECT_EQ(analyze_topology(result.mesh).non_manifold_edges, 0u);
  EXPECT_TRUE(std::any_of(warnings.begin(), warnings.end(), [](const std::string& w) {
    return w.find("reading the input again to decimate it in core") != std::string::npos;
  }));
  // Both tries are in the phases: cluster and decimate, then read and decimate.
  std::vector<std::string> names;
  for (const PhaseReport& p : result.phases) names.push_back(p.name);
  EXPECT_EQ(std::count(names.begin(), names.end(), "decimate"), 2) << names.size();
}

// lod gives way the same: its first level had stopped at 2,023 faces for 800, and every level after it
// started from there.
TEST(Lod, ALevelBlockedOnTheClusteredMeshGivesWayToDecimatingInCore) {
  test::TempDir dir;
  const std::string path = dir / "cup.ply";
  write_mesh(path, thick_cup(200, 0.01f));
  LodOptions options;
  options.level_faces = {800, 400};
  options.two_stage = true;
  options.intermediate = 4;
  std::vector<std::string> warnings;
  options.warn = [&](const std::string& w) { warnings.push_back(w); };
  const LodResult result = lod(path, options);
  ASSERT_EQ(result.levels.size(), 2u);
  double previous = 0;
  for (const LodLevel& level : result.levels) {
    EXPECT_EQ(level.mesh.face_count(), level.target_faces) << level.decimate.reason;
    EXPECT_TRUE(level.decimate.target_reached);
    EXPECT_EQ(analyze_topology(level.mesh).non_manifold_edges, 0u);
    EXPECT_GE(level.max_error, previous);
    previous = level.max_error;
  }
  EXPECT_FALSE(result.clustered);
  EXPECT_TRUE(std::any_of(warnings.begin(), warnings.end(), [](const std::string& w) {
    return w.find("reading the input again to decimate it in core") != std::string::npos;
  }));
  // The first try is in the phases, before the read that replaced it.
  ASSERT_GE(result.phases.size(), 4u);
  EXPECT_EQ(result.phases[1].name, "cluster");
  EXPECT_EQ(result.phases[2].name, "level 800");
  EXPECT_EQ(result.phases.back().name, "level 400");

  // A later level that stops gives way alone: 8,000 faces come from the clustered mesh, then 800 had
  // stopped at 1,483.
  options.level_faces = {8000, 800};
  const LodResult later = lod(path, options);
  ASSERT_EQ(later.levels.size(), 2u);
  EXPECT_TRUE(later.clustered);
  EXPECT_TRUE(later.levels[0].decimate.target_reached);
  EXPECT_EQ(later.levels[1].mesh.face_count(), 800u) << later.levels[1].decimate.reason;
  EXPECT_EQ(analyze_topology(later.levels[1].mesh).non_manifold_edges, 0u);
  EXPECT_GE(later.levels[1].max_error, later.levels[0].max_error);
  EXPECT_EQ(later.phases.back().name, "level 800");
  EXPECT_EQ(later.phases.back().triangles_in, 80'000u);
}

TEST(Pipeline, MaxErrorCountsTheClusteringStage) {
  // Out of core the intermediate is clustered to a size, not to an error: --max-error 0 let no collapse
  // through, yet the output was the clustered intermediate, reported with a max_error of 0 and the target
  // reached.
  test::TempDir dir;
  const std::string path = write_scan(dir, 20'000);
  SimplifyOptions options;
  options.max_error = 0;
  options.memory_limit = 256 << 10;
  const SimplifyResult clustered = simplify(path, options);
  ASSERT_TRUE(clustered.clustered);
  EXPECT_LT(clustered.mesh.face_count(), 20'000u);
  EXPECT_GT(clustered.cluster_error, 0.0);
  EXPECT_EQ(clustered.max_error(), clustered.cluster_error);
  EXPECT_FALSE(clustered.decimate.target_reached);
  EXPECT_NE(clustered.decimate.reason.find("--max-error"), std::string::npos) << clustered.decimate.reason;
  // The error is of the clustered vertices: none lies farther from the original's surface than a few times
  // it (it is an area-weighted RMS distance to the planes of its cell's triangles).
  const IndexedMesh original = read_mesh(path);
  const DistanceIndex index(original);
  for (const Vec3f& p : clustered.mesh.positions) {
    EXPECT_LE(std::sqrt(index.closest_point(p.cast<double>()).distance_squared), 4 * clustered.cluster_error);
  }
  // A bound the clustering meets is kept; in core there is no clustering error.
  options.max_error = 2 * clustered.cluster_error;
  const SimplifyResult within = simplify(path, options);
  EXPECT_TRUE(within.decimate.target_reached) << within.decimate.reason;
  EXPECT_LE(within.max_error(), options.max_error);
  options.memory_limit = 0;
  const SimplifyResult in_core = simplify(path, options);
  ASSERT_FALSE(in_core.clustered);
  EXPECT_EQ(in_core.cluster_error, 0.0);
  EXPECT_EQ(in_core.max_error(), in_core.decimate.max_error);
}

TEST(Pipeline, TwoStageWithAnErrorBoundAloneClusters) {
  // Without a count, the intermediate was as large as the memory budget allows, so every input that fit
  // was decimated directly and --two-stage did nothing, without a word.
  test::TempDir dir;
  const std::string path = write_scan(dir, 300'000);
  SimplifyOptions options;
  options.max_error = 1e-3;
  options.two_stage = true;
  const SimplifyResult result = simplify(path, options);
  EXPECT_TRUE(result.clustered);
  EXPECT_GT(result.intermediate_faces, 200'000u);
  EXPECT_LT(result.intermediate_faces, 300'000u);
  EXPECT_TRUE(result.decimate.target_reached) << result.decimate.reason;
  EXPECT_LE(result.max_error(), options.max_error);
  EXPECT_LT(result.mesh.face_count(), result.intermediate_faces);
}

TEST(Lod, LevelsComeOutInTheRequestedCountsLargestFirst) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 60'000, 2);
  LodOptions options;
  options.level_faces = {500, 20'000, 3'001};
  std::vector<std::size_t> seen;
  options.on_level = [&](std::size_t level, std::uint64_t target_faces, const IndexedMesh& mesh) {
    EXPECT_EQ(level, seen.size());
    EXPECT_EQ(target_faces, mesh.face_count());
    seen.push_back(mesh.face_count());
  };
  const LodResult result = lod(path, options);
  ASSERT_EQ(result.levels.size(), 3u);
  EXPECT_EQ(seen, (std::vector<std::size_t>{20'000, 3'001, 500}));
  double previous = 0;
  for (const LodLevel& level : result.levels) {
    EXPECT_EQ(level.faces, level.target_faces);
    EXPECT_TRUE(level.mesh.triangles.empty());  // handed to on_level, not kept
    EXPECT_GE(level.max_error, previous);
    EXPECT_GE(level.max_error, level.decimate.max_error);
    previous = level.max_error;
  }
  EXPECT_GT(result.levels.back().max_error, result.levels.front().max_error);
  EXPECT_FALSE(result.clustered);
  EXPECT_EQ(result.input_faces, read_mesh(path).face_count());

  // Through the clustering stage the counts are just as exact.
  options.two_stage = true;
  options.intermediate = 2;
  options.on_level = nullptr;
  const LodResult clustered = lod(path, options);
  EXPECT_TRUE(clustered.clustered);
  for (const LodLevel& level : clustered.levels) EXPECT_EQ(level.mesh.face_count(), level.target_faces);
}

// A ratio level counts the triangles actually read, which only the read (or the clustering pass) knows: an
// OBJ says nothing of its face count up front, and its size suggests about a third of it here.
TEST(Lod, RatiosResolveAgainstTheTrianglesRead) {
  test::TempDir dir;
  const IndexedMesh scan = read_mesh(write_scan(dir, 60'000, 2));
  const std::string obj = dir / "scan.obj";
  write_mesh(obj, scan);
  const std::uint64_t faces = scan.face_count();
  LodOptions options;
  options.level_ratios = {0.01, 0.5, 0.1};
  std::vector<std::uint64_t> named, announced;
  options.on_targets = [&](const std::vector<std::uint64_t>& targets) {
    EXPECT_TRUE(named.empty()) << "the targets come before the first level";
    announced = targets;
  };
  options.on_level = [&](std::size_t, std::uint64_t target_faces, const IndexedMesh&) {
    named.push_back(target_faces);
  };
  const std::vector<std::uint64_t> expected = {(faces + 1) / 2, (faces + 5) / 10, (faces + 50) / 100};
  for (bool two_stage : {false, true}) {
    SCOPED_TRACE(two_stage ? "clustered" : "in core");
    options.two_stage = two_stage;
    options.intermediate = two_stage ? 1.5 : 0;
    named.clear();
    announced.clear();
    const LodResult result = lod(obj, options);
    EXPECT_EQ(result.clustered, two_stage);
    EXPECT_EQ(result.input_faces, faces);
    ASSERT_EQ(result.levels.size(), 3u);
    EXPECT_EQ(announced, expected);
    EXPECT_EQ(named, expected);
    const double ratios[] = {0.5, 0.1, 0.01};
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(result.levels[i].target_faces, expected[i]);
      EXPECT_EQ(result.levels[i].faces, expected[i]);
      EXPECT_EQ(result.levels[i].target_ratio, ratios[i]);
    }
  }
}

TEST(Lod, EachLevelIsTheDecimationOfThePreviousWithItsQuadricsCarried) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 40'000, 1);
  LodOptions options;
  options.level_faces = {8'000, 800};
  const LodResult result = lod(path, options);
  ASSERT_EQ(result.levels.size(), 2u);

  DecimateOptions first;
  first.target_faces = 8'000;
  first.output_quadrics = true;
  QuadricMesh input;
  input.mesh = read_mesh(path);
  DecimateResult level0 = decimate(input, first);
  EXPECT_EQ(level0.mesh.triangles, result.levels[0].mesh.triangles);
  DecimateOptions second;
  second.target_faces = 800;
  second.boundary_weight = 0;  // the carried quadrics already hold the border planes level 0 added
  const DecimateResult carried = decimate(QuadricMesh{level0.mesh, level0.quadrics, level0.areas}, second);
  EXPECT_EQ(carried.mesh.positions, result.levels[1].mesh.positions);
  EXPECT_EQ(carried.mesh.triangles, result.levels[1].mesh.triangles);
  EXPECT_EQ(carried.stats.max_error, result.levels[1].decimate.max_error);
  EXPECT_EQ(result.levels[1].max_error, std::max(level0.stats.max_error, carried.stats.max_error));
}

TEST(Lod, RefusesBadLevelsAndPatterns) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 5'000);
  LodOptions options;
  EXPECT_THROW(lod(path, options), Error);
  options.level_faces = {100, 0};
  EXPECT_THROW(lod(path, options), Error);
  options.level_faces = {100, 50, 100};
  EXPECT_THROW(lod(path, options), Error);
  // Ratios: in (0, 1], distinct, apart enough to give distinct counts, and not beside face counts.
  options.level_faces = {100};
  options.level_ratios = {0.1};
  EXPECT_THROW(lod(path, options), Error);
  options.level_faces.clear();
  for (const std::vector<double>& bad :
       {std::vector<double>{0.1, 0}, {1.5}, {-0.1}, {0.1, std::nan("")}, {0.2, 0.1, 0.2}}) {
    options.level_ratios = bad;
    EXPECT_THROW(lod(path, options), Error);
  }
  options.level_ratios = {0.1, 0.01001, 0.01};  // 48 twice of the scan's 4,800 faces
  const std::uint64_t faces = read_mesh(path).face_count();
  ASSERT_EQ(faces, 4800u);
  try {
    lod(path, options);
    ADD_FAILURE() << "two ratios of one count were taken";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("0.01001 and 0.01 both give 48 faces of its 4800"), std::string::npos) << what;
  }
  options.level_ratios = {1, 0.1};
  const LodResult whole = lod(path, options);
  ASSERT_EQ(whole.levels.size(), 2u);
  EXPECT_EQ(whole.levels[0].faces, whole.input_faces);
  EXPECT_EQ(lod_level_path("out_{faces}.ply", 1000, true), "out_1000.ply");
  EXPECT_EQ(lod_level_path("{faces}/m{faces}.obj", 7, true), "7/m7.obj");
  EXPECT_EQ(lod_level_path("single.ply", 7, false), "single.ply");
  EXPECT_THROW(lod_level_path("single.ply", 7, true), Error);
}

TEST(Pipeline, RefusesMissingTargetsAndBadFiles) {
  test::TempDir dir;
  const std::string path = write_scan(dir, 5'000);
  EXPECT_THROW(simplify(path, SimplifyOptions{}), Error);
  SimplifyOptions options;
  options.target_faces = 100;
  EXPECT_THROW(simplify(dir / "missing.ply", options), Error);
  // A NaN ratio passed the range check beside a face target; the message is the library's, not a flag's.
  options.target_ratio = std::numeric_limits<double>::quiet_NaN();
  try {
    simplify(path, options);
    ADD_FAILURE() << "a NaN ratio was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("the ratio must be in (0, 1]"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace ocsimp
