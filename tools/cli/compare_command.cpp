// ocsimp compare: Metro-style distance between an original mesh and its simplification.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>

#include "commands.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/compare.h"

namespace ocsimp::cli {
namespace {

// A percentage of the original's diagonal for the table; n/a where the original is a point (it printed 0 %
// for distances of 1.7).
std::string percent_text(const SurfaceDistance& all, double distance) {
  const double percent = all.percent(distance);
  char text[32];
  if (std::isnan(percent))
    std::snprintf(text, sizeof text, "%10s", "n/a");
  else
    std::snprintf(text, sizeof text, "%9.4f%%", percent);
  return text;
}

nlohmann::json one_sided_json(const OneSidedDistance& d, const SurfaceDistance& all) {
  return {{"hausdorff", d.hausdorff},
          {"mean", d.mean},
          {"rms", d.rms},
          {"hausdorff_percent", all.percent(d.hausdorff)},
          {"mean_percent", all.percent(d.mean)},
          {"rms_percent", all.percent(d.rms)},
          {"samples", d.samples},
          {"vertex_samples", d.vertex_samples},
          {"farthest", {d.farthest.x(), d.farthest.y(), d.farthest.z()}},
          // null when nothing was refined (--no-vertices)
          {"hausdorff_bound", std::isfinite(d.hausdorff_bound) ? nlohmann::json(d.hausdorff_bound) : nullptr},
          {"hausdorff_settled", d.hausdorff_settled}};
}

// Says so when a refinement ran out of queries before pinning the Hausdorff distance down (see compare.h).
void print_bound(const char* label, const OneSidedDistance& d) {
  if (std::isfinite(d.hausdorff_bound) && !d.hausdorff_settled)
    std::printf("%s Hausdorff: refinement stopped at its query budget; the true distance is at most %.6g\n",
                label, d.hausdorff_bound);
}

void print_row(const char* label, double hausdorff, double mean, double rms, const SurfaceDistance& all) {
  std::printf("  %-10s %12.6g %s  %12.6g %s  %12.6g %s\n", label, hausdorff,
              percent_text(all, hausdorff).c_str(), mean, percent_text(all, mean).c_str(), rms,
              percent_text(all, rms).c_str());
}

}  // namespace

void add_compare_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "compare",
      "Measure how far a simplified mesh is from its original: Hausdorff, mean and RMS distance both ways "
      "(area-uniform samples plus vertices, exact closest points, the Hausdorff distance refined to within "
      "0.01 % or, where that does not settle, given with an upper bound), also as % of the original's "
      "diagonal");
  struct Flags {
    std::string original;
    std::string simplified;
    CompareOptions options;
    bool no_vertices = false;
    bool json = false;
    std::string report;
    int threads = 0;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  cmd->add_option("original", flags->original, "The original mesh (PLY, OBJ, STL or Draco)")->required();
  cmd->add_option("simplified", flags->simplified, "The simplified mesh")->required();
  cmd->add_option("--samples", flags->options.samples, "Area-uniform samples in each direction")
      ->capture_default_str()
      ->transform(whole_number(0, 1'000'000'000));
  cmd->add_option("--seed", flags->options.seed, "Sampling seed (same seed, same numbers)")
      ->capture_default_str()
      ->transform(whole_number(0));
  cmd->add_flag(
      "--no-vertices", flags->no_vertices,
      "Do not also measure every vertex, nor refine the Hausdorff distance from them: it is then the "
      "largest over the area samples (vertices only raise the Hausdorff distance, but for a side of no "
      "area samples, with --samples 0 or no area, whose averages are over its vertices)");
  cmd->add_flag("--json", flags->json, "Print one JSON object instead of a table");
  cmd->add_option("--report", flags->report, "Also write the JSON, with timing, to this file")
      ->check(file_name());
  cmd->add_option("--threads", flags->threads, "Threads (0 = all cores); the numbers do not depend on it")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress bar");
  cmd->callback([flags] {
    const auto start = std::chrono::steady_clock::now();
    if (!flags->report.empty()) check_report_destination(flags->report, {flags->original, flags->simplified});
    // 140 bytes a face of the original at peak on gen 4 M (its mesh and search index).
    check_whole_mesh_fits({flags->original, flags->simplified}, 125,
                          "compare holds each mesh and its search index", "");
    const auto limit = limit_threads(flags->threads);
    const ProgressFn progress = make_progress(flags->quiet);
    CompareOptions options = flags->options;
    options.include_vertices = !flags->no_vertices;
    options.progress = progress;
    ReadOptions read;
    read.progress = progress;

    // Each mesh is dropped once its index holds a copy: for a 10 M-triangle original that is 180 MB less.
    struct Counts {
      std::size_t vertices = 0, faces = 0;
    };
    auto load = [&](const std::string& path, Counts& counts) {
      const IndexedMesh mesh = read_mesh(path, read);
      counts = {mesh.vertex_count(), mesh.face_count()};
      report(progress, "index", 0, mesh.face_count());
      DistanceIndex index(mesh, path);
      report(progress, "index", mesh.face_count(), mesh.face_count());
      return index;
    };
    Counts original, simplified;
    const DistanceIndex original_index = load(flags->original, original);
    const DistanceIndex simplified_index = load(flags->simplified, simplified);
    const SurfaceDistance d = measure_distance(original_index, simplified_index, options);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

    nlohmann::json out;
    out["original"] = {{"file", flags->original}, {"vertices", original.vertices}, {"faces", original.faces}};
    out["simplified"] = {
        {"file", flags->simplified}, {"vertices", simplified.vertices}, {"faces", simplified.faces}};
    out["samples"] = options.samples;
    out["seed"] = options.seed;
    out["include_vertices"] = options.include_vertices;
    out["diagonal"] = d.diagonal;
    out["hausdorff"] = d.hausdorff;
    out["mean"] = d.mean;
    out["rms"] = d.rms;
    out["hausdorff_percent"] = d.percent(d.hausdorff);
    out["mean_percent"] = d.percent(d.mean);
    out["rms_percent"] = d.percent(d.rms);
    out["forward"] = one_sided_json(d.forward, d);
    out["backward"] = one_sided_json(d.backward, d);
    HeldCommits held;  // the report appears once the table is out (see publish)
    if (!flags->report.empty()) {
      nlohmann::json report = out;
      report["seconds"] = seconds;
      report["peak_rss_bytes"] = peak_rss_bytes();
      write_json_report(flags->report, report);
    }
    // The report is then the output: the table, or --json's copy of the same fields, would follow it.
    const bool report_out = is_standard_output(flags->report);
    if (flags->json && !report_out) {
      std::printf("%s\n", json_text(out).c_str());
    } else if (!report_out) {
      std::printf("original    %s: %zu vertices, %zu faces, bounding-box diagonal %g\n",
                  flags->original.c_str(), original.vertices, original.faces, d.diagonal);
      std::printf("simplified  %s: %zu vertices, %zu faces\n", flags->simplified.c_str(), simplified.vertices,
                  simplified.faces);
      std::printf("samples     forward %zu + %zu vertices, backward %zu + %zu vertices, seed %llu\n\n",
                  d.forward.samples, d.forward.vertex_samples, d.backward.samples, d.backward.vertex_samples,
                  static_cast<unsigned long long>(options.seed));
      std::printf("  %-10s %23s  %23s  %23s\n", "", "Hausdorff   (% diag)", "mean   (% diag)",
                  "RMS   (% diag)");
      print_row("forward", d.forward.hausdorff, d.forward.mean, d.forward.rms, d);
      print_row("backward", d.backward.hausdorff, d.backward.mean, d.backward.rms, d);
      print_row("symmetric", d.hausdorff, d.mean, d.rms, d);
      std::printf(
          "\nforward: from the original's surface to the simplified one; backward: the reverse. Symmetric: "
          "max of the\nHausdorff distances, average of the means, RMS = sqrt((forward^2 + backward^2) / "
          "2).\n");
      print_bound("forward", d.forward);
      print_bound("backward", d.backward);
      if (!flags->quiet) std::fprintf(stderr, "measured in %.2f s\n", seconds);
    }
    publish(held);
  });
}

}  // namespace ocsimp::cli
