// ocsimp lod: a chain of levels of detail from one read of the input, each decimated from the previous one
// with its quadrics carried, so every level's error is a distance to the original surface.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>

#include "commands.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/atomic_file.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/pipeline.h"

namespace ocsimp::cli {
namespace {

constexpr const char* kReportFields = R"(Report (--report FILE.json), one object:
  command             "lod"
  input, output       the input path and the output pattern
  input_faces         triangles read (polygons split into triangles)
  clustered, out_of_core, intermediate_faces, memory_limit_bytes, peak_rss_bytes, seconds   as in simplify
  max_error           the last (smallest) level's max_error
  levels              largest first: [{target_faces, faces, vertices, seam_copies, file, seconds, max_error,
                      level_max_error, target_reached, stop}], and target_ratio with --ratios (vertices
                      counts a texture seam's vertex once per side, seam_copies those beyond the first, as
                      in ocsimp decimate); max_error is the largest
                      collapse cost down the chain up to this level, or the clustering stage's vertex error
                      where larger, as an RMS distance to the original's planes (carried quadrics; not a
                      Hausdorff bound); level_max_error is this level's own run's largest cost
  phases              [{name, seconds, triangles_in, triangles_out, peak_rss_bytes}]: open, read or cluster,
                      then "level N" per level (decimating it and writing its file))";

}  // namespace

