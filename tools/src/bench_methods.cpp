#include "ocsimp/tools/bench_methods.h"

#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <thread>
#include <utility>

#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/error.h"
#include "ocsimp/decimate/decimate.h"
#include "ocsimp/streaming/mesh_stream.h"
#include "ocsimp/tools/pipeline.h"

#ifdef OCSIMP_HAVE_MESHOPTIMIZER
#include <meshoptimizer.h>

#include <cfloat>
#endif

namespace ocsimp {
namespace {

using Clock = std::chrono::steady_clock;

constexpr BenchMethod kAllMethods[] = {
    BenchMethod::grid_mean, BenchMethod::grid_quadric, BenchMethod::octree,        BenchMethod::decimate,
    BenchMethod::two_stage, BenchMethod::meshopt,      BenchMethod::meshopt_sloppy};

bool is_meshopt(BenchMethod method) {
  return method == BenchMethod::meshopt || method == BenchMethod::meshopt_sloppy;
}

// The method's peak resident memory: see the top of bench_methods.h.
class PeakMemoryWindow {
 public:
  PeakMemoryWindow() {
    // Free heap the allocator keeps would be reused by the method without raising the resident size.
    malloc_trim(0);
    std::ofstream clear("/proc/self/clear_refs");
    clear << "5";  // resets VmHWM to the current VmRSS (Linux 4.0+)
    clear.flush();
    reset_ = static_cast<bool>(clear);
    baseline_ = current_rss_bytes();
    // The reset succeeded only if the high-water mark now sits at the current size. Within a slack: Linux
    // keeps a process's resident size in per-CPU counters and reads them approximately (up to 32 pages per
    // CPU apart), so the two figures can differ by that much right after a reset. (The slack was 16 pages
    // when BenchMethods.EveryMethodReachesWhatItPromises failed once under ctest -j2, this being the one
    // figure in it that depends on timing; it did not fail again in 60 runs.)
    const std::uint64_t cpus = std::max(1u, std::thread::hardware_concurrency());
    const std::uint64_t slack =
        std::max<std::uint64_t>(std::uint64_t{1} << 20, cpus * (std::uint64_t{256} << 10));
    if (reset_ && peak_rss_bytes() > baseline_ + slack) reset_ = false;
  }

  std::optional<std::uint64_t> peak() const {
    if (!reset_ || baseline_ == 0) return std::nullopt;
    const std::uint64_t high = peak_rss_bytes();
    return high > baseline_ ? high - baseline_ : 0;
  }

