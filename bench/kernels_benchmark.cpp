// Micro-benchmarks of the hot kernels, single-threaded:
//  - quadric accumulation: Quadric::triangle + += over a generated scan's triangles, into one sum (arithmetic
//    alone) and into per-vertex sums (the access pattern of face_quadrics_per_vertex and of the cluster
//    cells);
//  - quadric minimization: ocsimp::minimize on corner (rank 3), crease (rank 2) and flat (rank 1) quadrics;
//  - cell hashing: cluster.h exposes no hashing kernel (the cell tables are internal to cluster/), so this
//    times cluster() on an in-memory TriangleStream and reports nanoseconds per input triangle, for grids of
//    64^3 to 512^3 cells and both representatives;
//  - one collapse with its re-costing: decimate() to a tenth of a generated scan, minus decimate() to the
//    input's own face count (the setup alone: quadrics, edges, queue, output), divided by the collapses done.
//
//   build-bench/bin/bench_kernels --benchmark_min_time=0.2
#include <benchmark/benchmark.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "grid.h"  // cluster/src: the cell grid and hash tables are the cluster module's internals
#include "hash.h"
#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/quadric.h"
#include "ocsimp/decimate/decimate.h"
#include "ocsimp/streaming/mesh_stream.h"
#include "ocsimp/tools/generate.h"

