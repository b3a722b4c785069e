// Speed of distance measurement (tools/compare.h): the closest-point kernel, BVH builds, query throughput
// with and without the previous-closest-point bound, and the target case, a 10 M-triangle original
// against a 100 k-triangle result in under a minute.
//
//   build-cmp/bin/compare_bench --benchmark_filter=Large   # the 10 M vs 100 k case alone (about 1 GB)
#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "ocsimp/tools/compare.h"
#include "ocsimp/tools/generate.h"

namespace ocsimp {
namespace {

IndexedMesh scan(std::uint64_t triangles, double noise) {
  GenerateOptions options;
  options.triangles = triangles;
  options.noise = noise;
  return generate_scan_mesh(options);
}

void BM_ClosestPointOnTriangle(benchmark::State& state) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> coordinate(-1, 1);
  std::vector<Vec3d> points(4096 * 4);
  for (Vec3d& p : points) p = {coordinate(rng), coordinate(rng), coordinate(rng)};
  std::size_t i = 0;
  for (auto _ : state) {
    const Vec3d* q = &points[4 * (i++ & 4095)];
    benchmark::DoNotOptimize(closest_point_on_triangle(q[0], q[1], q[2], q[3]));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ClosestPointOnTriangle);

void BM_BuildIndex(benchmark::State& state) {
  const IndexedMesh mesh = scan(static_cast<std::uint64_t>(state.range(0)), 0.15);
  for (auto _ : state) {
    const DistanceIndex index(mesh);
    benchmark::DoNotOptimize(index.area());
  }
  state.SetItemsProcessed(state.iterations() * std::int64_t(mesh.face_count()));
}
BENCHMARK(BM_BuildIndex)->Arg(100'000)->Arg(1'000'000)->Unit(benchmark::kMillisecond)->UseRealTime();

// Area samples of a 100 k-triangle surface queried one by one against a 1 M-triangle index, single thread:
// arg 1 bounds each search by the distance to the previous sample's closest point (what measure_one_sided
// does), arg 0 starts every search unbounded (the baseline).
void BM_QuerySamples(benchmark::State& state) {
  const bool bounded = state.range(0) != 0;
  const DistanceIndex target(scan(1'000'000, 0.15));
  const std::vector<Vec3d> samples = DistanceIndex(scan(100'000, 0.0)).sample_surface(100'000, 1);
  for (auto _ : state) {
    Vec3d previous = Vec3d::Zero();
    bool have_previous = false;
    double sum = 0;
    for (const Vec3d& p : samples) {
      const double bound = bounded && have_previous ? (p - previous).norm() * 1.000001
                                                    : std::numeric_limits<double>::infinity();
      ClosestPoint closest = target.closest_point(p, bound);
      if (!(closest.distance_squared < std::numeric_limits<double>::infinity()))
        closest = target.closest_point(p);
      sum += closest.distance_squared;
      previous = closest.point;
      have_previous = true;
    }
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * std::int64_t(samples.size()));
}
BENCHMARK(BM_QuerySamples)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// A CAD-style cone: `segments` long side slivers from a wide ring to a narrow one, and two fan caps whose
// slivers run from the centre to the rim at every angle (boxes mostly empty, overlapping by the hundreds).
IndexedMesh fan_cone(Index segments) {
  IndexedMesh mesh;
  for (Index i = 0; i < 2 * segments; ++i) {
    const double angle = 2 * std::numbers::pi * double(i % segments) / double(segments),
                 radius = i < segments ? 1 : 0.01;
    mesh.positions.emplace_back(float(radius * std::cos(angle)), float(radius * std::sin(angle)),
                                i < segments ? 0.0f : 2.0f);
  }
  mesh.positions.emplace_back(0.0f, 0.0f, 0.0f);
  mesh.positions.emplace_back(0.0f, 0.0f, 2.0f);
  for (Index i = 0; i < segments; ++i) {
    const Index j = (i + 1) % segments;
    mesh.triangles.push_back({i, j, segments + j});
    mesh.triangles.push_back({i, segments + j, segments + i});
    mesh.triangles.push_back({2 * segments, j, i});
    mesh.triangles.push_back({2 * segments + 1, segments + i, segments + j});
  }
  return mesh;
}

// 100 k area samples of a 20 k-triangle mesh measured against itself as `compare` does (bounded searches,
// all cores): arg 0 a generated scan (well-shaped triangles, the baseline), arg 1 a cone of 5,000 segments
// (all slivers across the axes, which the index builds with spatial splits).
void BM_MeasureSelf(benchmark::State& state) {
  const IndexedMesh mesh = state.range(0) == 0 ? scan(20'000, 0.15) : fan_cone(5'000);
  const DistanceIndex index(mesh);
  CompareOptions options;
  options.samples = 100'000;
  options.include_vertices = false;
  for (auto _ : state) benchmark::DoNotOptimize(measure_one_sided(index, index, options).rms);
  state.SetItemsProcessed(state.iterations() * std::int64_t(options.samples));
  state.counters["faces"] = double(mesh.face_count());
}
BENCHMARK(BM_MeasureSelf)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// The requirement: 10 M triangles against 100 k, default options (1 M area samples each way plus
// every vertex), all cores. Counters give each phase in seconds.
void BM_LargeCompare(benchmark::State& state) {
  const IndexedMesh original = scan(10'000'000, 0.15);
  const IndexedMesh simplified = scan(100'000, 0.0);
  using Clock = std::chrono::steady_clock;
  auto seconds_since = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  for (auto _ : state) {
    CompareOptions options;
    auto t = Clock::now();
    const DistanceIndex original_index(original);
    state.counters["build_10M_s"] = seconds_since(t);
    t = Clock::now();
    const DistanceIndex simplified_index(simplified);
    state.counters["build_100k_s"] = seconds_since(t);
    t = Clock::now();
    const OneSidedDistance forward = measure_one_sided(original_index, simplified_index, options);
    state.counters["forward_s"] = seconds_since(t);
    t = Clock::now();
    const OneSidedDistance backward = measure_one_sided(simplified_index, original_index, options);
    state.counters["backward_s"] = seconds_since(t);
    state.counters["rms_percent"] =
        combine_distances(forward, backward, original_index.bounds().diagonal()).rms * 100 /
        original_index.bounds().diagonal();
    state.counters["forward_queries"] = double(forward.samples + forward.vertex_samples);
  }
  state.counters["faces"] = double(original.face_count());
}
BENCHMARK(BM_LargeCompare)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
}  // namespace ocsimp

BENCHMARK_MAIN();