 private:
  bool reset_ = false;
  std::uint64_t baseline_ = 0;
};

// One timed run: the output mesh, the seconds that count and the memory window's figure.
struct TimedRun {
  IndexedMesh mesh;
  double seconds = 0;
  std::optional<std::uint64_t> peak;
};

double seconds_between(Clock::time_point start, Clock::time_point end) {
  return std::chrono::duration<double>(end - start).count();
}

// Drops vertices no face uses and renumbers the rest in order, so vertex counts are comparable between
// methods that keep the input's vertex buffer (meshoptimizer) and those that compact (the rest).
IndexedMesh compact(const std::vector<Vec3f>& positions, std::vector<Triangle> triangles,
                    const Vec3d& origin) {
  constexpr Index kUnused = std::numeric_limits<Index>::max();
  std::vector<Index> remap(positions.size(), kUnused);
  IndexedMesh out;
  out.origin = origin;
  for (Triangle& t : triangles) {
    for (Index& v : t) {
      if (remap[v] == kUnused) {
        remap[v] = static_cast<Index>(out.positions.size());
        out.positions.push_back(positions[v]);
      }
      v = remap[v];
    }
  }
  out.triangles = std::move(triangles);
  return out;
}

TimedRun run_cluster(const IndexedMesh& mesh, BenchMethod method, std::uint64_t target, int threads) {
  ClusterOptions options;
  options.target_faces = target;
  options.threads = static_cast<unsigned>(std::max(threads, 0));
  options.octree = method == BenchMethod::octree;
  options.representative = method == BenchMethod::grid_mean ? Representative::mean : Representative::quadric;
  std::unique_ptr<TriangleStream> stream = make_mesh_stream(mesh);
  TimedRun run;
  PeakMemoryWindow window;
  const auto start = Clock::now();
  QuadricMesh result = cluster(*stream, options);
  run.seconds = seconds_between(start, Clock::now());
  run.peak = window.peak();
  stream.reset();
  run.mesh = compact(result.mesh.positions, std::move(result.mesh.triangles), result.mesh.origin);
  return run;
}

TimedRun run_decimate(const IndexedMesh& mesh, std::uint64_t target, int threads) {
  DecimateOptions options;
  options.target_faces = target;
  options.threads = threads;
  QuadricMesh input;
  input.mesh = mesh;
  TimedRun run;
  PeakMemoryWindow window;
  const auto start = Clock::now();
  DecimateResult result = decimate(std::move(input), options);
  run.seconds = seconds_between(start, Clock::now());
  run.peak = window.peak();
  run.mesh = std::move(result.mesh);
  return run;
}

TimedRun run_two_stage(const std::string& path, std::uint64_t target, int threads) {
  if (path.empty()) throw Error("bench: two-stage runs the pipeline on a file, and this mesh has none");
  SimplifyOptions options;
  options.target_faces = target;
  options.two_stage = true;
  options.threads = threads;
  TimedRun run;
  PeakMemoryWindow window;
  SimplifyResult result = simplify(path, options);
  run.peak = window.peak();
  for (const PhaseReport& phase : result.phases) {
    if (phase.name != "open") run.seconds += phase.seconds;
  }
  run.mesh = std::move(result.mesh);
  return run;
}

#ifdef OCSIMP_HAVE_MESHOPTIMIZER
TimedRun run_meshopt(const IndexedMesh& mesh, BenchMethod method, std::uint64_t target) {
  std::vector<unsigned int> indices;
  indices.reserve(mesh.triangles.size() * 3);
  for (const Triangle& t : mesh.triangles) indices.insert(indices.end(), t.begin(), t.end());
  // Both functions may write up to the input's index count.
  std::vector<unsigned int> destination(indices.size());
  const std::size_t target_indices =
      static_cast<std::size_t>(std::min<std::uint64_t>(target, mesh.face_count())) * 3;
  const float* positions = mesh.positions.empty() ? nullptr : mesh.positions.front().data();
  static_assert(sizeof(Vec3f) == 3 * sizeof(float), "meshoptimizer reads positions with a 12-byte stride");
  TimedRun run;
  PeakMemoryWindow window;
  const auto start = Clock::now();
  // The error limit is disabled (FLT_MAX) so that both go as far toward the target as they can.
  const std::size_t count =
      method == BenchMethod::meshopt
          ? meshopt_simplify(destination.data(), indices.data(), indices.size(), positions,
                             mesh.vertex_count(), sizeof(Vec3f), target_indices, FLT_MAX, 0, nullptr)
          : meshopt_simplifySloppy(destination.data(), indices.data(), indices.size(), positions,
                                   mesh.vertex_count(), sizeof(Vec3f), target_indices, FLT_MAX, nullptr);
  run.seconds = seconds_between(start, Clock::now());
  run.peak = window.peak();
  std::vector<Triangle> triangles(count / 3);
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    triangles[i] = {destination[3 * i], destination[3 * i + 1], destination[3 * i + 2]};
  }
  run.mesh = compact(mesh.positions, std::move(triangles), mesh.origin);
  return run;
}
#endif

TimedRun run_once(const BenchInput& input, BenchMethod method, std::uint64_t target, int threads) {
  switch (method) {
    case BenchMethod::grid_mean:
    case BenchMethod::grid_quadric:
    case BenchMethod::octree:
      return run_cluster(input.mesh, method, target, threads);
    case BenchMethod::decimate:
      return run_decimate(input.mesh, target, threads);
    case BenchMethod::two_stage:
      return run_two_stage(input.path, target, threads);
    case BenchMethod::meshopt:
    case BenchMethod::meshopt_sloppy:
#ifdef OCSIMP_HAVE_MESHOPTIMIZER
      return run_meshopt(input.mesh, method, target);
#else
      break;
#endif
  }
  throw Error(std::string("bench: method ") + bench_method_name(method) + " is not built in");
}

double median(std::vector<double> values) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

std::string with_commas(std::uint64_t value) {
  std::string digits = std::to_string(value);
  std::string out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return out;
}

std::string format(const char* pattern, double value) {
  char text[64];
  std::snprintf(text, sizeof text, pattern, value);
  return text;
}

// "10 %", "0.5 %" for ratios; the count otherwise.
std::string target_label(const BenchResult& r) {
  if (r.target_ratio <= 0) return with_commas(r.target_faces);
  return format("%g", 100.0 * r.target_ratio) + " %";
}

std::string seconds_text(double seconds) {
  return format(seconds < 0.01 ? "%.4f" : "%.3f", seconds);
}

double to_mib(std::uint64_t bytes) {
  return static_cast<double>(bytes) / double(1 << 20);
}

nlohmann::ordered_json one_sided_json(const OneSidedDistance& d, const SurfaceDistance& all) {
  return {{"hausdorff", d.hausdorff},
          {"mean", d.mean},
          {"rms", d.rms},
          {"hausdorff_percent", all.percent(d.hausdorff)},
          {"mean_percent", all.percent(d.mean)},
          {"rms_percent", all.percent(d.rms)},
          {"samples", d.samples},
          {"vertex_samples", d.vertex_samples},
          {"hausdorff_bound",
           std::isfinite(d.hausdorff_bound) ? nlohmann::ordered_json(d.hausdorff_bound) : nullptr},
          {"hausdorff_settled", d.hausdorff_settled}};
}

}  // namespace

