// ocsimp bench: every simplification method at every face target on one mesh, with time, memory, faces
// reached and distance to the original (tools/bench_methods.h); bench/run_bench.sh drives it.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "ocsimp/core/error.h"
#include "ocsimp/decimate/decimate.h"
#include "ocsimp/streaming/atomic_file.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/bench_methods.h"

namespace ocsimp::cli {

void add_bench_command(CLI::App& app) {
  std::string method_names;
  for (BenchMethod method : available_bench_methods()) {
    method_names += std::string(method_names.empty() ? "" : ",") + bench_method_name(method);
  }
  auto* cmd = app.add_subcommand(
      "bench",
      "Benchmark every simplification method at every target on one mesh: median time of the simplification "
      "call, peak memory, faces reached, and RMS / Hausdorff distance to the original; prints a Markdown "
      "table");
  struct Flags {
    std::string input, name, json, csv;
    std::string faces, ratios, methods;
    BenchOptions options;
    int distance_threads = 0;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  cmd->add_option("input", flags->input, "The mesh (PLY, OBJ, STL or Draco)")->required();
  auto* faces = cmd->add_option("--faces", flags->faces, "Face targets, comma-separated (e.g. 10000,2000)");
  auto* ratios = cmd->add_option("--ratios", flags->ratios,
                                 "Face targets as fractions of the input's faces (e.g. 0.1,0.02)");
  faces->excludes(ratios);
  auto* methods_option = cmd->add_option("--methods", flags->methods,
                                         "Methods, comma-separated (default: all of " + method_names + ")");
  cmd->add_option("--repeat", flags->options.repeat,
                  "Runs per method and target; the median time is reported")
      ->capture_default_str()
      ->transform(whole_number(1, 1000));
  cmd->add_option("--samples", flags->options.compare.samples, "Area samples each way for the distances")
      ->capture_default_str()
      ->transform(whole_number(1, 1'000'000'000));
  cmd->add_option("--seed", flags->options.compare.seed, "Sampling seed")
      ->capture_default_str()
      ->transform(whole_number(0));
  cmd->add_option("--threads", flags->options.threads,
                  "Threads for ocsimp's methods (0 = all cores; meshoptimizer runs on one)")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_option("--distance-threads", flags->distance_threads,
                  "Threads for the distance measurement (0 = all cores; the numbers do not depend on it)")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_option("--name", flags->name,
                  "The mesh's label in the table (default: the file name without extension)");
  cmd->add_option("--json", flags->json, "Also write every number as JSON to this file")->check(file_name());
  cmd->add_option("--csv", flags->csv, "Also write every number as CSV to this file")->check(file_name());
  cmd->add_flag("-q,--quiet", flags->quiet, "Only the table: no progress lines on stderr");
  cmd->callback([flags, methods_option] {
    if (flags->faces.empty() && flags->ratios.empty()) throw Error("bench: give --faces or --ratios");
    // Refused before the benchmark runs, not after it.
    for (const std::string* path : {&flags->json, &flags->csv}) {
      if (!path->empty()) check_report_destination(*path, {flags->input});
    }
    // One would replace the other, silently.
    if (!flags->json.empty() && !flags->csv.empty() && same_file(flags->json, flags->csv))
      throw Error(flags->csv, {}, "--json and --csv name the same file");
    // The lists are checked before the mesh is read.
    const std::vector<std::uint64_t> faces =
        flags->faces.empty() ? std::vector<std::uint64_t>{} : parse_face_list(flags->faces, "--faces");
    const std::vector<double> ratios =
        flags->ratios.empty() ? std::vector<double>{} : parse_ratio_list(flags->ratios, "--ratios");
    std::vector<BenchMethod> methods;
    if (methods_option->count() > 0) {  // given empty, the list is refused rather than read as "all"
      for (const std::string& name : parse_name_list(flags->methods, "--methods"))
        methods.push_back(parse_bench_method(name));
    } else {
      methods = available_bench_methods();
    }

    BenchInput input;
    input.path = flags->input;
    input.name = flags->name.empty() ? std::filesystem::path(flags->input).stem().string() : flags->name;
    input.mesh = read_mesh(flags->input);
    if (input.mesh.face_count() == 0) throw Error(flags->input, {}, "the mesh has no faces to simplify");

    std::vector<std::uint64_t> targets = faces;
    for (double ratio : ratios) targets.push_back(ratio_target(ratio, input.mesh.face_count()));
    const Console console = make_console(true, flags->input);  // warnings only: bench draws no bar
    for (std::uint64_t target : faces) {
      if (target >= input.mesh.face_count()) {
        console.warn("the target of " + std::to_string(target) + " faces is not below the mesh's " +
                     std::to_string(input.mesh.face_count()) + ": its rows measure the mesh as it is");
      }
    }

    BenchOptions options = flags->options;
    if (!flags->quiet) {
      std::fprintf(stderr, "%s: %zu vertices, %zu faces; %zu methods x %zu targets, %d runs each\n",
                   flags->input.c_str(), input.mesh.vertex_count(), input.mesh.face_count(), methods.size(),
                   targets.size(), options.repeat);
      options.on_result = [](const BenchResult& r) {
        std::fprintf(stderr, "  %-14s target %-10llu faces %-10llu %9.4f s  RMS %s %% diag\n",
                     bench_method_name(r.method), static_cast<unsigned long long>(r.target_faces),
                     static_cast<unsigned long long>(r.faces), r.seconds,
                     r.distance ? std::to_string(r.distance->percent(r.distance->rms)).c_str() : "-");
      };
    }
    // The methods take their thread count from `options.threads`; this only limits the distance sampling.
    const auto limit = limit_threads(flags->distance_threads);
    const std::vector<BenchResult> results = run_bench(input, methods, targets, ratios, options);

    std::fputs(bench_markdown_table(results).c_str(), stdout);
    const bool lower_bounds = std::any_of(results.begin(), results.end(), [](const BenchResult& r) {
      return r.distance && !r.distance->hausdorff_settled();
    });
    if (lower_bounds)
      std::printf(
          "\nA Hausdorff distance marked + is a lower bound: its refinement ran out of queries (see "
          "`ocsimp compare`).\n");
    HeldCommits held;  // both files appear once the table is out (see publish)
    auto write_text = [](const std::string& path, const std::string& text) {
      AtomicFile file(path);
      file.write(text);
      file.commit();
    };
    if (!flags->json.empty()) write_text(flags->json, bench_json(results, options));
    if (!flags->csv.empty()) write_text(flags->csv, bench_csv(results));
    publish(held);
  });
}

}  // namespace ocsimp::cli
