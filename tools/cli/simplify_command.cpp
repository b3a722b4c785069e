// ocsimp simplify: the whole pipeline, from a file of any size to an exact target.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include "commands.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/pipeline.h"

namespace ocsimp::cli {

void add_simplify_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("simplify",
                                 "Simplify a mesh of any size: decimate in core when it fits the memory budget, "
                                 "otherwise cluster in one streaming pass first and carry the quadrics on");
  struct Flags {
    std::string input, output, report, memory_limit;
    SimplifyOptions options;
    bool ascii = false;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  SimplifyOptions& o = flags->options;
  cmd->add_option("input", flags->input, "Input mesh (PLY, OBJ, STL or Draco)")->required();
  cmd->add_option("-o,--output", flags->output, "Output mesh (.ply, .obj, .stl or .drc)")->required();
  cmd->add_option("--faces", o.target_faces, "Exact face count (N-1 where a closed manifold's parity forbids N)")
      ->check(CLI::Range(std::uint64_t{1}, std::numeric_limits<std::uint64_t>::max()));
  cmd->add_option("--ratio", o.target_ratio, "Fraction of the input's faces, in (0, 1]")
      ->check(CLI::Range(std::numeric_limits<double>::min(), 1.0));
  cmd->add_option("--max-error", o.max_error, "Largest collapse cost allowed, as a distance in model units")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--memory-limit", flags->memory_limit, "Peak memory budget, e.g. 2G (default: a third of RAM)");
  cmd->add_flag("--two-stage", o.two_stage, "Cluster first even when the input fits in core");
  cmd->add_option("--intermediate", o.intermediate,
                  "Intermediate faces as a multiple of the target (default: from the memory budget, at most 8)");
  cmd->add_option("--threads", o.threads, "Threads (0 = all cores); the output does not depend on it")
      ->capture_default_str();
  cmd->add_option("--report", flags->report, "Write a JSON report of the run to this file");
  cmd->add_flag("--ascii", flags->ascii, "Text PLY or STL output");
  cmd->add_flag("-q,--quiet", flags->quiet, "Nothing but errors");
  cmd->callback([flags] {
    SimplifyOptions options = flags->options;
    if (options.target_faces == 0 && options.target_ratio == 0 && !std::isfinite(options.max_error)) {
      throw Error("simplify: give --faces, --ratio or --max-error");
    }
    format_from_extension(flags->output);  // refuse an unknown output format before reading anything
    if (!flags->memory_limit.empty()) options.memory_limit = parse_byte_size(flags->memory_limit);
    options.progress = make_progress(flags->quiet);
    const auto start = std::chrono::steady_clock::now();
    SimplifyResult result = simplify(flags->input, options);
    const auto write_start = std::chrono::steady_clock::now();
    WriteOptions write;
    write.ascii = flags->ascii;
    write_mesh(flags->output, result.mesh, write);
    const auto end = std::chrono::steady_clock::now();
    result.phases.push_back({"write", std::chrono::duration<double>(end - write_start).count(),
                             result.mesh.face_count(), result.mesh.face_count(), peak_rss_bytes()});
    const double total = std::chrono::duration<double>(end - start).count();

    nlohmann::json report;
    report["input"] = flags->input;
    report["output"] = flags->output;
    report["input_faces"] = result.input_faces;
    report["output_faces"] = result.mesh.face_count();
    report["output_vertices"] = result.mesh.vertex_count();
    report["clustered"] = result.clustered;
    report["intermediate_faces"] = result.intermediate_faces;
    report["memory_limit_bytes"] = result.memory_limit;
    report["peak_rss_bytes"] = peak_rss_bytes();
    report["seconds"] = total;
    report["max_error"] = result.decimate.max_error;
    report["target_reached"] = result.decimate.target_reached;
    report["stop"] = stop_name(result.decimate.stop);
    report["reason"] = result.decimate.reason;
    report["phases"] = nlohmann::json::array();
    for (const PhaseReport& p : result.phases) {
      report["phases"].push_back({{"name", p.name},
                                  {"seconds", p.seconds},
                                  {"triangles_in", p.triangles_in},
                                  {"triangles_out", p.triangles_out},
                                  {"peak_rss_bytes", p.peak_rss_bytes}});
    }
    if (!flags->report.empty()) write_json_report(flags->report, report);
    if (!flags->quiet) {
      std::printf("%-10s %10s %14s %14s %12s\n", "phase", "seconds", "triangles in", "triangles out", "peak RSS");
      for (const PhaseReport& p : result.phases) {
        std::printf("%-10s %10.3f %14llu %14llu %12s\n", p.name.c_str(), p.seconds,
                    static_cast<unsigned long long>(p.triangles_in), static_cast<unsigned long long>(p.triangles_out),
                    format_bytes(p.peak_rss_bytes).c_str());
      }
      std::printf("%-10s %10.3f   %s -> %s: %zu faces, max collapse error %.6g%s\n", "total", total,
                  flags->input.c_str(), flags->output.c_str(), result.mesh.face_count(), result.decimate.max_error,
                  result.clustered ? " (clustered first)" : "");
      if (!result.decimate.target_reached && !result.decimate.reason.empty()) {
        std::printf("note: %s\n", result.decimate.reason.c_str());
      }
    }
  });
}

}  // namespace ocsimp::cli