const char* bench_method_name(BenchMethod method) {
  switch (method) {
    case BenchMethod::grid_mean:
      return "grid-mean";
    case BenchMethod::grid_quadric:
      return "grid-quadric";
    case BenchMethod::octree:
      return "octree";
    case BenchMethod::decimate:
      return "decimate";
    case BenchMethod::two_stage:
      return "two-stage";
    case BenchMethod::meshopt:
      return "meshopt";
    case BenchMethod::meshopt_sloppy:
      return "meshopt-sloppy";
  }
  return "?";
}

bool bench_has_meshoptimizer() {
#ifdef OCSIMP_HAVE_MESHOPTIMIZER
  return true;
#else
  return false;
#endif
}

std::vector<BenchMethod> available_bench_methods() {
  std::vector<BenchMethod> methods;
  for (BenchMethod method : kAllMethods) {
    if (!is_meshopt(method) || bench_has_meshoptimizer()) methods.push_back(method);
  }
  return methods;
}

BenchMethod parse_bench_method(std::string_view name) {
  for (BenchMethod method : kAllMethods) {
    if (name != bench_method_name(method)) continue;
    if (is_meshopt(method) && !bench_has_meshoptimizer()) {
      throw Error("bench: method '" + std::string(name) +
                  "' needs meshoptimizer, which this build did not find");
    }
    return method;
  }
  std::string known;
  for (BenchMethod method : available_bench_methods())
    known += std::string(known.empty() ? "" : ", ") + bench_method_name(method);
  throw Error("bench: unknown method '" + std::string(name) + "' (this build has " + known + ")");
}

