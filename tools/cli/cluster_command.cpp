// ocsimp cluster: streaming vertex clustering, one pass over the input.
#include <chrono>
#include <cstdio>
#include <memory>

#include "commands.h"
#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"

namespace ocsimp::cli {

void add_cluster_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "cluster",
      "Simplify by vertex clustering in one pass over the input (any size): a uniform grid or an adaptive "
      "octree, vertices placed by quadric error, open borders kept");
  struct Flags {
    std::string input, output, report;
    ClusterOptions options;
    std::uint64_t faces = 0, vertices = 0;
    std::string representative = "quadric";
    bool no_boundary = false;
    std::string memory_limit;
    bool ascii = false;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  cmd->add_option("input", flags->input, "Input mesh (PLY, OBJ, STL or Draco)")->required();
  cmd->add_option("-o,--output", flags->output, "Output mesh (.ply, .obj, .stl or .drc)")
      ->check(file_name())
      ->required();
  auto* grid = cmd->add_option("--grid", flags->options.grid, "Uniform grid: cells along the longest axis")
                   ->capture_default_str()
                   ->transform(whole_number(1, 1u << 21));
  auto* cell = cmd->add_option("--cell-size", flags->options.cell_size, "Uniform grid: edge length of a cell")
                   ->check(positive_number());
  auto* faces = cmd->add_option("--faces", flags->faces,
                                "Face budget, never exceeded. Octree: the largest face count not above it, "
                                "by merging; uniform grid: the resolution a search finds closest below it (a "
                                "grid's face count does not grow strictly with its resolution)")
                    ->transform(whole_number(1, std::uint64_t{1} << 40));
  auto* octree =
      cmd->add_flag("--octree", flags->options.octree, "Adaptive octree: needs --vertices or --faces");
  auto* vertices = cmd->add_option("--vertices", flags->vertices, "Octree: exactly this many vertices")
                       ->transform(whole_number(1, std::uint64_t{1} << 40));
  grid->excludes(cell);
  faces->excludes(grid)->excludes(cell);
  vertices->excludes(faces)->excludes(grid)->excludes(cell)->needs(octree);
  cmd->add_option(
         "--representative", flags->representative,
         "Where a cell puts its vertex: quadric (minimizer of the cell's quadric), constrained (that "
         "minimizer kept inside the cell) or mean (average of the cell's vertices)")
      ->check(CLI::IsMember({"quadric", "constrained", "mean"}))
      ->capture_default_str();
  cmd->add_flag("--no-boundary", flags->no_boundary,
                "Do not hold open borders in place, nor fit representatives to sharp creases (the same edge "
                "planes serve both, so this changes closed meshes too)");
  cmd->add_option("--boundary-weight", flags->options.boundary_weight,
                  "Weight of a border crossing against a cell's worth of surface")
      ->capture_default_str()
      ->check(non_negative_number());
  cmd->add_option(
         "--memory-limit", flags->memory_limit,
         "Bytes the input's vertex array may take, e.g. 2G (default: a third of RAM, or half of "
         "`ulimit -v` where less); a larger one "
         "is dereferenced on disk under TMPDIR and its faces clustered as triangle soups (with a target "
         "or --grid, only where that takes less memory than staying in core); a warning says when the "
         "run's peak went over it")
      ->check(byte_size());
  cmd->add_option("--threads", flags->options.threads,
                  "Threads (0 = all cores); the output does not depend on it")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_option("--report", flags->report, "Write cells, faces in and out, times and peak memory as JSON")
      ->check(file_name());
  cmd->add_flag("--ascii", flags->ascii, "Text PLY or STL instead of binary");
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress bar, no summary");
  cmd->callback([flags, grid] {
    const auto start = std::chrono::steady_clock::now();
    check_mesh_destination(flags->output, flags->input);  // refuse a bad destination before reading anything
    if (!flags->report.empty()) check_report_destination(flags->report, {flags->input, flags->output});
    ClusterOptions options = flags->options;
    options.preserve_boundary = !flags->no_boundary;
    options.representative = flags->representative == "mean"          ? Representative::mean
                             : flags->representative == "constrained" ? Representative::constrained
                                                                      : Representative::quadric;
    options.target_faces = flags->faces;
    options.target_vertices = flags->vertices;
    if (options.octree && flags->vertices == 0 && flags->faces == 0) {
      throw Error("--octree needs --vertices N or --faces N");
    }
    const auto limit = limit_threads(static_cast<int>(options.threads));
    const Console console = make_console(flags->quiet, flags->input);
    const ProgressFn& progress = console.progress;
    options.progress = progress;

    ReadOptions read;
    read.progress = progress;
    read.warn = console.warn;
    const std::uint64_t memory_limit =
        effective_memory_limit(flags->memory_limit.empty() ? 0 : parse_byte_size(flags->memory_limit));
    read.memory_budget = cluster_vertex_allowance(options, memory_limit);
    std::unique_ptr<TriangleStream> stream = open_triangle_stream(flags->input, read);
    const bool out_of_core = dereferenced_out_of_core(*stream);
    // Out of core the clustering sees corners, not the file's vertex array: the count comes from the stream.
    const std::uint64_t file_vertices = dereferenced_vertex_count(*stream);
    if (!stream->attributes_left_out().empty())
      console.warn(attributes_left_out_warning(stream->attributes_left_out()));
    const double open_seconds = seconds_since(start);
    ClusterStats stats;
    const QuadricMesh result = cluster(*stream, options, &stats);
    // As every other command says of it when reading: an empty output would read as "every triangle
    // collapsed".
    if (stats.input_triangles == 0) throw Error(flags->input, {}, "the mesh has no faces");
    const std::uint64_t input_bytes = stream->bytes_total();
    const Box3 box = stream->bounds();
    stream.reset();    // its vertex array is scratch now; free it before writing
    HeldCommits held;  // the mesh appears once the report and summary are out (see publish)
    const auto write_start = std::chrono::steady_clock::now();
    WriteOptions write;
    write.ascii = flags->ascii;
    write.progress = progress;
    write_result(flags->output, result.mesh, write);
    const double write_seconds = seconds_since(write_start);
    const double total_seconds = seconds_since(start);
    warn_if_over_memory_limit(console, memory_limit);

    if (!flags->report.empty()) {
      nlohmann::json report;
      report["input"] = {{"file", flags->input},
                         {"bytes", input_bytes},
                         {"vertices", out_of_core ? file_vertices : stats.input_vertices},
                         {"faces", stats.input_triangles}};
      // Clusters no face uses are written only where the octree's vertex target counts them or no face is
      // left; otherwise they are left out, and saying so under "output" read as vertices of the file.
      const bool kept = (options.octree && options.target_vertices > 0) || stats.output_faces == 0;
      report["output"] = {{"file", flags->output},
                          {"vertices", stats.output_vertices},
                          {"faces", stats.output_faces},
                          {"isolated_vertices", kept ? stats.isolated_vertices : 0}};
      // The grid and cell size asked for, null where a target chose the cells (those used are under "cells").
      const bool given = planned_fine_cells(options) == 0;
      const bool by_size = given && options.cell_size > 0, by_grid = given && !by_size;
      report["options"] = {
          {"mode", options.octree ? "octree" : "grid"},
          {"grid", by_grid ? nlohmann::json(options.grid) : nlohmann::json(nullptr)},
          {"cell_size", by_size ? nlohmann::json(options.cell_size) : nlohmann::json(nullptr)},
          {"target_faces", options.target_faces},
          {"target_vertices", options.target_vertices},
          {"representative", representative_name(options.representative)},
          {"boundary", options.preserve_boundary},
          {"boundary_weight", options.boundary_weight},
          {"threads", options.threads}};
      report["cells"] = {
          {"fine", stats.fine_cells},         {"fine_grid", stats.fine_grid},
          {"spanned", stats.spanned_cells},   {"fine_cell_size", stats.fine_cell_size},
          {"output", stats.output_vertices},  {"left_out_without_faces", kept ? 0 : stats.isolated_vertices},
          {"output_grid", stats.output_grid}, {"output_cell_size", stats.output_cell_size}};
      report["triangles"] = {{"in", stats.input_triangles},
                             {"collapsed_in_fine_cells", stats.collapsed_triangles},
                             {"repeated_fine_cells", stats.duplicate_triangles},
                             {"out", stats.output_faces}};
      report["target_met"] = stats.target_met;
      report["out_of_core"] = out_of_core;
      report["seconds"] = {{"open", open_seconds},
                           {"cluster", stats.seconds},
                           {"write", write_seconds},
                           {"total", total_seconds}};
      report["triangles_per_second"] =
          total_seconds > 0 ? static_cast<double>(stats.input_triangles) / total_seconds : 0.0;
      report["peak_rss_bytes"] = peak_rss_bytes();
      write_json_report(flags->report, report);
    }
    // A grid spans the bounding box of every vertex, used or not (the box is known before the faces are
    // read): an outlier no face uses left the faces in a few cells, bunny --grid 100 a single one without a
    // word, and a far one keeps even the finest grid (2^21 cells along the box) from a target. Compared with
    // the grid the pass used, not the one asked for: a box of one point is a single cell whatever the --grid,
    // and no vertex stretches it; parts far apart span the box, and get no such hint either.
    const bool one_point = !box.empty() && box.lo == box.hi;
    const bool stretched = !one_point && 2 * std::uint64_t{stats.spanned_cells} < stats.fine_grid;
    // On the finest grid there is (ClusterOptions::grid's limit of 2^21 cells along the box) no --cell-size
    // helps: a UTM-placed scan with one unused vertex at the origin kept a single cell.
    const bool finest = stats.fine_grid >= (1u << 21);
    const std::string stretch = std::string("vertices no face uses stretch the bounding box") +
                                (finest ? ", and no grid is finer; simplify decimates such an input in core"
                                 : options.octree ? ""
                                                  : "; --cell-size sets the cells' size directly");
    if (stretched && options.grid > 0 && !(options.cell_size > 0) && !options.octree &&
        options.target_faces == 0) {
      console.warn("the faces span only " + std::to_string(stats.spanned_cells) + " of the " +
                   std::to_string(options.grid) + " cells of " +
                   (grid->count() > 0 ? "--grid " : "the default --grid ") + std::to_string(options.grid) +
                   ": " + stretch);
    }
    // A face target can miss with cells to spare: a face whose corners share a cell collapses, and a part
    // thinner than the cells (a strip 1000 long and 0.01 wide) loses them all, on a fine grid chosen for
    // its cells before any face was read.
    const bool faces_collapsed = options.target_faces > 0 && stats.fine_cells >= options.target_faces;
    if (!stats.target_met && faces_collapsed) {
      char size[32];
      std::snprintf(size, sizeof size, "%.3g", stats.fine_cell_size);
      console.warn("the face target was not reached: the fine grid's " + std::to_string(stats.fine_cells) +
                   " cells, " + size +
                   " wide, keep few of the faces (a face whose corners share a cell collapses, and parts "
                   "thinner than a cell lose all theirs); --cell-size or --grid sets smaller cells");
    } else if (!stats.target_met && stats.fine_cells <= 1 && !stretched) {
      // Not a stretched box: a box of one point spans one cell of every grid.
      console.warn(std::string("the ") + (flags->vertices ? "vertex" : "face") +
                   " target was not reached: every vertex lies in one cell of the finest grid (the input has "
                   "no extent to cluster)");
    } else if (!stats.target_met) {
      std::string note = std::string("the ") + (flags->vertices ? "vertex" : "face") +
                         " target was not reached (the finest grid has " + std::to_string(stats.fine_cells) +
                         (stats.fine_cells == 1 ? " cell" : " cells");
      if (stretched) {
        note += ", and the faces span only " + std::to_string(stats.spanned_cells) + " of its " +
                std::to_string(stats.fine_grid) + " along the box: " + stretch;
      }
      console.warn(note + ")");
    }
    if (show_summary(flags->quiet, flags->report)) {
      std::printf(
          "%s: %llu triangles -> %llu vertices, %llu faces (%llu fine cells) in %.2f s, peak RSS %s\n",
          flags->input.c_str(), static_cast<unsigned long long>(stats.input_triangles),
          static_cast<unsigned long long>(stats.output_vertices),
          static_cast<unsigned long long>(stats.output_faces),
          static_cast<unsigned long long>(stats.fine_cells), total_seconds,
          format_bytes(peak_rss_bytes()).c_str());
    }
    publish(held);
  });
}

}  // namespace ocsimp::cli
