// ocsimp simplify: the whole pipeline, from a file of any size to an exact target.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

#include "commands.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/pipeline.h"

namespace ocsimp::cli {
namespace {

constexpr const char* kReportFields = R"(Report (--report FILE.json), one object:
  command             "simplify"
  input, output       the paths
  input_faces         triangles read (polygons split into triangles)
  output_faces        faces written; output_vertices likewise (a texture seam's vertex once per side)
  output_seam_copies  vertices written beyond the first at a seam's position (see ocsimp decimate)
  clustered           whether the clustering stage ran (input over the in-core budget, or --two-stage)
  out_of_core         whether the input's vertices were dereferenced on disk (their array did not fit what
                      clustering leaves of the budget)
  intermediate_faces  faces after clustering (0 when not clustered)
  memory_limit_bytes  the budget in force; peak_rss_bytes the process's peak resident memory
  seconds             wall time of the whole run
  max_error           the result's largest error in model units, as an area-weighted RMS distance to the
                      original's planes (not a Hausdorff bound): the largest collapse cost applied, or a
                      clustered vertex's own error where larger
  cluster_error       that error of the clustering stage's vertices alone (0 when not clustered)
  target_reached, stop, reason   how the decimator stopped (see ocsimp decimate)
  phases              [{name, seconds, triangles_in, triangles_out, peak_rss_bytes}] for open, read or
                      cluster, decimate and write, in order)";

}  // namespace

void add_simplify_command(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("simplify",
                         "Simplify a mesh of any size: decimate in core when it fits the memory budget, "
                         "otherwise cluster in one streaming pass first and carry the quadrics on");
  cmd->footer(kReportFields);
  struct Flags {
    std::string input, output, report, memory_limit;
    SimplifyOptions options;
    bool ascii = false;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  SimplifyOptions& o = flags->options;
  cmd->add_option("input", flags->input, "Input mesh (PLY, OBJ, STL or Draco)")->required();
  cmd->add_option("-o,--output", flags->output, "Output mesh (.ply, .obj, .stl or .drc)")
      ->check(file_name())
      ->required();
  CLI::Option* faces = cmd->add_option("--faces", o.target_faces,
                                       "Exact face count, never more (N-1 where every collapse left removes "
                                       "two, as on a closed manifold; fewer "
                                       "where each removes more)")
                           ->transform(whole_number(1));
  cmd->add_option("--ratio", o.target_ratio, "Fraction of the input's faces, in (0, 1]")
      ->check(fraction())
      ->excludes(faces);
  cmd->add_option(
         "--max-error", o.max_error,
         "Largest collapse cost allowed, as a distance in model units (an area-weighted RMS distance to "
         "the original's planes, as in ocsimp decimate: not a bound on the Hausdorff distance)")
      ->check(non_negative_number(true));
  cmd->add_option(
         "--memory-limit", flags->memory_limit,
         "Peak memory budget, e.g. 2G (default: a third of RAM, or half of `ulimit -v` where less); an input "
         "whose vertex array does not "
         "fit beside the clustering is dereferenced on disk under TMPDIR when that takes less memory (a "
         "target far below the input)")
      ->check(byte_size());
  cmd->add_flag(
      "--two-stage", o.two_stage,
      "Cluster first even when the input fits in core (an input no larger than the intermediate, by "
      "default at least 262,144 faces, is decimated directly unless --intermediate is given)");
  cmd->add_option(
      "--intermediate", o.intermediate,
      "Intermediate faces as a multiple of the target, for a run that clusters first (--two-stage, or an "
      "input past the memory budget); an input that fits is otherwise decimated directly (default: from the "
      "memory budget, at most 8, and at least 262,144 faces where the budget has room)");
  add_weld_flag(cmd, o.decimate.weld);
  cmd->add_option("--threads", o.threads, "Threads (0 = all cores); the output does not depend on it")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_option("--report", flags->report, "Write a JSON report of the run to this file (fields below)")
      ->check(file_name());
  cmd->add_flag("--ascii", flags->ascii, "Text PLY or STL output");
  cmd->add_flag("-q,--quiet", flags->quiet, "Only warnings and errors (no progress bars, no summary)");
  cmd->callback([flags] {
    SimplifyOptions options = flags->options;
    const auto limit = limit_threads(options.threads);
    if (options.target_faces == 0 && options.target_ratio == 0 && !std::isfinite(options.max_error)) {
      throw Error("simplify needs --faces N, --ratio R or a finite --max-error E");
    }
    check_mesh_destination(flags->output, flags->input);  // refuse a bad destination before reading anything
    if (!flags->report.empty()) check_report_destination(flags->report, {flags->input, flags->output});
    if (!flags->memory_limit.empty()) options.memory_limit = parse_byte_size(flags->memory_limit);
    const Console console = make_console(flags->quiet, flags->input);
    const ProgressFn& progress = console.progress;
    options.progress = progress;
    options.warn = console.warn;
    const auto start = std::chrono::steady_clock::now();
    SimplifyResult result = simplify(flags->input, options);
    HeldCommits held;  // the mesh appears once the report and summary are out (see publish)
    const auto write_start = std::chrono::steady_clock::now();
    WriteOptions write;
    write.ascii = flags->ascii;
    write.progress = progress;
    write_result(flags->output, result.mesh, write);
    result.phases.push_back({"write", seconds_since(write_start), result.mesh.face_count(),
                             result.mesh.face_count(), peak_rss_bytes()});
    const double total = seconds_since(start);
    warn_if_over_memory_limit(console, result.memory_limit);

    if (!flags->report.empty()) {
      nlohmann::json report;
      report["command"] = "simplify";
      report["input"] = flags->input;
      report["output"] = flags->output;
      report["input_faces"] = result.input_faces;
      report["output_faces"] = result.mesh.face_count();
      report["output_vertices"] = result.mesh.vertex_count();
      report["output_seam_copies"] = result.decimate.seam_copies;
      report["clustered"] = result.clustered;
      report["out_of_core"] = result.out_of_core;
      report["intermediate_faces"] = result.intermediate_faces;
      report["memory_limit_bytes"] = result.memory_limit;
      report["peak_rss_bytes"] = peak_rss_bytes();
      report["seconds"] = total;
      report["max_error"] = result.max_error();
      report["cluster_error"] = result.cluster_error;
      report["target_reached"] = result.decimate.target_reached;
      report["stop"] = stop_name(result.decimate.stop);
      report["reason"] = result.decimate.reason;
      report["phases"] = phases_json(result.phases);
      write_json_report(flags->report, report);
    }
    if (!result.decimate.target_reached && !result.decimate.reason.empty()) {
      std::fprintf(stderr, "ocsimp: warning: target not reached: %s\n", result.decimate.reason.c_str());
    }
    if (show_summary(flags->quiet, flags->report)) {
      print_phase_table(result.phases);
      std::printf(
          "%-14s %10.3f   %s -> %s: %zu faces, %zu vertices%s, max error %.6g (distance)%s%s, peak RSS %s\n",
          "total", total, flags->input.c_str(), flags->output.c_str(), result.mesh.face_count(),
          result.mesh.vertex_count() - result.decimate.seam_copies,
          seam_copies_note(result.decimate.seam_copies).c_str(), result.max_error(),
          result.clustered ? ", clustered first" : "",
          result.out_of_core ? ", vertices dereferenced on disk" : "",
          format_bytes(peak_rss_bytes()).c_str());
    }
    publish(held);
  });
}

}  // namespace ocsimp::cli