BenchResult run_bench_method(const BenchInput& input, const DistanceIndex& original, BenchMethod method,
                             std::uint64_t target_faces, double target_ratio, const BenchOptions& options) {
  if (target_faces == 0) throw Error("bench: a face target must be at least 1");
  BenchResult result;
  result.mesh = input.name;
  result.input_faces = input.mesh.face_count();
  result.input_vertices = input.mesh.vertex_count();
  result.target_faces = target_faces;
  result.target_ratio = target_ratio;
  result.method = method;

  IndexedMesh output;
  const int runs = std::max(options.repeat, 1);
  for (int r = 0; r < runs; ++r) {
    output = {};  // the previous output goes before the next run's memory window opens
    TimedRun run = run_once(input, method, target_faces, options.threads);
    result.run_seconds.push_back(run.seconds);
    if (run.peak) result.peak_bytes = std::max(result.peak_bytes.value_or(0), *run.peak);
    output = std::move(run.mesh);
  }
  result.seconds = median(result.run_seconds);
  result.faces = output.face_count();
  result.vertices = output.vertex_count();
  if (output.face_count() > 0) {
    const DistanceIndex simplified(output, bench_method_name(method));
    result.distance = measure_distance(original, simplified, options.compare);
  }
  return result;
}

std::vector<BenchResult> run_bench(const BenchInput& input, const std::vector<BenchMethod>& methods,
                                   const std::vector<std::uint64_t>& target_faces,
                                   const std::vector<double>& target_ratios, const BenchOptions& options) {
  if (!target_ratios.empty() && target_ratios.size() != target_faces.size()) {
    throw Error("bench: give one ratio per target, or none");
  }
  const DistanceIndex original(input.mesh, input.path.empty() ? input.name : input.path);
  std::vector<BenchResult> results;
  for (std::size_t t = 0; t < target_faces.size(); ++t) {
    for (BenchMethod method : methods) {
      results.push_back(run_bench_method(input, original, method, target_faces[t],
                                         target_ratios.empty() ? 0.0 : target_ratios[t], options));
      if (options.on_result) options.on_result(results.back());
    }
  }
  return results;
}

std::string bench_markdown_table(const std::vector<BenchResult>& results) {
  std::string out =
      "| mesh | target | method | faces | seconds | RMS % diag | Hausdorff % diag | peak MiB |\n"
      "|---|---|---|---:|---:|---:|---:|---:|\n";
  for (const BenchResult& r : results) {
    // A '|' in the caller's label would start a new cell; a line break, a new row.
    std::string name;
    for (char c : r.mesh)
      name += c == '|' ? std::string("\\|") : c == '\n' || c == '\r' ? std::string(" ") : std::string(1, c);
    out += "| " + name + " | " + target_label(r) + " | " + bench_method_name(r.method) + " | " +
           with_commas(r.faces) + " | " + seconds_text(r.seconds) + " | ";
    if (r.distance) {
      out += format("%.4f", r.distance->percent(r.distance->rms)) + " | " +
             format("%.4f", r.distance->percent(r.distance->hausdorff)) +
             (r.distance->hausdorff_settled() ? "" : "+") + " | ";
    } else {
      out += "- | - | ";
    }
    out += (r.peak_bytes ? format("%.1f", to_mib(*r.peak_bytes)) : std::string("-")) + " |\n";
  }
  return out;
}

