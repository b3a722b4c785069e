// ocsimp decimate: Garland-Heckbert quadric edge collapse of a whole mesh in memory, to an exact face or
// vertex count or to an error bound.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

#include "commands.h"
#include "ocsimp/core/error.h"
#include "ocsimp/decimate/decimate.h"
#include "ocsimp/streaming/io.h"

namespace ocsimp::cli {

void add_decimate_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "decimate",
      "Simplify by quadric edge collapse (Garland-Heckbert, exact priority) to an exact face or vertex count "
      "or an error bound; the whole mesh is held in memory");
  struct Flags {
    std::string input, output, report;
    DecimateOptions options;
    bool no_area_weighting = false;
    bool ascii = false;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  DecimateOptions& o = flags->options;
  cmd->add_option("input", flags->input, "Input mesh (PLY, OBJ, STL or Draco)")->required();
  cmd->add_option("-o,--output", flags->output, "Output mesh (.ply, .obj, .stl or .drc)")
      ->check(file_name())
      ->required();
  CLI::Option* faces = cmd->add_option("--faces", o.target_faces,
                                       "Stop at exactly N faces, never more (N-1 where every collapse left "
                                       "removes two, as on a closed manifold; "
                                       "fewer where each removes more)")
                           ->transform(whole_number(1));
  cmd->add_option("--vertices", o.target_vertices,
                  "Stop at exactly N vertices (positions: the copies of one along a texture or normal seam "
                  "count once); with --faces or --ratio too, at whichever target is met first")
      ->transform(whole_number(1));
  cmd->add_option("--ratio", o.target_ratio, "Stop at round(R * input faces) faces, R in (0, 1]")
      ->check(fraction())
      ->excludes(faces);
  cmd->add_option(
         "--max-error", o.max_error,
         "Apply no collapse whose cost exceeds E: the area-weighted RMS distance, in model units, from the "
         "new vertex to the planes of the original surface it stands for, border and seam planes adding "
         "their error at --boundary-weight (an RMS, not a bound on the Hausdorff distance, which is usually "
         "larger)")
      ->check(non_negative_number(true));
  cmd->add_option("--pair-distance", o.pair_distance,
                  "Also join vertex pairs closer than T (model units) that share no edge")
      ->check(non_negative_number());
  cmd->add_option("--boundary-weight", o.boundary_weight,
                  "Weight of the planes that hold open borders and texture or normal seams in place (0: they "
                  "move freely)")
      ->capture_default_str()
      ->check(non_negative_number());
  cmd->add_flag("--lock-boundary", o.lock_boundary, "Border vertices never move or merge with each other");
  cmd->add_flag("--preserve-topology", o.preserve_topology,
                "Enforce the link condition: manifold stays manifold, no hole closes, no part vanishes");
  cmd->add_flag("--no-area-weighting", flags->no_area_weighting,
                "Weigh every face plane the same instead of by its area");
  cmd->add_option("--shape-weight", o.shape_weight, "Penalty on collapses that leave slivers (0: off)")
      ->capture_default_str()
      ->check(non_negative_number());
  cmd->add_option(
         "--attribute-weight", o.attribute_weight,
         "Penalty on collapsing an edge whose ends differ in normal, color or uv: keeps sharp "
         "attribute boundaries (a color edge); on smoothly varying attributes it costs both geometry "
         "and attribute accuracy (0: geometry only)")
      ->capture_default_str()
      ->check(non_negative_number());
  add_weld_flag(cmd, o.weld);
  cmd->add_option("--threads", o.threads, "Threads (0 = all cores); the output does not depend on it")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_option("--report", flags->report, "Write counts, statistics, times and peak memory as JSON")
      ->check(file_name());
  cmd->add_flag("--ascii", flags->ascii, "Text PLY or STL instead of binary");
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress bar, no summary");
  cmd->callback([flags] {
    const auto start = std::chrono::steady_clock::now();
    check_mesh_destination(flags->output, flags->input);  // refuse a bad destination before reading anything
    if (!flags->report.empty()) check_report_destination(flags->report, {flags->input, flags->output});
    DecimateOptions options = flags->options;
    const auto limit = limit_threads(options.threads);
    options.area_weighting = !flags->no_area_weighting;
    if (options.target_faces == 0 && options.target_vertices == 0 && options.target_ratio == 0 &&
        !(options.max_error < std::numeric_limits<double>::infinity())) {
      throw Error("decimate needs --faces N, --vertices N, --ratio R or a finite --max-error E");
    }
    const Console console = make_console(flags->quiet, flags->input);
    const ProgressFn& progress = console.progress;
    options.progress = progress;

    // 144 bytes a face at peak on gen 4 M.
    check_whole_mesh_fits({flags->input}, 130, "decimate holds the whole mesh and its edges",
                          "ocsimp simplify takes any size within --memory-limit, clustering first");
    ReadOptions read;
    read.progress = progress;
    read.warn = console.warn;
    // The decimator welds the sides of a seam back together and keeps each one's attributes.
    read.split_corner_attributes = options.weld;
    QuadricMesh input;
    input.mesh = read_mesh(flags->input, read);
    const double read_seconds = seconds_since(start);
    const std::size_t input_vertices = input.mesh.vertex_count();
    const std::size_t input_faces = input.mesh.face_count();
    const auto decimate_start = std::chrono::steady_clock::now();
    DecimateResult result = decimate(std::move(input), options);
    const double decimate_seconds = seconds_since(decimate_start);
    check_input_faces(flags->input, console.warn, options.weld, result.stats);
    HeldCommits held;  // the mesh appears once the report and summary are out (see publish)
    const auto write_start = std::chrono::steady_clock::now();
    WriteOptions write;
    write.ascii = flags->ascii;
    write.progress = progress;
    write_result(flags->output, result.mesh, write);
    const double write_seconds = seconds_since(write_start);
    const double total_seconds = seconds_since(start);
    const DecimateStats& s = result.stats;

    if (!flags->report.empty()) {
      nlohmann::json report;
      report["input"] = {{"file", flags->input},
                         {"vertices", input_vertices},
                         {"faces", input_faces},
                         {"faces_used", s.input_faces},
                         {"vertices_used", s.input_vertices},
                         {"welded_vertices", s.welded_vertices},
                         {"single_face_vertices", s.single_face_vertices},
                         {"separate_faces", s.separate_faces},
                         {"dropped_degenerate_faces", s.dropped_degenerate_faces},
                         {"dropped_repeated_faces", s.dropped_repeated_faces}};
      // vertices: the file's; positions: what the vertex target counts (a seam's copies of one count once).
      report["output"] = {{"file", flags->output},
                          {"vertices", result.mesh.vertex_count()},
                          {"positions", s.vertices},
                          {"seam_copies", s.seam_copies},
                          {"faces", s.faces}};
      report["options"] = {{"target_faces", options.target_faces},
                           {"target_vertices", options.target_vertices},
                           {"target_ratio", options.target_ratio},
                           {"max_error", std::isfinite(options.max_error) ? nlohmann::json(options.max_error)
                                                                          : nlohmann::json(nullptr)},
                           {"pair_distance", options.pair_distance},
                           {"boundary_weight", options.boundary_weight},
                           {"lock_boundary", options.lock_boundary},
                           {"preserve_topology", options.preserve_topology},
                           {"area_weighting", options.area_weighting},
                           {"shape_weight", options.shape_weight},
                           {"attribute_weight", options.attribute_weight},
                           {"weld", options.weld},
                           {"threads", options.threads}};
      report["decimate"] = {{"collapses", s.collapses},
                            {"target_faces", s.target_faces},
                            {"target_vertices", s.target_vertices},
                            {"target_reached", s.target_reached},
                            {"stop", stop_name(s.stop)},
                            {"reason", s.reason},
                            {"max_error", s.max_error},
                            {"rejected_flip", s.rejected_flip},
                            {"rejected_topology", s.rejected_topology}};
      report["seconds"] = {{"read", read_seconds},
                           {"decimate", decimate_seconds},
                           {"write", write_seconds},
                           {"total", total_seconds}};
      report["peak_rss_bytes"] = peak_rss_bytes();
      report["peak_rss_bytes_per_input_face"] =
          input_faces > 0 ? static_cast<double>(peak_rss_bytes()) / static_cast<double>(input_faces) : 0.0;
      write_json_report(flags->report, report);
    }
    if (!s.target_reached)
      std::fprintf(stderr, "ocsimp: warning: target not reached: %s\n", s.reason.c_str());
    if (show_summary(flags->quiet, flags->report)) {
      std::printf(
          "%s: %zu faces -> %llu faces, %llu vertices%s (%s) in %.2f s (decimate %.2f s), largest cost "
          "%.3g, peak RSS %s\n",
          flags->input.c_str(), input_faces, static_cast<unsigned long long>(s.faces),
          static_cast<unsigned long long>(s.vertices), seam_copies_note(s.seam_copies).c_str(),
          stop_name(s.stop), total_seconds, decimate_seconds, s.max_error,
          format_bytes(peak_rss_bytes()).c_str());
    }
    publish(held);
  });
}

}  // namespace ocsimp::cli
