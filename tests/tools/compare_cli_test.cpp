// `ocsimp compare` end to end: its numbers are the library's, repeat across thread counts, and bad input
// fails with one line.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/compare.h"
#include "test_support.h"

namespace ocsimp {
namespace {

using test::run_ocsimp;

TEST(CompareCli, JsonCarriesTheLibraryNumbersForAnyThreadCount) {
  test::TempDir dir;
  const IndexedMesh original = test::sphere(4);
  IndexedMesh simplified = test::sphere(2);
  for (Vec3f& p : simplified.positions) p.x() += 0.01f;
  write_mesh(dir / "original.ply", original);
  write_mesh(dir / "simplified.ply", simplified);
  const std::string args =
      "compare --json --samples 30000 --seed 9 " + (dir / "original.ply") + " " + (dir / "simplified.ply");
  const test::CommandResult one = run_ocsimp(args + " --threads 1", dir);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const test::CommandResult two = run_ocsimp(args + " --threads 2", dir);
  ASSERT_EQ(two.exit_code, 0) << two.err;
  EXPECT_EQ(one.out, two.out);

  CompareOptions options;
  options.samples = 30000;
  options.seed = 9;
  const SurfaceDistance d =
      measure_distance(read_mesh(dir / "original.ply"), read_mesh(dir / "simplified.ply"), options);
  const nlohmann::json j = nlohmann::json::parse(one.out);
  // JSON numbers round-trip doubles exactly.
  EXPECT_EQ(j["hausdorff"].get<double>(), d.hausdorff);
  EXPECT_EQ(j["mean"].get<double>(), d.mean);
  EXPECT_EQ(j["rms"].get<double>(), d.rms);
  EXPECT_EQ(j["diagonal"].get<double>(), d.diagonal);
  EXPECT_EQ(j["forward"]["hausdorff"].get<double>(), d.forward.hausdorff);
  EXPECT_EQ(j["forward"]["rms"].get<double>(), d.forward.rms);
  EXPECT_EQ(j["backward"]["mean"].get<double>(), d.backward.mean);
  EXPECT_EQ(j["backward"]["hausdorff_bound"].get<double>(), d.backward.hausdorff_bound);
  EXPECT_GE(d.backward.hausdorff_bound, d.backward.hausdorff);
  EXPECT_EQ(j["backward"]["samples"].get<std::size_t>(), 30000u);
  EXPECT_EQ(j["forward"]["vertex_samples"].get<std::size_t>(), original.vertex_count());
  EXPECT_DOUBLE_EQ(j["rms_percent"].get<double>(), 100 * d.rms / d.diagonal);
  EXPECT_GT(d.hausdorff, 0.01);  // the shift alone

  const test::CommandResult table = run_ocsimp(
      "compare -q --samples 30000 --seed 9 " + (dir / "original.ply") + " " + (dir / "simplified.ply"), dir);
  ASSERT_EQ(table.exit_code, 0) << table.err;
  for (const char* row : {"forward", "backward", "symmetric", "Hausdorff", "RMS"})
    EXPECT_NE(table.out.find(row), std::string::npos) << row;
}

// An original that is a single point has no diagonal to take a share of: the percentages are n/a (null in
// the JSON), not the 0 % they printed beside distances of 1.7.
TEST(CompareCli, PercentagesOfAPointAreNotAvailable) {
  test::TempDir dir;
  std::ofstream(dir / "point.obj") << "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n";
  std::ofstream(dir / "triangle.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  const std::string args = " --samples 100 " + (dir / "point.obj") + " " + (dir / "triangle.obj");
  const test::CommandResult json = run_ocsimp("compare --json" + args, dir);
  ASSERT_EQ(json.exit_code, 0) << json.err;
  const nlohmann::json j = nlohmann::json::parse(json.out);
  EXPECT_EQ(j["diagonal"].get<double>(), 0.0);
  EXPECT_GT(j["hausdorff"].get<double>(), 1.0);
  for (const nlohmann::json& part : {j, j["forward"], j["backward"]}) {
    for (const char* field : {"hausdorff_percent", "mean_percent", "rms_percent"})
      EXPECT_TRUE(part[field].is_null()) << field;
  }
  const test::CommandResult table = run_ocsimp("compare -q" + args, dir);
  ASSERT_EQ(table.exit_code, 0) << table.err;
  EXPECT_NE(table.out.find("n/a"), std::string::npos) << table.out;
  EXPECT_EQ(table.out.find("0.0000%"), std::string::npos) << table.out;
}

TEST(CompareCli, HelpShowsDefaultsAndBadInputFailsWithOneLine) {
  test::TempDir dir;
  const test::CommandResult help = run_ocsimp("compare --help", dir);
  EXPECT_EQ(help.exit_code, 0);
  for (const char* text : {"--samples", "1000000", "--seed", "--json", "--no-vertices", "--threads"})
    EXPECT_NE(help.out.find(text), std::string::npos) << text;

  write_mesh(dir / "square.ply", test::grid_square(2));
  const test::CommandResult unknown =
      run_ocsimp("compare --no-such-flag " + (dir / "square.ply") + " " + (dir / "square.ply"), dir);
  EXPECT_EQ(unknown.exit_code, 2);

  const test::CommandResult missing =
      run_ocsimp("compare " + (dir / "square.ply") + " " + (dir / "nope.ply"), dir);
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("nope.ply"), std::string::npos);
  EXPECT_EQ(std::count(missing.err.begin(), missing.err.end(), '\n'), 1) << missing.err;

  // A mesh with vertices and no faces reads fine but has no surface to measure.
  std::ofstream(dir / "points.ply")
      << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nelement face 0\nproperty list uchar int vertex_indices\n"
         "end_header\n0 0 0\n1 0 0\n0 1 0\n";
  const test::CommandResult empty =
      run_ocsimp("compare " + (dir / "square.ply") + " " + (dir / "points.ply"), dir);
  EXPECT_EQ(empty.exit_code, 2);
  EXPECT_NE(empty.err.find("points.ply"), std::string::npos) << empty.err;
  EXPECT_EQ(std::count(empty.err.begin(), empty.err.end(), '\n'), 1) << empty.err;
}

}  // namespace
}  // namespace ocsimp