std::string bench_csv(const std::vector<BenchResult>& results) {
  std::string out =
      "mesh,input_faces,input_vertices,target_ratio,target_faces,method,faces,vertices,seconds,seconds_min,"
      "seconds_max,runs,peak_bytes,diagonal,hausdorff,mean,rms,hausdorff_percent,mean_percent,rms_percent,"
      "forward_hausdorff,forward_mean,forward_rms,backward_hausdorff,backward_mean,backward_rms,samples\n";
  auto number = [](double value) { return format("%.9g", value); };
  for (const BenchResult& r : results) {
    // Mesh names are labels the caller chose; quote them so a comma cannot shift the columns.
    std::string name = "\"";
    for (char c : r.mesh) name += c == '"' ? std::string("\"\"") : std::string(1, c);
    name += "\"";
    const auto [low, high] = std::minmax_element(r.run_seconds.begin(), r.run_seconds.end());
    out += name + "," + std::to_string(r.input_faces) + "," + std::to_string(r.input_vertices) + "," +
           number(r.target_ratio) + "," + std::to_string(r.target_faces) + "," + bench_method_name(r.method) +
           "," + std::to_string(r.faces) + "," + std::to_string(r.vertices) + "," + number(r.seconds) + "," +
           number(r.run_seconds.empty() ? 0.0 : *low) + "," + number(r.run_seconds.empty() ? 0.0 : *high) +
           "," + std::to_string(r.run_seconds.size()) + "," +
           (r.peak_bytes ? std::to_string(*r.peak_bytes) : "") + ",";
    if (r.distance) {
      const SurfaceDistance& d = *r.distance;
      out += number(d.diagonal) + "," + number(d.hausdorff) + "," + number(d.mean) + "," + number(d.rms) +
             "," + number(d.percent(d.hausdorff)) + "," + number(d.percent(d.mean)) + "," +
             number(d.percent(d.rms)) + "," + number(d.forward.hausdorff) + "," + number(d.forward.mean) +
             "," + number(d.forward.rms) + "," + number(d.backward.hausdorff) + "," +
             number(d.backward.mean) + "," + number(d.backward.rms) + "," +
             std::to_string(d.forward.samples) + "\n";
    } else {
      out += ",,,,,,,,,,,,,\n";
    }
  }
  return out;
}

std::string bench_json(const std::vector<BenchResult>& results, const BenchOptions& options) {
  nlohmann::ordered_json out;
  out["settings"] = {{"repeat", std::max(options.repeat, 1)},
                     {"threads", options.threads},
                     {"samples", options.compare.samples},
                     {"seed", options.compare.seed},
                     {"include_vertices", options.compare.include_vertices},
                     {"meshoptimizer", bench_has_meshoptimizer()},
#ifdef OCSIMP_HAVE_MESHOPTIMIZER
                     {"meshoptimizer_version", MESHOPTIMIZER_VERSION},
#endif
                     {"seconds", "median of the runs, simplification call only (see bench_methods.h)"},
                     {"peak_bytes", "resident high-water mark above the resident size before the call"}};
  out["results"] = nlohmann::ordered_json::array();
  for (const BenchResult& r : results) {
    nlohmann::ordered_json row = {
        {"mesh", r.mesh},
        {"input_faces", r.input_faces},
        {"input_vertices", r.input_vertices},
        {"target_faces", r.target_faces},
        {"target_ratio", r.target_ratio},
        {"method", bench_method_name(r.method)},
        {"faces", r.faces},
        {"vertices", r.vertices},
        {"seconds", r.seconds},
        {"run_seconds", r.run_seconds},
        {"peak_bytes", r.peak_bytes ? nlohmann::ordered_json(*r.peak_bytes) : nlohmann::ordered_json()}};
    if (r.distance) {
      const SurfaceDistance& d = *r.distance;
      row["distance"] = {{"diagonal", d.diagonal},
                         {"hausdorff", d.hausdorff},
                         {"mean", d.mean},
                         {"rms", d.rms},
                         {"hausdorff_percent", d.percent(d.hausdorff)},
                         {"mean_percent", d.percent(d.mean)},
                         {"rms_percent", d.percent(d.rms)},
                         {"forward", one_sided_json(d.forward, d)},
                         {"backward", one_sided_json(d.backward, d)}};
    } else {
      row["distance"] = nullptr;
    }
    out["results"].push_back(std::move(row));
  }
  // The mesh's name comes from its file name, which need not be UTF-8: such bytes become U+FFFD.
  return out.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

}  // namespace ocsimp