void add_lod_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "lod",
      "Levels of detail from one read of the input: each level decimated from the previous one with its "
      "quadrics carried, so every level's error is measured against the original; each file written "
      "atomically");
  cmd->footer(kReportFields);
  struct Flags {
    std::string input, output, report, memory_limit, faces, ratios;
    LodOptions options;
    bool ascii = false;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  LodOptions& o = flags->options;
  cmd->add_option("input", flags->input, "Input mesh (PLY, OBJ, STL or Draco)")->required();
  cmd->add_option("-o,--output", flags->output,
                  "Output pattern; {faces} becomes each level's target, e.g. 'out_{faces}.ply'")
      ->check(file_name())
      ->required();
  auto* faces = cmd->add_option("--faces", flags->faces,
                                "Face counts of the levels, comma-separated, e.g. 1000000,100000,10000");
  cmd->add_option("--ratios", flags->ratios,
                  "Or the levels as ratios of the input's faces, comma-separated, e.g. 0.1,0.01,0.001; "
                  "{faces} then becomes each ratio's count")
      ->excludes(faces);
  cmd->add_option("--memory-limit", flags->memory_limit,
                  "Peak memory budget, e.g. 2G (default: a third of RAM, or half of `ulimit -v` where less)")
      ->check(byte_size());
  cmd->add_flag(
      "--two-stage", o.two_stage,
      "Cluster first even when the input fits in core (an input no larger than the intermediate, by "
      "default at least 262,144 faces, is decimated directly unless --intermediate is given)");
  cmd->add_option(
      "--intermediate", o.intermediate,
      "Intermediate faces as a multiple of the largest level, for a run that clusters first (--two-stage, "
      "or an input past the memory budget) (default: from the memory budget, at most 8, and at least "
      "262,144 faces where the budget has room)");
  add_weld_flag(cmd, o.decimate.weld);
  cmd->add_option("--threads", o.threads, "Threads (0 = all cores); the output does not depend on it")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_option("--report", flags->report, "Write a JSON report of the run to this file (fields below)")
      ->check(file_name());
  cmd->add_flag("--ascii", flags->ascii, "Text PLY or STL output");
  cmd->add_flag("-q,--quiet", flags->quiet, "Only warnings and errors (no progress bars, no summary)");
  cmd->callback([flags] {
    LodOptions options = flags->options;
    const auto limit = limit_threads(options.threads);
    if (flags->faces.empty() == flags->ratios.empty())
      throw Error("lod needs its levels: --faces N,M,... or --ratios R,S,...");
    if (!flags->faces.empty()) options.level_faces = parse_face_list(flags->faces, "--faces");
    if (!flags->ratios.empty()) options.level_ratios = parse_ratio_list(flags->ratios, "--ratios");
    const bool several = options.level_faces.size() + options.level_ratios.size() > 1;
    // The levels' files may not replace the input (a pattern such as in_{faces}.ply easily names it), nor may
    // the report replace a level. Checked before anything is read for counts; a ratio's file is named only
    // once the input's count is known (on_targets), but its folder and format do not depend on that.
    auto check_level_files = [flags, several](const std::vector<std::uint64_t>& levels) {
      std::vector<std::string> meshes{flags->input};
      for (std::uint64_t faces : levels) {
        const std::string path = lod_level_path(flags->output, faces, several);
        check_mesh_destination(path, flags->input);
        // Two names of one file (a symbolic link to another level's) would leave one level of the two.
        for (std::size_t i = 1; i < meshes.size(); ++i) {
          if (same_file(path, meshes[i])) {
            throw Error(path, {}, "this level's file is also the level file " + meshes[i]);
          }
        }
        meshes.push_back(path);
      }
      if (!flags->report.empty()) check_report_destination(flags->report, meshes);
    };
    if (!options.level_faces.empty()) check_level_files(options.level_faces);
    if (!options.level_ratios.empty()) {
      check_mesh_destination(lod_level_path(flags->output, 1, several));
      if (!flags->report.empty()) check_report_destination(flags->report, {flags->input});
      options.on_targets = check_level_files;
    }
    if (!flags->memory_limit.empty()) options.memory_limit = parse_byte_size(flags->memory_limit);
    const Console console = make_console(flags->quiet, flags->input);
    const ProgressFn& progress = console.progress;
    options.progress = progress;
    options.warn = console.warn;
    std::vector<std::string> files;
    std::vector<std::size_t> vertices;
    WriteOptions write;
    write.ascii = flags->ascii;
    write.progress = progress;
    options.on_level = [&](std::size_t, std::uint64_t target_faces, const IndexedMesh& mesh) {
      files.push_back(lod_level_path(flags->output, target_faces, several));
      vertices.push_back(mesh.vertex_count());
      write_result(files.back(), mesh, write);
    };
    // The levels and the report appear together once all are written: a run that fails or is interrupted
    // part way leaves none, rather than a few levels beside stale ones from an earlier run (see publish).
    HeldCommits held;
    const auto start = std::chrono::steady_clock::now();
    const LodResult result = lod(flags->input, options);
    const double total = seconds_since(start);
    warn_if_over_memory_limit(console, result.memory_limit);

    if (!flags->report.empty()) {
      nlohmann::json report;
      report["command"] = "lod";
      report["input"] = flags->input;
      report["output"] = flags->output;
      report["input_faces"] = result.input_faces;
      report["clustered"] = result.clustered;
      report["out_of_core"] = result.out_of_core;
      report["intermediate_faces"] = result.intermediate_faces;
      report["memory_limit_bytes"] = result.memory_limit;
      report["peak_rss_bytes"] = peak_rss_bytes();
      report["seconds"] = total;
      report["max_error"] = result.levels.empty() ? 0.0 : result.levels.back().max_error;
      report["levels"] = nlohmann::json::array();
      for (std::size_t i = 0; i < result.levels.size(); ++i) {
        const LodLevel& level = result.levels[i];
        nlohmann::json entry = {{"target_faces", level.target_faces},
                                {"faces", level.faces},
                                {"vertices", vertices[i]},
                                {"seam_copies", level.decimate.seam_copies},
                                {"file", files[i]},
                                {"seconds", level.seconds},
                                {"max_error", level.max_error},
                                {"level_max_error", level.decimate.max_error},
                                {"target_reached", level.decimate.target_reached},
                                {"stop", stop_name(level.decimate.stop)}};
        if (level.target_ratio > 0) entry["target_ratio"] = level.target_ratio;
        report["levels"].push_back(std::move(entry));
      }
      report["phases"] = phases_json(result.phases);
      write_json_report(flags->report, report);
    }
    for (const LodLevel& level : result.levels) {
      if (!level.decimate.target_reached && !level.decimate.reason.empty()) {
        std::fprintf(stderr, "ocsimp: warning: level %llu: %s\n",
                     static_cast<unsigned long long>(level.target_faces), level.decimate.reason.c_str());
      }
    }
    if (show_summary(flags->quiet, flags->report)) {
      print_phase_table(result.phases);
      std::printf("\n%-12s %12s %12s %10s %14s  %s\n", "level", "faces", "vertices", "seconds", "max error",
                  "file");
      for (std::size_t i = 0; i < result.levels.size(); ++i) {
        const LodLevel& level = result.levels[i];
        std::printf("%-12llu %12llu %12llu %10.3f %14.6g  %s%s\n",
                    static_cast<unsigned long long>(level.target_faces),
                    static_cast<unsigned long long>(level.faces),
                    static_cast<unsigned long long>(vertices[i] - level.decimate.seam_copies), level.seconds,
                    level.max_error, files[i].c_str(), seam_copies_note(level.decimate.seam_copies).c_str());
      }
      std::printf(
          "total %.3f s from %llu input faces%s%s, peak RSS %s; max error is a distance to the original\n",
          total, static_cast<unsigned long long>(result.input_faces),
          result.clustered ? ", clustered first" : "",
          result.out_of_core ? ", vertices dereferenced on disk" : "",
          format_bytes(peak_rss_bytes()).c_str());
    }
    publish(held);
  });
}

}  // namespace ocsimp::cli