namespace ocsimp {
namespace {

using Clock = std::chrono::steady_clock;

// CPU seconds of the calling thread: on a shared machine the wall clock also counts other processes' turns,
// so every counter below comes in both. (Single-threaded runs: the work stays on this thread.)
double thread_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

IndexedMesh scan(std::uint64_t triangles) {
  GenerateOptions options;
  options.triangles = triangles;
  options.threads = 1;
  return generate_scan_mesh(options);
}

// The corners of every triangle of a 100 k-triangle scan, in double, laid out as they are read.
const std::vector<Vec3d>& scan_corners() {
  static const std::vector<Vec3d> corners = [] {
    const IndexedMesh mesh = scan(100'000);
    std::vector<Vec3d> out;
    out.reserve(mesh.face_count() * 3);
    for (const Triangle& t : mesh.triangles) {
      for (Index v : t) out.push_back(mesh.positions[v].cast<double>());
    }
    return out;
  }();
  return corners;
}

void BM_QuadricTriangleSum(benchmark::State& state) {
  const std::vector<Vec3d>& corners = scan_corners();
  for (auto _ : state) {
    Quadric sum;
    for (std::size_t i = 0; i < corners.size(); i += 3)
      sum += Quadric::triangle(corners[i], corners[i + 1], corners[i + 2]);
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * std::int64_t(corners.size() / 3));
}
BENCHMARK(BM_QuadricTriangleSum)->Unit(benchmark::kMicrosecond);

// Triangle quadric added at its three corners' vertices (random access into a 50 k-vertex array).
void BM_QuadricTrianglePerVertex(benchmark::State& state) {
  static const IndexedMesh mesh = scan(100'000);
  std::vector<Quadric> sums(mesh.vertex_count());
  for (auto _ : state) {
    for (const Triangle& t : mesh.triangles) {
      const Quadric q =
          Quadric::triangle(mesh.positions[t[0]].cast<double>(), mesh.positions[t[1]].cast<double>(),
                            mesh.positions[t[2]].cast<double>());
      for (Index v : t) sums[v] += q;
    }
    benchmark::DoNotOptimize(sums.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * std::int64_t(mesh.face_count()));
}
BENCHMARK(BM_QuadricTrianglePerVertex)->Unit(benchmark::kMicrosecond);

// Quadrics of `rank` random planes through points near the origin (rank 1: one plane, a flat region; 2: a
// crease; 3: a corner), each minimized around a point off its minimizer, as a cluster cell or an edge does.
void BM_Minimize(benchmark::State& state) {
  const int rank = static_cast<int>(state.range(0));
  std::mt19937_64 rng(7);
  std::normal_distribution<double> gauss(0.0, 1.0);
  constexpr std::size_t kCount = 4096;
  std::vector<Quadric> quadrics(kCount);
  std::vector<Vec3d> origins(kCount);
  for (std::size_t i = 0; i < kCount; ++i) {
    const Vec3d on(gauss(rng), gauss(rng), gauss(rng));
    for (int p = 0; p < rank; ++p) {
      const Vec3d n = Vec3d(gauss(rng), gauss(rng), gauss(rng)).normalized();
      quadrics[i] += Quadric::plane(n, -n.dot(on), 0.5 + std::abs(gauss(rng)));
    }
    origins[i] = on + 0.1 * Vec3d(gauss(rng), gauss(rng), gauss(rng));
  }
  std::size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(minimize(quadrics[i], origins[i]));
    i = (i + 1) & (kCount - 1);
  }
  state.SetItemsProcessed(state.iterations());
  state.SetLabel("rank " + std::to_string(rank));
}
BENCHMARK(BM_Minimize)->Arg(1)->Arg(2)->Arg(3);

// Cell hashing, the clustering pass's bottleneck (BASELINES.md): each vertex of a 1M-triangle scan located on
// a G^3 grid over its box and its cell key looked up in the open-addressing cell table, in the reader's
// vertex order. args = grid cells along the longest axis, mode (0: locate only; 1: locate + insert into a
// table pre-sized for the occupied cells; 2: locate + find in the filled table). items/s = vertices/s.
void BM_CellHash(benchmark::State& state) {
  using namespace cluster_detail;
  static const IndexedMesh mesh = scan(1'000'000);
  Box3 box;
  for (const Vec3f& p : mesh.positions) box.add(p);
  const Grid grid = Grid::uniform(box, static_cast<std::uint32_t>(state.range(0)));
  const int mode = static_cast<int>(state.range(1));
  KeySet occupied;
  for (const Vec3f& p : mesh.positions) occupied.insert(grid.locate(p.cast<double>()));
  CellMap filled(occupied.size());
  {
    bool inserted = false;
    std::uint32_t next = 0;
    occupied.for_each([&](CellKey key) { filled.insert(key, next++, inserted); });
  }
  for (auto _ : state) {
    std::uint64_t sum = 0;
    if (mode == 1) {
      CellMap map(occupied.size());
      bool inserted = false;
      std::uint32_t next = 0;
      for (const Vec3f& p : mesh.positions) {
        sum += map.insert(grid.locate(p.cast<double>()), next, inserted);
        next += inserted;
      }
    } else {
      for (const Vec3f& p : mesh.positions) {
        const CellKey key = grid.locate(p.cast<double>());
        sum += mode == 0 ? key : filled.find(key);
      }
    }
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * mesh.positions.size()));
  state.counters["cells"] = double(occupied.size());
  state.SetLabel(mode == 0 ? "locate" : mode == 1 ? "locate+insert" : "locate+find");
}
BENCHMARK(BM_CellHash)->ArgsProduct({{256, 1024}, {0, 1, 2}})->Unit(benchmark::kMillisecond);

// cluster() per input triangle: args = triangles, grid cells along the longest axis, representative
// (0 quadric, 1 mean). Only the cluster() call is timed (manual time); the stream over a copy of the mesh is
// built outside it.
void BM_ClusterPerTriangle(benchmark::State& state) {
  const auto triangles = static_cast<std::uint64_t>(state.range(0));
  const IndexedMesh mesh = scan(triangles);
  ClusterOptions options;
  options.grid = static_cast<std::uint32_t>(state.range(1));
  options.representative = state.range(2) == 0 ? Representative::quadric : Representative::mean;
  options.threads = 1;
  std::uint64_t faces = 0;
  // Rate counters divide by the whole loop's CPU time, not the manual time: the figures are computed here.
  double timed = 0, cpu = 0;
  for (auto _ : state) {
    std::unique_ptr<TriangleStream> stream = make_mesh_stream(mesh);
    const double cpu_start = thread_cpu_seconds();
    const auto start = Clock::now();
    const QuadricMesh out = cluster(*stream, options);
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    cpu += thread_cpu_seconds() - cpu_start;
    state.SetIterationTime(seconds);
    timed += seconds;
    faces = out.mesh.face_count();
  }
  const double per = 1e9 / (double(state.iterations()) * double(mesh.face_count()));
  state.counters["ns_per_triangle"] = timed * per;
  state.counters["cpu_ns_per_triangle"] = cpu * per;
  state.counters["faces_out"] = double(faces);
  state.SetLabel(state.range(2) == 0 ? "quadric" : "mean");
}
BENCHMARK(BM_ClusterPerTriangle)
    ->Args({1 << 17, 64, 0})
    ->Args({1 << 17, 64, 1})
    ->Args({1 << 20, 128, 0})
    ->Args({1 << 20, 512, 0})
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

// decimate() per collapse: args = input triangles. Each iteration decimates to a tenth and, separately, to
// the input's own face count (no collapse: quadrics, edges, queue and output only); the manual time is the
// difference, so ns_per_collapse is the marginal cost of one collapse with the re-costing of its
// neighbourhood. setup_ms reports the part subtracted.
void BM_DecimatePerCollapse(benchmark::State& state) {
  const IndexedMesh mesh = scan(static_cast<std::uint64_t>(state.range(0)));
  DecimateOptions to_tenth;
  to_tenth.target_faces = mesh.face_count() / 10;
  to_tenth.threads = 1;
  DecimateOptions setup_only = to_tenth;
  setup_only.target_faces = mesh.face_count();
  double collapses = 0, setup_seconds = 0, marginal_seconds = 0, marginal_cpu = 0;
  for (auto _ : state) {
    QuadricMesh a{mesh, {}}, b{mesh, {}};
    double cpu_start = thread_cpu_seconds();
    auto start = Clock::now();
    const DecimateResult setup = decimate(std::move(a), setup_only);
    const double setup_time = std::chrono::duration<double>(Clock::now() - start).count();
    const double setup_cpu = thread_cpu_seconds() - cpu_start;
    cpu_start = thread_cpu_seconds();
    start = Clock::now();
    const DecimateResult full = decimate(std::move(b), to_tenth);
    const double full_time = std::chrono::duration<double>(Clock::now() - start).count();
    marginal_cpu += thread_cpu_seconds() - cpu_start - setup_cpu;
    benchmark::DoNotOptimize(setup.mesh.triangles.data());
    state.SetIterationTime(std::max(full_time - setup_time, 1e-9));
    collapses = double(full.stats.collapses);
    setup_seconds += setup_time;
    marginal_seconds += full_time - setup_time;
  }
  const double iterations = double(state.iterations());
  state.counters["collapses"] = collapses;
  state.counters["ns_per_collapse"] = collapses > 0 ? 1e9 * marginal_seconds / (iterations * collapses) : 0.0;
  state.counters["cpu_ns_per_collapse"] = collapses > 0 ? 1e9 * marginal_cpu / (iterations * collapses) : 0.0;
  state.counters["setup_ms"] = 1e3 * setup_seconds / iterations;
}
BENCHMARK(BM_DecimatePerCollapse)->Arg(100'000)->Arg(400'000)->UseManualTime()->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace ocsimp

BENCHMARK_MAIN();
