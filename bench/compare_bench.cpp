// Speed of distance measurement (tools/compare.h): the closest-point kernel, BVH builds, query throughput
// with and without the previous-closest-point bound, and the target case, a 10 M-triangle original
// against a 100 k-triangle result in under a minute.
//
//   build-cmp/bin/compare_bench --benchmark_filter=Large   # the 10 M vs 100 k case alone (about 1 GB)
#include <benchmark/benchmark.h>

#include <chrono>
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
