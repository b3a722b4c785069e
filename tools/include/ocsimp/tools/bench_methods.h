// End-to-end simplification benchmarks: every method ocsimp has (and meshoptimizer's, when the build found
// it) on one mesh at a set of face targets, with the time of the simplification call, the memory it used,
// the faces it reached and its two-sided distance to the original (tools/compare.h). `ocsimp bench` prints
// what run_bench() returns; bench/run_bench.sh drives it over the shared meshes.
//
//   ocsimp::BenchInput input{"bunny", "bunny.ply", ocsimp::read_mesh("bunny.ply")};
//   const std::uint64_t target = ocsimp::ratio_target(0.1, input.mesh.face_count());
//   std::vector<ocsimp::BenchResult> rows =
//       ocsimp::run_bench(input, ocsimp::available_bench_methods(), {target}, {0.1}, ocsimp::BenchOptions{});
//   std::fputs(ocsimp::bench_markdown_table(rows).c_str(), stdout);
//
// What is measured, per method and target:
//  - seconds: the median over `repeat` runs of the simplification call alone. Inputs are prepared before the
//    clock starts (an in-memory TriangleStream over a copy of the mesh for the cluster methods, a copy of the
//    mesh for the decimator, a flat index buffer for meshoptimizer) and outputs converted after it stops.
//    The exception is `two-stage`, which runs the pipeline on the file: its reading of faces is fused with
//    the clustering pass and cannot be split off, so its time is the pipeline's "cluster" and "decimate"
//    phases (faces parsed, clustered, decimated) without the "open" phase (header and vertex array).
//  - peak_bytes: the method's own peak resident memory, measured in this process: free heap is returned to
//    the system (malloc_trim), the kernel's resident high-water mark (VmHWM) is reset to the current
//    resident size (writing 5 to /proc/self/clear_refs), and after the call the new high-water mark minus
//    the resident size before it is the method's peak. The prepared input is resident before the reset, so
//    it is not counted; for `two-stage` the reader's vertex array is (the pipeline loads it). The largest
//    figure over the runs is kept. Forking a child per run would isolate better but is unsafe once TBB's
//    worker threads exist.
//  - distance: measure_distance() between the original and the last run's output, the original's
//    DistanceIndex built once per mesh.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"
#include "ocsimp/tools/compare.h"

namespace ocsimp {

// What each method promises about the faces it reaches for a target T:
enum class BenchMethod {
  grid_mean,       // uniform grid, cell mean as representative (Rossignac & Borrel): <= T
  grid_quadric,    // uniform grid, quadric-minimizing representative (Lindstrom 2000): <= T
  octree,          // adaptive octree merged least error first, quadric representatives: <= T
  decimate,        // Garland-Heckbert edge collapse in core: T, or T-1 for a closed manifold's parity
  two_stage,       // the pipeline with two_stage set (octree clustering, then decimation): T or T-1
  meshopt,         // meshopt_simplify with its error limit disabled: <= T (stops early when it must)
  meshopt_sloppy,  // meshopt_simplifySloppy (a grid search over cell sizes): <= T
};

// "grid-mean", "grid-quadric", "octree", "decimate", "two-stage", "meshopt", "meshopt-sloppy".
const char* bench_method_name(BenchMethod method);
// The method with that name; throws Error naming the methods this build has when there is none, or when
// it is a meshoptimizer method and the build did not find meshoptimizer.
BenchMethod parse_bench_method(std::string_view name);
// Every method this build can run, in the order above (meshoptimizer's only when the build found it).
std::vector<BenchMethod> available_bench_methods();
// Whether the meshoptimizer methods were built in.
bool bench_has_meshoptimizer();

struct BenchInput {
  std::string name;  // the label in tables ("bunny")
  std::string path;  // the file `mesh` was read from; `two-stage` runs the pipeline on it (required for it)
  IndexedMesh mesh;
};

struct BenchResult {
  std::string mesh;
  std::uint64_t input_faces = 0;
  std::uint64_t input_vertices = 0;
  std::uint64_t target_faces = 0;
  double target_ratio = 0;  // the ratio the target came from (0 when it was given as a count)
  BenchMethod method = BenchMethod::decimate;
  std::uint64_t faces = 0;     // reached
  std::uint64_t vertices = 0;  // used by the output's faces
  double seconds = 0;          // median of run_seconds
  std::vector<double> run_seconds;
  std::optional<std::uint64_t> peak_bytes;  // empty when the high-water mark cannot be reset here
  // Distances to the original; empty when the output has no faces (nothing to measure).
  std::optional<SurfaceDistance> distance;
};

struct BenchOptions {
  int repeat = 3;   // runs per method and target; the median time is reported (at least 1)
  int threads = 1;  // for ocsimp's methods (meshoptimizer is single-threaded); 0: all cores
  // Samples of the distance measurement (default 1 M each way, like /work/shared/BASELINES.md).
  CompareOptions compare;
  // Called after each result is complete (for a running log).
  std::function<void(const BenchResult&)> on_result;
};

// Runs one method on one mesh at one target `repeat` times and measures the result against `original`
// (the input mesh's DistanceIndex). `target_ratio` only labels the row. Throws Error for a target of 0, a
// `two-stage` run without a path, a method this build lacks, and whatever the method throws.
BenchResult run_bench_method(const BenchInput& input, const DistanceIndex& original, BenchMethod method,
                             std::uint64_t target_faces, double target_ratio, const BenchOptions& options);

// Every method at every target (targets outer, methods inner), building the original's DistanceIndex once.
// `target_ratios` is empty or holds the ratio each target came from.
std::vector<BenchResult> run_bench(const BenchInput& input, const std::vector<BenchMethod>& methods,
                                   const std::vector<std::uint64_t>& target_faces,
                                   const std::vector<double>& target_ratios, const BenchOptions& options);

// Markdown, one row per result: mesh | target | method | faces | seconds | RMS % diag | Hausdorff % diag |
// peak MiB ("-" where unknown; a "+" after a Hausdorff distance whose refinement did not settle, a lower
// bound: see compare.h).
std::string bench_markdown_table(const std::vector<BenchResult>& results);
// Every number, one row per result, with a header line.
std::string bench_csv(const std::vector<BenchResult>& results);
// {"settings": {...}, "results": [...]}: every number of every result, pretty-printed.
std::string bench_json(const std::vector<BenchResult>& results, const BenchOptions& options);

}  // namespace ocsimp
