#include "ocsimp/tools/bench_methods.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "ocsimp/core/error.h"
#include "ocsimp/decimate/decimate.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/generate.h"
#include "test_support.h"

namespace ocsimp {
namespace {

// A closed generated scan, written to a file because `two-stage` runs the pipeline on one.
BenchInput generated_input(const test::TempDir& dir, std::uint64_t triangles) {
  GenerateOptions options;
  options.triangles = triangles;
  options.seed = 11;
  BenchInput input;
  input.name = "scan";
  input.path = dir / "scan.ply";
  generate_scan_ply(input.path, options);
  input.mesh = read_mesh(input.path);
  return input;
}

BenchOptions quick_options() {
  BenchOptions options;
  options.repeat = 1;
  options.compare.samples = 20'000;
  return options;
}

void expect_sane_distance(const BenchResult& r) {
  ASSERT_TRUE(r.distance.has_value()) << bench_method_name(r.method);
  const SurfaceDistance& d = *r.distance;
  for (double v : {d.hausdorff, d.mean, d.rms, d.forward.rms, d.backward.rms}) {
    EXPECT_TRUE(std::isfinite(v)) << bench_method_name(r.method);
    EXPECT_GE(v, 0.0) << bench_method_name(r.method);
  }
  // Over one sample set the largest distance bounds the RMS, which bounds the mean (Jensen).
  EXPECT_GE(d.hausdorff, d.rms) << bench_method_name(r.method);
  EXPECT_GE(d.rms, d.mean) << bench_method_name(r.method);
  EXPECT_GT(d.diagonal, 0.0);
  // A simplification to a tenth of the faces stays close to the surface: well under a tenth of the diagonal.
  EXPECT_LT(d.percent(d.rms), 10.0) << bench_method_name(r.method);
}

TEST(BenchMethods, NamesRoundTripAndUnknownNamesAreRejected) {
  for (BenchMethod method : available_bench_methods()) {
    EXPECT_EQ(parse_bench_method(bench_method_name(method)), method);
  }
  EXPECT_THROW(parse_bench_method("qslim"), Error);
  EXPECT_EQ(available_bench_methods().size(), bench_has_meshoptimizer() ? 7u : 5u);
  if (!bench_has_meshoptimizer()) {
    EXPECT_THROW(parse_bench_method("meshopt"), Error);
  }
}

TEST(BenchMethods, EveryMethodReachesWhatItPromises) {
  test::TempDir dir;
  const BenchInput input = generated_input(dir, 20'000);
  const DistanceIndex original(input.mesh, "scan");
  const std::uint64_t target = 2'000;
  BenchOptions options = quick_options();
  options.repeat = 2;
  for (BenchMethod method : available_bench_methods()) {
    SCOPED_TRACE(bench_method_name(method));
    const BenchResult r = run_bench_method(input, original, method, target, 0.1, options);
    EXPECT_EQ(r.method, method);
    EXPECT_EQ(r.input_faces, input.mesh.face_count());
    EXPECT_EQ(r.target_faces, target);
    EXPECT_EQ(r.run_seconds.size(), 2u);
    EXPECT_GE(r.seconds, *std::min_element(r.run_seconds.begin(), r.run_seconds.end()));
    EXPECT_LE(r.seconds, *std::max_element(r.run_seconds.begin(), r.run_seconds.end()));
    EXPECT_GT(r.vertices, 0u);
    switch (method) {
      case BenchMethod::decimate:
      case BenchMethod::two_stage:
        // Exact, or one below where a closed manifold's parity forbids the count.
        EXPECT_LE(r.faces, target);
        EXPECT_GE(r.faces, target - 1);
        break;
      default:
        // Face-target modes of the clusterers and meshoptimizer: never above; a sane count is within a factor
        // of two (the uniform grid steps its resolution, sloppy clustering its cell size).
        EXPECT_LE(r.faces, target);
        EXPECT_GE(r.faces, target / 2);
        break;
    }
    // Euler: a surface of F triangles has about F / 2 vertices; the output's are the ones its faces use.
    EXPECT_LE(r.vertices, 3 * r.faces);
    expect_sane_distance(r);
#ifdef __linux__
    EXPECT_TRUE(r.peak_bytes.has_value());
#endif
  }
}

TEST(BenchMethods, QuadricGridBeatsMeanGridOnASphere) {
  // On a convex surface every cell's mean lies inside it (the chord sags), while the quadric's minimizer
  // sits on the tangent planes: at the same cells, the quadric representative is closer.
  BenchInput input;
  input.name = "sphere";
  input.mesh = test::sphere(6, 1.0f);  // 32,768 faces
  const DistanceIndex original(input.mesh, "sphere");
  for (std::uint64_t target : {500u, 3'000u}) {
    SCOPED_TRACE(target);
    const BenchResult mean =
        run_bench_method(input, original, BenchMethod::grid_mean, target, 0, quick_options());
    const BenchResult quadric =
        run_bench_method(input, original, BenchMethod::grid_quadric, target, 0, quick_options());
    ASSERT_TRUE(mean.distance && quadric.distance);
    // Both see the same cells: the representative does not decide which cells are occupied.
    EXPECT_EQ(mean.faces, quadric.faces);
    EXPECT_LT(quadric.distance->rms, 0.5 * mean.distance->rms);
  }
}

TEST(BenchMethods, TwoStageNeedsAFile) {
  BenchInput input;
  input.name = "sphere";
  input.mesh = test::sphere(3);
  const DistanceIndex original(input.mesh);
  EXPECT_THROW(run_bench_method(input, original, BenchMethod::two_stage, 100, 0, quick_options()), Error);
  EXPECT_THROW(run_bench_method(input, original, BenchMethod::decimate, 0, 0, quick_options()), Error);
}

TEST(BenchMethods, TablesHaveARowPerMethodAndTarget) {
  test::TempDir dir;
  const BenchInput input = generated_input(dir, 12'000);
  const std::vector<BenchMethod> methods = available_bench_methods();
  const std::vector<double> ratios = {0.1, 0.02};
  std::vector<std::uint64_t> targets;
  for (double ratio : ratios) targets.push_back(ratio_target(ratio, input.mesh.face_count()));
  std::size_t reported = 0;
  BenchOptions options = quick_options();
  options.on_result = [&](const BenchResult&) { ++reported; };
  const std::vector<BenchResult> results = run_bench(input, methods, targets, ratios, options);
  ASSERT_EQ(results.size(), methods.size() * targets.size());
  EXPECT_EQ(reported, results.size());

  // Markdown: a header, a separator, then one row per (target, method), each pair exactly once.
  std::istringstream table(bench_markdown_table(results));
  std::string line;
  std::vector<std::string> rows;
  while (std::getline(table, line)) rows.push_back(line);
  ASSERT_EQ(rows.size(), 2 + results.size());
  EXPECT_EQ(rows[0].rfind(
                "| mesh | target | method | faces | seconds | RMS % diag | Hausdorff % diag | peak MiB |", 0),
            0u);
  std::map<std::pair<std::string, std::string>, int> seen;
  for (std::size_t i = 2; i < rows.size(); ++i) {
    std::vector<std::string> cells;
    std::istringstream row(rows[i]);
    std::string cell;
    std::getline(row, cell, '|');  // before the first bar
    while (std::getline(row, cell, '|')) cells.push_back(cell.substr(1, cell.size() - 2));
    ASSERT_EQ(cells.size(), 8u) << rows[i];
    EXPECT_EQ(cells[0], "scan");
    ++seen[{cells[1], cells[2]}];
  }
  for (const char* target : {"10 %", "2 %"}) {
    for (BenchMethod method : methods) EXPECT_EQ((seen[{target, bench_method_name(method)}]), 1) << target;
  }
  // A label with a bar or a line break stays in its cell and its row (it split both).
  std::vector<BenchResult> labelled(results.begin(), results.begin() + 1);
  labelled[0].mesh = "a|b\nc";
  const std::string one_row = bench_markdown_table(labelled);
  EXPECT_EQ(std::count(one_row.begin(), one_row.end(), '\n'), 3);
  EXPECT_NE(one_row.find("| a\\|b c |"), std::string::npos) << one_row;

  // CSV: a header and one line per result. JSON: one object per result with the numbers the plots read.
  std::istringstream csv(bench_csv(results));
  std::size_t csv_lines = 0;
  while (std::getline(csv, line)) ++csv_lines;
  EXPECT_EQ(csv_lines, 1 + results.size());
  const nlohmann::json json = nlohmann::json::parse(bench_json(results, options));
  ASSERT_EQ(json["results"].size(), results.size());
  for (std::size_t i = 0; i < results.size(); ++i) {
    const nlohmann::json& row = json["results"][i];
    EXPECT_EQ(row["method"], bench_method_name(results[i].method));
    EXPECT_EQ(row["faces"].get<std::uint64_t>(), results[i].faces);
    EXPECT_DOUBLE_EQ(row["distance"]["rms_percent"].get<double>(),
                     results[i].distance->percent(results[i].distance->rms));
  }
}

}  // namespace
}  // namespace ocsimp
