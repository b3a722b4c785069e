// The `ocsimp` binary end to end: exit codes, one-line errors, atomic outputs, determinism of `gen`.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "ocsimp/core/system.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/compare.h"
#include "test_support.h"

namespace ocsimp {
namespace {

const std::string kOcsimp = std::string(OCSIMP_BINARY_DIR) + "/bin/ocsimp";

struct CommandResult {
  int exit_code = -1;
  std::string out, err;
};

// Runs ocsimp with `args` (a shell-quoted string), capturing stdout and stderr.
CommandResult run(const std::string& args, const test::TempDir& dir) {
  const std::string out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string command = kOcsimp + " " + args + " >" + out + " 2>" + err;
  const int status = std::system(command.c_str());
  CommandResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  auto slurp = [](const std::string& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  };
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

std::string file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::size_t lines(const std::string& text) {
  std::size_t n = 0;
  for (char c : text) n += c == '\n';
  return n;
}

TEST(Cli, HelpListsEveryCommandAndFlagDefaults) {
  test::TempDir dir;
  const CommandResult top = run("--help", dir);
  EXPECT_EQ(top.exit_code, 0);
  for (const char* command : {"info", "convert", "gen"})
    EXPECT_NE(top.out.find(command), std::string::npos) << command;
  const CommandResult gen = run("gen --help", dir);
  EXPECT_EQ(gen.exit_code, 0);
  EXPECT_NE(gen.out.find("--triangles"), std::string::npos);
  EXPECT_NE(gen.out.find("2000000"), std::string::npos);  // the default is shown
}

TEST(Cli, UnknownFlagIsAnError) {
  test::TempDir dir;
  const CommandResult r = run("info --no-such-flag x.ply", dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("no-such-flag"), std::string::npos);
  // A misspelt command is named as such (CLI11 said a command was missing).
  const CommandResult command = run("decimat x.ply", dir);
  EXPECT_EQ(command.exit_code, 2);
  EXPECT_EQ(command.err, "ocsimp: unknown command 'decimat' (see ocsimp --help)\n");
}

// A negative count used to pass as 2^64 - 3 (a silent no-op decimation), and bounds printed as "0.000000"
// or hundreds of digits.
TEST(Cli, BadNumbersSayWhatTheFlagTakes) {
  test::TempDir dir;
  const struct {
    const char* args;
    const char* message;
  } cases[] = {
      {"decimate in.ply -o out.ply --faces -3", "--faces: '-3' is not a whole number >= 1"},
      {"decimate in.ply -o out.ply --vertices 1.5", "--vertices: '1.5' is not a whole number >= 1"},
      {"simplify in.ply -o out.ply --faces -1", "--faces: '-1' is not a whole number >= 1"},
      {"decimate in.ply -o out.ply --ratio 0", "--ratio: '0' is not a number in (0, 1]"},
      {"decimate in.ply -o out.ply --max-error -1e-9",
       "--max-error: '-1e-9' is not a number >= 0 (inf: no bound)"},
      {"decimate in.ply -o out.ply --boundary-weight nan", "'nan' is not a finite number >= 0"},
      {"cluster in.ply -o out.ply --cell-size 0", "--cell-size: '0' is not a finite number > 0"},
      {"cluster in.ply -o out.ply --grid 10 --threads -1",
       "--threads: '-1' is not a whole number from 0 to 4096"},
      // A budget of nothing was taken as the default (a third of RAM).
      {"simplify in.ply -o out.ply --faces 10 --memory-limit 0", "--memory-limit: '0' is less than a byte"},
      {"lod in.ply -o out.ply --faces 10 --memory-limit 0.5",
       "--memory-limit: not a size: '0.5' (a fraction of a byte"},
      // Hexadecimal, which strtod reads (16 and 1/8 here), as the integer flags and the readers refuse it.
      {"cluster in.ply -o out.ply --cell-size 0x10", "--cell-size: '0x10' is not a finite number > 0"},
      {"decimate in.ply -o out.ply --ratio 0x1p-3", "--ratio: '0x1p-3' is not a number in (0, 1]"},
  };
  for (const auto& c : cases) {
    const CommandResult r = run(c.args, dir);
    EXPECT_EQ(r.exit_code, 2) << c.args;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << c.args << "\n" << r.err;
    EXPECT_EQ(r.err.find("0.000000"), std::string::npos) << r.err;
    // One line, like every other error, naming the command whose help lists the flags.
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_EQ(r.err.rfind("ocsimp: ", 0), 0u) << r.err;
    const std::string command = std::string(c.args).substr(0, std::string(c.args).find(' '));
    EXPECT_NE(r.err.find("(see ocsimp " + command + " --help)"), std::string::npos) << r.err;
  }
}

// Whole numbers are decimal whatever their leading zeros: CLI11 read "010" as octal 8, and refused "09".
TEST(Cli, WholeNumbersWithLeadingZerosAreDecimal) {
  test::TempDir dir;
  const std::string mesh = dir / "square.ply", out = dir / "out.ply";
  write_mesh(mesh, test::grid_square(8));  // 128 faces, open: every count is reachable
  for (const auto& [faces, expected] : {std::pair{"010", 10u}, {"09", 9u}, {"0100", 100u}}) {
    const CommandResult r = run("decimate -q " + mesh + " -o " + out + " --faces " + faces, dir);
    ASSERT_EQ(r.exit_code, 0) << faces << "\n" << r.err;
    EXPECT_EQ(read_mesh(out).face_count(), expected) << faces;
  }
  const CommandResult r = run("cluster -q " + mesh + " -o " + out + " --octree --vertices 010", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_mesh(out).vertex_count(), 10u);
}

TEST(Cli, TargetsThatContradictEachOtherAreRefused) {
  test::TempDir dir;
  const std::string mesh = dir / "sphere.ply";
  write_mesh(mesh, test::sphere(2));
  for (const char* command : {"decimate", "simplify"}) {
    // Two face targets: one used to win silently.
    const CommandResult both =
        run(std::string(command) + " " + mesh + " -o " + (dir / "out.ply") + " --faces 10 --ratio 0.5", dir);
    EXPECT_EQ(both.exit_code, 2) << both.err;
    EXPECT_NE(both.err.find("--faces excludes --ratio"), std::string::npos) << both.err;
    // An infinite error bound is no target by itself.
    const CommandResult unbounded =
        run(std::string(command) + " " + mesh + " -o " + (dir / "out.ply") + " --max-error inf", dir);
    EXPECT_EQ(unbounded.exit_code, 2) << unbounded.err;
    EXPECT_NE(unbounded.err.find("a finite --max-error E"), std::string::npos) << unbounded.err;
    EXPECT_FALSE(std::filesystem::exists(dir / "out.ply"));
  }
}

TEST(Cli, GenIsDeterministicAndInfoCountsIt) {
  test::TempDir dir;
  ASSERT_EQ(run("gen -q -o " + (dir / "a.ply") + " --triangles 20000 --seed 3", dir).exit_code, 0);
  ASSERT_EQ(run("gen -q -o " + (dir / "b.ply") + " --triangles 20000 --seed 3 --threads 1", dir).exit_code,
            0);
  ASSERT_EQ(run("gen -q -o " + (dir / "c.ply") + " --triangles 20000 --seed 4", dir).exit_code, 0);
  EXPECT_EQ(file_bytes(dir / "a.ply"), file_bytes(dir / "b.ply"));
  EXPECT_NE(file_bytes(dir / "a.ply"), file_bytes(dir / "c.ply"));

  const CommandResult info = run("info --json " + (dir / "a.ply"), dir);
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json j = nlohmann::json::parse(info.out);
  ASSERT_TRUE(j["vertices"].is_number_integer());
  ASSERT_TRUE(j["faces"].is_number_integer());
  const long n = std::lround(std::sqrt(20000.0 / 12.0));
  EXPECT_EQ(j["faces"].get<long>(), 12 * n * n);
  EXPECT_EQ(j["vertices"].get<long>(), 6 * n * n + 2);
  EXPECT_EQ(j["boundary_edges"].get<long>(), 0);
  EXPECT_EQ(j["components"].get<long>(), 1);
}

// A face of three distinct corners at collinear or coincident positions spans no area, which "degenerate
// faces" (a repeated corner index) did not count: a Draco file quantized to 1 bit read as 0 degenerate faces.
TEST(Cli, InfoCountsZeroAreaFacesApartFromRepeatedCorners) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(2);  // 9 vertices, 8 faces
  mesh.positions.push_back({0.5f, 0.5f, 0.0f});
  mesh.positions.push_back({2.0f, 2.0f, 0.0f});
  mesh.triangles.push_back({0, 9, 10});  // on the diagonal y = x
  mesh.triangles.push_back({4, 9, 9});   // a repeated corner
  mesh.triangles.push_back({4, 9, 0});   // corners 4 and 9 coincide
  write_mesh(dir / "m.ply", mesh);
  const CommandResult info = run("info --json " + (dir / "m.ply"), dir);
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json j = nlohmann::json::parse(info.out);
  EXPECT_EQ(j["degenerate_faces"].get<long>(), 1);
  EXPECT_EQ(j["zero_area_faces"].get<long>(), 2);
  const CommandResult text = run("info " + (dir / "m.ply"), dir);
  EXPECT_NE(text.out.find("  zero-area faces        2\n"), std::string::npos) << text.out;
}

// The box's sides are told apart however far from zero a float file lies: a 2-wide square at UTM northings
// printed as (499999, 4e+06, 0) .. (500001, 4e+06, 0).
TEST(Cli, InfoPrintsTheBoxWithTheDigitsItsExtentNeeds) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(2);
  for (Vec3f& p : mesh.positions) p = 2.0f * p + Vec3f(499999.0f, 4000001.0f, 0.0f);
  write_mesh(dir / "far.stl", mesh);
  const CommandResult text = run("info " + (dir / "far.stl"), dir);
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("  bounding box           (499999, 4000001, 0) .. (500001, 4000003, 0)\n"),
            std::string::npos)
      << text.out;
  // Near zero, six digits as before.
  write_mesh(dir / "near.ply", test::grid_square(3));
  EXPECT_NE(
      run("info " + (dir / "near.ply"), dir).out.find("  bounding box           (0, 0, 0) .. (1, 1, 0)\n"),
      std::string::npos);
}

// A file of no vertex has no bounding box: the text said (inf, inf, inf) .. (-inf, -inf, -inf), where --json
// says null.
TEST(Cli, InfoOfAnEmptyMeshHasNoBoundingBox) {
  test::TempDir dir;
  std::ofstream(dir / "empty.ply")
      << ("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
          "element face 0\nproperty list uchar int vertex_indices\nend_header\n");
  const CommandResult text = run("info " + (dir / "empty.ply"), dir);
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("  bounding box           none (no vertex)\n"), std::string::npos) << text.out;
  EXPECT_EQ(text.out.find("inf"), std::string::npos) << text.out;
  const nlohmann::json j = nlohmann::json::parse(run("info --json " + (dir / "empty.ply"), dir).out);
  EXPECT_TRUE(j["bounding_box"]["min"][0].is_null());
}

// The pipeline plans within --memory-limit from measured bytes per cell, but a plan can come out short (a
// grid larger than planned): a 20 M-triangle scan to 1 M faces under 500M peaked at 633 MiB without a word.
// The run now says when its peak went over; no process fits in 1M, and every one in 4G.
TEST(Cli, SimplifyAndLodSayWhenTheirPeakMemoryWentOverTheLimit) {
  test::TempDir dir;
  const std::string in = dir / "in.ply";
  write_mesh(in, test::sphere(4));
  for (const std::string& command :
       {"simplify -q " + in + " -o " + (dir / "s.ply") + " --faces 100",
        "lod -q " + in + " -o " + (dir / "l_{faces}.ply") + " --faces 400,100"}) {
    const CommandResult tight = run(command + " --memory-limit 1M", dir);
    EXPECT_EQ(tight.exit_code, 0) << tight.err;
    EXPECT_NE(tight.err.find("in.ply: the run's peak memory, "), std::string::npos) << tight.err;
    EXPECT_NE(tight.err.find(", went over the memory limit of 1.0 MiB\n"), std::string::npos) << tight.err;
    const CommandResult roomy = run(command + " --memory-limit 4G", dir);
    EXPECT_EQ(roomy.exit_code, 0) << roomy.err;
    EXPECT_TRUE(roomy.err.empty()) << roomy.err;
  }
}

// A triangle soup (each face its own three vertices) decimates unwelded as separate triangles, each removed
// whole: simplify to 1 % of a 2 M-triangle soup wrote scattered triangles 32 % of the diagonal from the
// surface, with a max_error of 0.0012 and no word. Each command that decimates it directly with --no-weld
// says so once; by default it is welded.
TEST(Cli, DecimatingATriangleSoupSaysItFallsApart) {
  test::TempDir dir;
  const std::string soup = dir / "soup.ply", mesh = dir / "mesh.ply";
  write_mesh(soup, test::triangle_soup(test::sphere(3)));
  write_mesh(mesh, test::sphere(3));
  const std::vector<std::string> commands = {"decimate -q IN -o " + (dir / "d.ply") + " --faces 100",
                                             "simplify -q IN -o " + (dir / "s.ply") + " --faces 100",
                                             "lod -q IN -o " + (dir / "l_{faces}.ply") + " --faces 200,100"};
  for (const std::string& command : commands) {
    auto with = [&](const std::string& input) {
      std::string c = command;
      return c.replace(c.find("IN"), 2, input);
    };
    const CommandResult loose = run(with(soup) + " --no-weld", dir);
    EXPECT_EQ(loose.exit_code, 0) << loose.err;
    EXPECT_EQ(lines(loose.err), 1u) << command << "\n" << loose.err;
    EXPECT_NE(loose.err.find("soup.ply: 1536 of the 1536 vertices each belong to a single face"),
              std::string::npos)
        << loose.err;
    const CommandResult welded = run(with(soup) + " --weld", dir);
    EXPECT_TRUE(welded.err.empty()) << command << "\n" << welded.err;
    const CommandResult by_default = run(with(soup), dir);  // welding is the default
    EXPECT_TRUE(by_default.err.empty()) << command << "\n" << by_default.err;
    const CommandResult indexed = run(with(mesh), dir);
    EXPECT_TRUE(indexed.err.empty()) << command << "\n" << indexed.err;
  }
}

// Out of memory was "ocsimp: out of memory", naming no file. Under a 100 MB address-space limit a
// 1 M-triangle decimation (about 145 MB resident) cannot finish; the process gets as far as reading.
// AddressSanitizer reserves terabytes of address space up front, so under it the limit would stop the start.
TEST(Cli, OutOfMemoryNamesTheInputAndLeavesNoOutput) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "an address-space limit stops AddressSanitizer itself";
#endif
  test::TempDir dir;
  const std::string in = dir / "in.ply", out = dir / "out.ply", err = dir / "err.txt";
  ASSERT_EQ(run("gen -q --triangles 1000000 -o " + in, dir).exit_code, 0);
  const std::string command =
      "ulimit -v 100000; " + kOcsimp + " decimate -q " + in + " -o " + out + " --ratio 0.1 2>" + err;
  const int status = std::system(("bash -c '" + command + "'").c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3) << file_bytes(err);
  EXPECT_EQ(lines(file_bytes(err)), 1u) << file_bytes(err);
  EXPECT_EQ(file_bytes(err).rfind("ocsimp: " + in + ": out of memory in decimate (", 0), 0u)
      << file_bytes(err);
  EXPECT_FALSE(std::filesystem::exists(out));
}

// The default budget was a third of the machine's memory whatever `ulimit -v` allowed: a 3 M-triangle scan
// simplified under 400 MB of address space planned to decimate in core and ran out of memory (exit 3). The
// default is now half the address-space limit where that is less, and the run clusters first.
TEST(Cli, TheDefaultMemoryBudgetKeepsWithinUlimit) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "an address-space limit stops AddressSanitizer itself";
#endif
  test::TempDir dir;
  const std::string in = dir / "in.ply", out = dir / "out.ply", report = dir / "r.json",
                    err = dir / "err.txt";
  ASSERT_EQ(run("gen -q --triangles 3000000 -o " + in, dir).exit_code, 0);
  const std::string command = "ulimit -v 400000; " + kOcsimp + " simplify -q " + in + " -o " + out +
                              " --faces 10000 --report " + report + " 2>" + err;
  const int status = std::system(("bash -c '" + command + "'").c_str());
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 0) << file_bytes(err);
  const nlohmann::json r = nlohmann::json::parse(file_bytes(report));
  EXPECT_EQ(r["memory_limit_bytes"].get<std::uint64_t>(), 400000ull * 1024 / 2);
  EXPECT_TRUE(r["clustered"].get<bool>());
  EXPECT_EQ(r["output_faces"].get<std::uint64_t>(), 10000u);
  EXPECT_EQ(read_mesh(out).face_count(), 10000u);
}

// A cluster whose every triangle collapsed is left out of the file, and the report said so as the output's
// "isolated_vertices", which read as vertices of the file: it now counts them under the cells.
TEST(Cli, ClusterReportCountsClustersLeftOutApartFromTheOutput) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(8);
  const Index base = static_cast<Index>(mesh.positions.size());
  mesh.positions.insert(mesh.positions.end(),
                        {{0.5f, 0.5f, 1.0f}, {0.501f, 0.5f, 1.0f}, {0.5f, 0.501f, 1.0f}});
  mesh.triangles.push_back({base, base + 1, base + 2});  // a speck that collapses into one cell
  write_mesh(dir / "in.ply", mesh);
  const std::string out = dir / "out.ply", report = dir / "r.json";
  ASSERT_EQ(
      run("cluster -q " + (dir / "in.ply") + " -o " + out + " --grid 4 --report " + report, dir).exit_code,
      0);
  const nlohmann::json r = nlohmann::json::parse(file_bytes(report));
  EXPECT_EQ(r["output"]["vertices"].get<std::size_t>(), read_mesh(out).vertex_count());
  EXPECT_EQ(r["output"]["isolated_vertices"].get<long>(), 0);
  EXPECT_EQ(r["cells"]["left_out_without_faces"].get<long>(), 1);
  EXPECT_EQ(analyze_topology(read_mesh(out)).unreferenced_vertices, 0u);
  // The options say what was asked for: it reported the default grid (256) for a cell size or a face target.
  EXPECT_EQ(r["options"]["grid"].get<long>(), 4);
  EXPECT_TRUE(r["options"]["cell_size"].is_null());
  for (const std::string asked : {"--cell-size 0.25", "--faces 20"}) {
    ASSERT_EQ(run("cluster -q " + (dir / "in.ply") + " -o " + out + " " + asked + " --report " + report, dir)
                  .exit_code,
              0);
    const nlohmann::json j = nlohmann::json::parse(file_bytes(report));
    EXPECT_TRUE(j["options"]["grid"].is_null()) << asked;
    EXPECT_EQ(j["options"]["cell_size"].is_null(), asked != "--cell-size 0.25") << asked;
  }
}

// A textured mesh decimates with its seams kept: the report tells the file's vertices from the positions
// the vertex target counts, and the summary names the copies.
TEST(Cli, DecimateReportCountsTheCopiesAlongSeams) {
  OCSIMP_REQUIRE_SHARED_MESH(spot, "spot.obj");
  test::TempDir dir;
  const std::string out = dir / "out.ply", report = dir / "r.json";
  const CommandResult r = run("decimate " + spot + " -o " + out + " --ratio 0.1 --report " + report, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");  // the OBJ's seams are kept, not smeared
  const nlohmann::json j = nlohmann::json::parse(file_bytes(report));
  const IndexedMesh mesh = read_mesh(out);
  const auto copies = j["output"]["seam_copies"].get<std::size_t>();
  EXPECT_GT(copies, 0u);
  EXPECT_EQ(j["output"]["vertices"].get<std::size_t>(), mesh.vertex_count());
  EXPECT_EQ(j["output"]["positions"].get<std::size_t>() + copies, mesh.vertex_count());
  std::set<std::array<float, 3>> positions;
  for (const Vec3f& p : mesh.positions) positions.insert({p.x(), p.y(), p.z()});
  EXPECT_EQ(positions.size(), j["output"]["positions"].get<std::size_t>());
  EXPECT_NE(r.out.find(" (+" + std::to_string(copies) + " copies along seams)"), std::string::npos) << r.out;
  // simplify and lod, which decimate in core here, count them the same way.
  const CommandResult simplified = run(
      "simplify -q " + spot + " -o " + (dir / "s.ply") + " --ratio 0.1 --report " + (dir / "s.json"), dir);
  ASSERT_EQ(simplified.exit_code, 0) << simplified.err;
  const nlohmann::json sj = nlohmann::json::parse(file_bytes(dir / "s.json"));
  EXPECT_EQ(sj["output_seam_copies"].get<std::size_t>(), copies);
  EXPECT_EQ(sj["output_vertices"].get<std::size_t>(), read_mesh(dir / "s.ply").vertex_count());
  const CommandResult levels = run(
      "lod -q " + spot + " -o " + (dir / "l_{faces}.ply") + " --ratios 0.1,0.05 --report " + (dir / "l.json"),
      dir);
  ASSERT_EQ(levels.exit_code, 0) << levels.err;  // a second level over seams was refused
  const nlohmann::json lj = nlohmann::json::parse(file_bytes(dir / "l.json"));
  EXPECT_EQ(lj["levels"][0]["seam_copies"].get<std::size_t>(), copies);
  EXPECT_GT(lj["levels"][1]["seam_copies"].get<std::size_t>(), 0u);
  // Through a clustering stage the seams are averaged over, and simplify says so (it said nothing).
  const CommandResult clustered = run(
      "simplify -q " + spot + " -o " + (dir / "s.ply") + " --faces 300 --two-stage --intermediate 4", dir);
  ASSERT_EQ(clustered.exit_code, 0) << clustered.err;
  EXPECT_NE(clustered.err.find("the clustering stage averages texture coordinates over each of its cells"),
            std::string::npos)
      << clustered.err;
}

// An OBJ output gives a seam's sides one `v` line: spot decimated, or only converted, is as closed as spot
// (its `info` counted every seam edge as a border), and each corner still names its own uv.
TEST(Cli, ObjOutputsStayClosedAcrossTextureSeams) {
  OCSIMP_REQUIRE_SHARED_MESH(spot, "spot.obj");
  test::TempDir dir;
  const std::string decimated = dir / "d.obj", converted = dir / "c.obj", report = dir / "r.json";
  const CommandResult d =
      run("decimate -q " + spot + " -o " + decimated + " --ratio 0.1 --report " + report, dir);
  ASSERT_EQ(d.exit_code, 0) << d.err;
  const nlohmann::json j = nlohmann::json::parse(file_bytes(report));
  ASSERT_GT(j["output"]["seam_copies"].get<std::size_t>(), 0u);
  const CommandResult c = run("convert -q " + spot + " " + converted, dir);
  ASSERT_EQ(c.exit_code, 0) << c.err;
  EXPECT_EQ(c.err, "");  // the seams are kept, not smeared
  for (const std::string& path : {decimated, converted}) {
    const CommandResult info = run("info --json " + path, dir);
    ASSERT_EQ(info.exit_code, 0) << info.err;
    const nlohmann::json facts = nlohmann::json::parse(info.out);
    EXPECT_EQ(facts["boundary_edges"].get<long>(), 0) << path;
    EXPECT_EQ(facts["non_manifold_vertices"].get<long>(), 0) << path;
    EXPECT_EQ(facts["components"].get<long>(), 1) << path;
  }
  const auto positions = j["output"]["positions"].get<long>();
  EXPECT_EQ(nlohmann::json::parse(run("info --json " + decimated, dir).out)["vertices"].get<long>(),
            positions);
  // The conversion keeps spot's own numbers of v and vt records, and every corner's uv.
  const IndexedMesh source = read_mesh(spot), copy = read_mesh(converted);
  EXPECT_EQ(copy.vertex_count(), source.vertex_count());
  ReadOptions split;
  split.split_corner_attributes = true;
  const IndexedMesh a = read_mesh(spot, split), b = read_mesh(converted, split);
  ASSERT_EQ(a.face_count(), b.face_count());
  for (std::size_t f = 0; f < a.face_count(); ++f) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(a.uvs[a.triangles[f][k]], b.uvs[b.triangles[f][k]]) << f;
      ASSERT_EQ(a.positions[a.triangles[f][k]], b.positions[b.triangles[f][k]]) << f;
    }
  }
}

// File names are bytes. One that is not UTF-8 made every JSON output fail after the work was done (exit 1,
// and a decimated mesh written without its report).
TEST(Cli, JsonOutputsNameAFileWhoseNameIsNotUtf8) {
  test::TempDir dir;
  const std::string mesh = dir / "x\xff\x01.ply", out = dir / "y.ply", report = dir / "r.json";
  write_mesh(mesh, test::grid_square(8));

  const CommandResult info = run("info --json " + mesh, dir);
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json j = nlohmann::json::parse(info.out);
  EXPECT_EQ(j["faces"].get<long>(), 128);

  const CommandResult decimate =
      run("decimate -q " + mesh + " -o " + out + " --faces 20 --report " + report, dir);
  ASSERT_EQ(decimate.exit_code, 0) << decimate.err;
  const nlohmann::json r = nlohmann::json::parse(file_bytes(report));
  EXPECT_EQ(r["output"]["faces"].get<long>(), 20) << r.dump();
  EXPECT_NE(r.dump().find("x\xef\xbf\xbd\\u0001.ply"), std::string::npos) << r.dump();

  const CommandResult compare = run("compare -q --json --samples 1000 " + mesh + " " + out, dir);
  ASSERT_EQ(compare.exit_code, 0) << compare.err;
  EXPECT_GE(nlohmann::json::parse(compare.out)["hausdorff"].get<double>(), 0.0);
}
// A scan in georeferenced double coordinates (gen --offset, as UTM metres) simplifies as well as the same
// scan at zero by every command, and comes out in double coordinates: float positions at y = 4.2e6 are 0.5
// apart, half the scan's size, so reading it into floats as it stands made a 27 % Hausdorff distance of a
// decimated cylinder at 1e5.
TEST(Cli, ScanFarFromZeroSimplifiesAsWellAsAtZero) {
  test::TempDir dir;
  const std::string gen = "gen -q --triangles 20000 --seed 5 -o ";
  ASSERT_EQ(run(gen + (dir / "zero.ply"), dir).exit_code, 0);
  ASSERT_EQ(run(gen + (dir / "far.ply") + " --offset 652113.25 4210775.5 312.125", dir).exit_code, 0);
  const CommandResult info = run("info --json " + (dir / "far.ply"), dir);
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json j = nlohmann::json::parse(info.out);
  EXPECT_GT(j["bounding_box"]["min"][1].get<double>(), 4.2e6);
  EXPECT_LT(j["diagonal"].get<double>(), 10.0);

  auto rms = [&](const std::string& original, const std::string& simplified) {
    const CommandResult r =
        run("compare --json -q --samples 20000 " + (dir / original) + " " + (dir / simplified), dir);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.exit_code == 0 ? nlohmann::json::parse(r.out)["rms"].get<double>() : 1e9;
  };
  for (const std::string command : {"decimate --ratio 0.1", "cluster --grid 24",
                                    "simplify --faces 2000 --two-stage", "lod --faces 4000,400"}) {
    const bool lod = command.rfind("lod", 0) == 0;
    for (const std::string name : {"zero", "far"}) {
      const std::string out = dir / (name + (lod ? "_{faces}.ply" : "_out.ply"));
      const CommandResult r = run(command + " -q " + (dir / (name + ".ply")) + " -o '" + out + "'", dir);
      ASSERT_EQ(r.exit_code, 0) << command << ": " << r.err;
    }
    const std::string far_out = lod ? "far_400.ply" : "far_out.ply",
                      zero_out = lod ? "zero_400.ply" : "zero_out.ply";
    EXPECT_NE(file_bytes(dir / far_out).find("property double x"), std::string::npos) << command;
    const double at_zero = rms("zero.ply", zero_out), far = rms("far.ply", far_out);
    EXPECT_GT(at_zero, 0) << command;
    EXPECT_LT(far, 1.01 * at_zero) << command;
  }
  // STL holds floats only: it is written, and the loss is said.
  const CommandResult stl =
      run("decimate --ratio 0.1 -q " + (dir / "far.ply") + " -o " + (dir / "far.stl"), dir);
  EXPECT_EQ(stl.exit_code, 0);
  EXPECT_NE(stl.err.find("float coordinates only"), std::string::npos) << stl.err;
}

TEST(Cli, BadInputGivesOneLineNamingTheFileAndExit2) {
  test::TempDir dir;
  const std::string bad = dir / "bad.ply";
  std::ofstream(bad)
      << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
         "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n";
  const CommandResult r = run("info " + bad, dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.err), 1u) << r.err;
  EXPECT_NE(r.err.find("bad.ply"), std::string::npos);
  EXPECT_NE(r.err.find("line"), std::string::npos);

  const CommandResult missing = run("info " + (dir / "nope.ply"), dir);
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_EQ(lines(missing.err), 1u);
  EXPECT_NE(missing.err.find("nope.ply"), std::string::npos);

  // An empty name is named too (the message named no file: "cannot open: No such file or directory").
  for (const char* command : {"info ''", "cluster '' -o out.ply --grid 4"}) {
    const CommandResult empty = run(command, dir);
    EXPECT_EQ(empty.exit_code, 2) << command;
    EXPECT_EQ(empty.err, "ocsimp: cannot open '': an empty file name\n") << command;
  }
}

// A strip one cell wide clusters to vertices only: the run succeeds, writes them, and says on stderr (even
// with -q) that no face is left and the file cannot be read back.
TEST(Cli, AResultWithoutFacesIsWrittenWithAWarning) {
  test::TempDir dir;
  const std::string strip = dir / "strip.ply";
  {
    std::ofstream out(strip);
    out << "ply\nformat ascii 1.0\nelement vertex 20\nproperty float x\nproperty float y\nproperty float z\n"
           "element face 18\nproperty list uchar int vertex_indices\nend_header\n";
    for (int i = 0; i < 10; ++i) out << i << " 0 0\n" << i << " 0.001 0\n";
    for (int i = 0; i < 9; ++i) {
      out << "3 " << 2 * i << " " << 2 * i + 2 << " " << 2 * i + 3 << "\n";
      out << "3 " << 2 * i << " " << 2 * i + 3 << " " << 2 * i + 1 << "\n";
    }
  }
  const std::string result = dir / "out.ply";
  const CommandResult r = run("cluster -q --grid 4 " + strip + " -o " + result, dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(lines(r.err), 1u) << r.err;
  EXPECT_NE(r.err.find("warning"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no faces"), std::string::npos) << r.err;
  EXPECT_TRUE(std::filesystem::exists(result));
  // info reads it back (it used to refuse it); the simplifying commands refuse it as input.
  const CommandResult info = run("info --json " + result, dir);
  EXPECT_EQ(info.exit_code, 0) << info.err;
  EXPECT_NE(info.out.find("\"faces\": 0,"), std::string::npos) << info.out;
  const CommandResult again =
      run("decimate -q " + result + " -o " + (dir / "again.ply") + " --ratio 0.5", dir);
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_NE(again.err.find("element face is empty"), std::string::npos) << again.err;

  // With faces left, nothing is said.
  const CommandResult kept = run("cluster -q --cell-size 0.0004 " + strip + " -o " + result, dir);
  EXPECT_EQ(kept.exit_code, 0) << kept.err;
  EXPECT_TRUE(kept.err.empty()) << kept.err;
  EXPECT_GT(read_mesh(result).face_count(), 0u);
}

// Draco's encoder drops faces with a repeated corner without a word: convert says how many.
TEST(Cli, ConvertToDracoSaysWhichFacesItLosesAndOthersLoseNone) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(2);
  mesh.triangles.push_back({0, 0, 1});
  mesh.triangles.push_back({4, 5, 5});
  const std::string in = dir / "in.ply";
  write_mesh(in, mesh);
  const CommandResult drc = run("convert -q " + in + " " + (dir / "out.drc"), dir);
  EXPECT_EQ(drc.exit_code, 0) << drc.err;
  EXPECT_EQ(lines(drc.err), 1u) << drc.err;
  EXPECT_NE(drc.err.find("out.drc: 2 faces with a repeated corner are left out"), std::string::npos)
      << drc.err;
  EXPECT_EQ(read_mesh(dir / "out.drc").face_count(), 8u);
  const CommandResult ply = run("convert -q " + in + " " + (dir / "out.ply"), dir);
  EXPECT_EQ(ply.exit_code, 0) << ply.err;
  EXPECT_TRUE(ply.err.empty()) << ply.err;
  EXPECT_EQ(read_mesh(dir / "out.ply").face_count(), 10u);
}

// STL holds no vertex attribute and OBJ no color alpha: they were dropped without a word. Formats that hold
// them say nothing.
TEST(Cli, WritingAFormatWithoutPlaceForAnAttributeSaysWhichIsLost) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(2);
  mesh.normals.assign(mesh.positions.size(), Vec3f(0, 0, 1));
  mesh.colors.assign(mesh.positions.size(), Color{10, 20, 30, 255});
  mesh.uvs.assign(mesh.positions.size(), Vec2f(0.5f, 0.5f));
  const std::string in = dir / "in.ply";
  write_mesh(in, mesh);
  const CommandResult stl = run("convert -q " + in + " " + (dir / "out.stl"), dir);
  EXPECT_EQ(stl.exit_code, 0) << stl.err;
  EXPECT_EQ(stl.err,
            "ocsimp: warning: " + (dir / "out.stl") +
                ": STL has no place for the mesh's normals, colors and texture coordinates: not written\n");
  for (const char* name : {"out.obj", "out.drc", "out.ply"}) {
    const CommandResult r = run("convert -q " + in + " " + (dir / name), dir);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_TRUE(r.err.empty()) << name << ": " << r.err;
  }
  for (Color& c : mesh.colors) c[3] = 100;
  write_mesh(in, mesh);
  const CommandResult obj = run("decimate -q " + in + " -o " + (dir / "out.obj") + " --faces 4", dir);
  EXPECT_EQ(obj.exit_code, 0) << obj.err;
  EXPECT_NE(obj.err.find("out.obj: OBJ has no place for the mesh's color alpha: not written"),
            std::string::npos)
      << obj.err;
  EXPECT_EQ(lines(obj.err), 1u) << obj.err;
}

// What is neither a regular file nor a folder is written as a stream. Renaming a temporary over it made it a
// regular file: run as root, `-o` or `--report` to /dev/null replaced the machine's /dev/null. A FIFO stands
// in for the device here; its reader would wait forever for a writer that renamed it away, hence timeout.
TEST(Cli, AFifoOrAPipeIsWrittenAsAStreamAndNeverReplaced) {
  test::TempDir dir;
  const std::string in = dir / "in.ply", fifo = dir / "out.ply", copy = dir / "copy.ply";
  write_mesh(in, test::sphere(2));
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string command = "timeout 20 cat " + fifo + " > " + copy + " & reader=$!; " + kOcsimp +
                              " convert -q " + in + " " + fifo + " 2>" + (dir / "err.txt") +
                              "; r=$?; wait $reader; exit $r";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << file_bytes(dir / "err.txt");
  struct stat info {};
  ASSERT_EQ(::stat(fifo.c_str(), &info), 0);
  EXPECT_TRUE(S_ISFIFO(info.st_mode));
  EXPECT_EQ(read_mesh(copy).face_count(), test::sphere(2).face_count());

  // A report to /dev/stdout, which is a pipe here: it could not even make its temporary.
  const std::string report = dir / "r.json";
  const std::string piped = kOcsimp + " cluster -q " + in + " -o " + (dir / "c.ply") +
                            " --grid 4 --report /dev/stdout | cat > " + report;
  ASSERT_EQ(std::system(piped.c_str()), 0);
  EXPECT_GT(nlohmann::json::parse(file_bytes(report))["output"]["faces"].get<long>(), 0);
}

// Opening a FIFO that no process writes waited for one forever, before "not a regular file" could be said.
TEST(Cli, AFifoWithoutAWriterIsRefusedAsInput) {
  test::TempDir dir;
  const std::string fifo = dir / "in.ply";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string err = dir / "err.txt";
  const int status = std::system(("timeout 20 " + kOcsimp + " info " + fifo + " 2>" + err).c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2) << "124 is timeout's";
  EXPECT_NE(file_bytes(err).find("in.ply: not a regular file"), std::string::npos) << file_bytes(err);
}

// An input without faces is refused as every other command refuses it, not written empty under a warning
// that "every triangle collapsed".
TEST(Cli, ClusterRefusesAnInputWithoutFaces) {
  test::TempDir dir;
  const std::string points = dir / "points.obj";
  std::ofstream(points) << "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  const std::string result = dir / "out.ply";
  for (const std::string mode : {"--grid 8", "--octree --faces 10"}) {
    const CommandResult r = run("cluster -q " + mode + " " + points + " -o " + result, dir);
    EXPECT_EQ(r.exit_code, 2) << mode;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_NE(r.err.find("points.obj: the mesh has no faces"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(result)) << mode;
  }
}

// --grid counts cells along the box of every vertex; one no face uses, far away, made the whole mesh a
// single cell, and the run said nothing.
// A face target missed with cells to spare (a strip thinner than the cells the target asks for) was
// reported as "the finest grid has 2001 cells", when --cell-size could go much finer.
TEST(Cli, ClusterSaysWhenThinPartsLoseTheirFaces) {
  test::TempDir dir;
  IndexedMesh strip;
  for (Index i = 0; i < 2'000; ++i) {
    const float x = static_cast<float>(i) / 2.0f;
    strip.positions.insert(strip.positions.end(), {{x, 0, 0}, {x, 0.01f, 0}});
    if (i > 0) {
      strip.triangles.push_back({2 * i - 2, 2 * i, 2 * i + 1});
      strip.triangles.push_back({2 * i - 2, 2 * i + 1, 2 * i - 1});
    }
  }
  const std::string in = dir / "strip.ply", out = dir / "out.ply";
  write_mesh(in, strip);
  const CommandResult r = run("cluster -q " + in + " -o " + out + " --faces 400", dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  ReadOptions faceless;
  faceless.faces_required = false;
  EXPECT_LT(read_mesh(out, faceless).face_count(), 400u);
  EXPECT_NE(r.err.find(in + ": the face target was not reached: the fine grid's "), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("--cell-size or --grid sets smaller cells"), std::string::npos) << r.err;
  // As it says: cells narrower than the strip keep its faces.
  const CommandResult fine = run("cluster -q " + in + " -o " + out + " --cell-size 0.004", dir);
  EXPECT_EQ(fine.exit_code, 0) << fine.err;
  EXPECT_GT(read_mesh(out).face_count(), 400u);
}

TEST(Cli, ClusterWarnsWhenUnusedVerticesStretchTheGrid) {
  test::TempDir dir;
  IndexedMesh mesh = test::grid_square(16);  // the unit square
  const std::string plain = dir / "plain.ply", stretched = dir / "stretched.ply";
  write_mesh(plain, mesh);
  mesh.positions.push_back(Vec3f(100, 0, 0));  // no face uses it
  write_mesh(stretched, mesh);
  const std::string result = dir / "out.ply", report = dir / "r.json";
  const CommandResult r =
      run("cluster -q --grid 8 " + stretched + " -o " + result + " --report " + report, dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("the faces span only 1 of the 8 cells of --grid 8"), std::string::npos) << r.err;
  EXPECT_EQ(nlohmann::json::parse(file_bytes(report))["cells"]["spanned"], 1);
  EXPECT_NE(r.err.find("has no faces"), std::string::npos) << r.err;  // one cell: every triangle collapsed
  // Without the outlier, or with a cell size, nothing to say.
  const CommandResult p = run("cluster -q --grid 8 " + plain + " -o " + result + " --report " + report, dir);
  EXPECT_EQ(p.exit_code, 0) << p.err;
  EXPECT_EQ(p.err.find("span"), std::string::npos) << p.err;
  EXPECT_GE(nlohmann::json::parse(file_bytes(report))["cells"]["spanned"], 8);
  EXPECT_GT(read_mesh(result).face_count(), 0u);
  const CommandResult c = run("cluster -q --cell-size 0.125 " + stretched + " -o " + result, dir);
  EXPECT_EQ(c.exit_code, 0) << c.err;
  EXPECT_EQ(c.err.find("span"), std::string::npos) << c.err;
  EXPECT_GT(read_mesh(result).face_count(), 0u);
  // Without --grid the default one is meant, and the warning says so rather than naming a flag never given.
  const CommandResult d = run("cluster -q " + stretched + " -o " + result, dir);
  EXPECT_EQ(d.exit_code, 0) << d.err;
  EXPECT_NE(d.err.find("of the 256 cells of the default --grid 256"), std::string::npos) << d.err;
  // Every vertex at one point: one cell whatever the --grid, and no outlier to blame.
  IndexedMesh point;
  point.positions.assign(6, Vec3f(1, 2, 3));
  point.triangles = {{0, 1, 2}, {3, 4, 5}};
  const std::string one = dir / "point.ply";
  write_mesh(one, point);
  const CommandResult o = run("cluster -q --grid 8 " + one + " -o " + result, dir);
  EXPECT_EQ(o.exit_code, 0) << o.err;
  EXPECT_EQ(o.err.find("span"), std::string::npos) << o.err;
  EXPECT_NE(o.err.find("has no faces"), std::string::npos) << o.err;
  // Nor with a target, which the finest grid misses (it blamed vertices no face uses, of which there are
  // none).
  point.positions.assign(300, Vec3f(1, 2, 3));
  point.triangles.clear();
  for (Index v = 0; v < 300; v += 3) point.triangles.push_back({v, v + 1, v + 2});
  write_mesh(one, point);
  const CommandResult ot = run("cluster -q --faces 50 " + one + " -o " + result, dir);
  EXPECT_EQ(ot.exit_code, 0) << ot.err;
  EXPECT_EQ(ot.err.find("stretch"), std::string::npos) << ot.err;
  EXPECT_NE(ot.err.find("every vertex lies in one cell of the finest grid"), std::string::npos) << ot.err;
  // A target the finest grid cannot reach, for the same reason: the warning names the input and the cause.
  const std::string sphere = dir / "sphere.ply";
  IndexedMesh far = test::sphere(3);
  write_mesh(sphere, far);
  far.positions.push_back(Vec3f(1e6f, 1e6f, 1e6f));
  write_mesh(stretched, far);
  for (const std::string& target : {std::string("--octree --vertices 200"), std::string("--faces 400")}) {
    const CommandResult t = run("cluster -q " + stretched + " -o " + result + " " + target, dir);
    EXPECT_EQ(t.exit_code, 0) << t.err;
    EXPECT_NE(t.err.find(stretched + ": the "), std::string::npos) << t.err;
    EXPECT_NE(t.err.find("target was not reached"), std::string::npos) << t.err;
    EXPECT_NE(t.err.find("vertices no face uses stretch the bounding box"), std::string::npos) << t.err;
    const CommandResult u = run("cluster -q " + sphere + " -o " + result + " " + target, dir);
    EXPECT_EQ(u.exit_code, 0) << u.err;
    EXPECT_TRUE(u.err.empty()) << u.err;
  }
  // So far out that the finest grid there is holds the whole sphere in one cell: the warning blamed the
  // input's lack of extent.
  far.positions.back() = Vec3f(1e8f, 0, 0);
  write_mesh(stretched, far);
  const CommandResult f = run("cluster -q --faces 400 " + stretched + " -o " + result, dir);
  EXPECT_EQ(f.exit_code, 0) << f.err;
  EXPECT_NE(f.err.find("the finest grid has 1 cell, and the faces span only 1 of its 2097152 along the box: "
                       "vertices no face uses stretch the bounding box, and no grid is finer"),
            std::string::npos)
      << f.err;
  EXPECT_EQ(f.err.find("no extent"), std::string::npos) << f.err;
}

TEST(Cli, FailedConvertLeavesNothingBehind) {
  test::TempDir dir;
  const std::string bad = dir / "truncated.ply";
  std::ofstream(bad) << "ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\n"
                        "property float y\nproperty float z\nend_header\n\x01\x02";
  const CommandResult r = run("convert " + bad + " " + (dir / "out.obj"), dir);
  EXPECT_EQ(r.exit_code, 2);
  for (const auto& entry : std::filesystem::directory_iterator(dir.path)) {
    const std::string name = entry.path().filename().string();
    EXPECT_TRUE(name == "truncated.ply" || name == "stdout.txt" || name == "stderr.txt") << name;
  }
  const CommandResult unknown = run("convert " + bad + " " + (dir / "out.xyz"), dir);
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_FALSE(std::filesystem::exists(dir / "out.xyz"));
}

// On a terminal, an error that stops a read ends the progress bar's line first: convert kept its bar alive
// past the command, and the error ran on after "0s left".
TEST(Cli, AnErrorOnATerminalStartsItsOwnLine) {
  if (std::system("command -v script >/dev/null 2>&1") != 0) GTEST_SKIP() << "no script(1) for a terminal";
  test::TempDir dir;
  const std::string whole = dir / "whole.ply", cut = dir / "cut.ply", log = dir / "terminal.txt";
  ASSERT_EQ(run("gen -q -o " + whole + " --triangles 20000", dir).exit_code, 0);
  const std::string bytes = file_bytes(whole);
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() * 3 / 5);
  for (const std::string& args : {"convert " + cut + " " + (dir / "o.ply"), "info " + cut}) {
    std::string script = "script -qec '";
    script.append(kOcsimp).append(" ").append(args).append("' /dev/null > ").append(log).append(" 2>&1");
    EXPECT_NE(std::system(script.c_str()), 0) << args;
    const std::string text = file_bytes(log);
    const std::size_t at = text.find("ocsimp: " + cut);
    ASSERT_NE(at, std::string::npos) << text;
    EXPECT_TRUE(at == 0 || text[at - 1] == '\n') << args << ": " << text;
  }
}

// The bar's line was about 90 characters whatever the terminal: on 80 columns it wrapped, and each redraw
// ('\r' returns to the last row only) scrolled the screen a row.
TEST(Cli, TheProgressBarFitsTheTerminal) {
  if (std::system("command -v script >/dev/null 2>&1") != 0) GTEST_SKIP() << "no script(1) for a terminal";
  test::TempDir dir;
  const std::string mesh = dir / "in.ply", log = dir / "terminal.txt";
  ASSERT_EQ(run("gen -q -o " + mesh + " --triangles 200000", dir).exit_code, 0);
  for (int columns : {40, 60, 80}) {
    std::string script = "script -qec 'stty cols " + std::to_string(columns) + "; ";
    script.append(kOcsimp).append(" decimate --threads 1 " + mesh + " -o " + (dir / "out.ply") +
                                  " --ratio 0.1");
    script.append("' /dev/null > ").append(log).append(" 2>&1");
    ASSERT_EQ(std::system(script.c_str()), 0) << script;
    std::size_t bars = 0, longest = 0, start = 0;
    const std::string text = file_bytes(log);
    for (std::size_t i = 0; i <= text.size(); ++i) {
      if (i == text.size() || text[i] == '\r' || text[i] == '\n') {
        const std::string_view piece(text.data() + start, i - start);
        if (piece.find("] ") != std::string_view::npos) {
          ++bars;
          longest = std::max(longest, piece.size());
        }
        start = i + 1;
      }
    }
    EXPECT_GE(bars, 2u) << text;
    EXPECT_LT(longest, static_cast<std::size_t>(columns)) << columns << " columns:\n" << text;
  }
}

TEST(Cli, AnUnwritableDestinationFailsBeforeAnyOutput) {
  // A report in a missing folder, or a destination that is a folder, used to fail only at the end, after the
  // mesh had been written: the run failed and left its output.
  test::TempDir dir;
  const std::string mesh = dir / "in.ply";
  write_mesh(mesh, test::grid_square(8));
  std::filesystem::create_directory(dir / "folder");
  const std::vector<std::string> commands = {
      "cluster " + mesh + " -o " + (dir / "out.ply") + " --grid 4 --report " + (dir / "missing/r.json"),
      "decimate " + mesh + " -o " + (dir / "out.ply") + " --ratio 0.5 --report " + (dir / "folder"),
      "simplify " + mesh + " -o " + (dir / "out.ply") + " --ratio 0.5 --report " + (dir / "missing/r.json"),
      "lod " + mesh + " -o " + (dir / "out_{faces}.ply") + " --faces 20,10 --report " + (dir / "folder"),
      "convert " + mesh + " " + (dir / "missing/out.ply"),
      "compare " + mesh + " " + mesh + " --report " + (dir / "folder"),
      "gen -o " + (dir / "missing/g.ply") + " --triangles 100",
  };
  for (const std::string& command : commands) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 2) << command;
    EXPECT_EQ(lines(r.err), 1u) << command << "\n" << r.err;
    EXPECT_TRUE(r.err.find("missing") != std::string::npos || r.err.find("is a folder") != std::string::npos)
        << r.err;
    for (const auto& entry : std::filesystem::directory_iterator(dir.path)) {
      const std::string name = entry.path().filename().string();
      EXPECT_TRUE(name == "in.ply" || name == "folder" || name == "stdout.txt" || name == "stderr.txt")
          << command << ": left " << name;
    }
    EXPECT_TRUE(std::filesystem::is_empty(dir / "folder")) << command;
  }
}

// A --report path that names the command's own input or output used to be written over it: the mesh was lost
// and the run exited 0.
TEST(Cli, AReportThatWouldOverwriteAMeshIsRefused) {
  test::TempDir dir;
  const std::string mesh = dir / "in.ply", out = dir / "out.ply";
  write_mesh(mesh, test::grid_square(8));
  const std::string original = file_bytes(mesh);
  const std::vector<std::string> commands = {
      "cluster " + mesh + " -o " + out + " --grid 4 --report " + out,
      "decimate " + mesh + " -o " + out + " --ratio 0.5 --report " + mesh,
      "simplify " + mesh + " -o " + out + " --ratio 0.5 --report " + dir.path.string() + "/./out.ply",
      "lod " + mesh + " -o " + (dir / "out_{faces}.ply") + " --faces 20,10 --report " + (dir / "out_10.ply"),
      "compare " + mesh + " " + mesh + " --report " + mesh,
      // Checked before the benchmark runs (the JSON's folder was found missing only at its end).
      "bench " + mesh + " --ratios 0.5 --json " + mesh,
      "bench " + mesh + " --ratios 0.5 --csv " + mesh,
  };
  for (const std::string& command : commands) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 2) << command;
    EXPECT_EQ(lines(r.err), 1u) << command << "\n" << r.err;
    EXPECT_NE(r.err.find("the report would overwrite the mesh file"), std::string::npos) << r.err;
    EXPECT_EQ(file_bytes(mesh), original) << command;
    for (const auto& entry : std::filesystem::directory_iterator(dir.path)) {
      const std::string name = entry.path().filename().string();
      EXPECT_TRUE(name == "in.ply" || name == "stdout.txt" || name == "stderr.txt")
          << command << ": left " << name;
    }
  }
  // bench's two reports at one path: the CSV replaced the JSON, silently.
  const CommandResult both =
      run("bench " + mesh + " --ratios 0.5 --json " + (dir / "r.txt") + " --csv " + (dir / "r.txt"), dir);
  EXPECT_EQ(both.exit_code, 2);
  EXPECT_EQ(both.err, "ocsimp: " + (dir / "r.txt") + ": --json and --csv name the same file\n");
  EXPECT_FALSE(std::filesystem::exists(dir / "r.txt"));
}

// Whether process `pid` holds a file open in `folder` (its output's temporary, named or not).
std::vector<std::string> names_in(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) names.push_back(entry.path().filename());
  std::sort(names.begin(), names.end());
  return names;
}

bool writes_in(pid_t pid, const std::string& folder) {
  std::error_code error;
  for (const auto& fd : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/fd", error)) {
    const std::string target = std::filesystem::read_symlink(fd.path(), error).string();
    if (!error && target.rfind(folder + "/", 0) == 0) return true;
  }
  return false;
}

// Past the shell's file-size limit a write fails, as when a disk fills: one error line and exit 2, and no
// file left. The kernel's SIGXFSZ had killed the process without a word (exit 153), leaving its temporary.
// Faces that all collapse to a repeated corner once equal positions are joined leave nothing to simplify:
// the commands that decimate refuse the file in one line instead of writing an empty mesh as a result (they
// wrote one, "reached 0 faces", exit 0).
TEST(Cli, NothingLeftToSimplifyIsAnError) {
  test::TempDir dir;
  const std::string mesh = dir / "flat.obj";
  std::ofstream(mesh) << "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\nv 2 1 1\nf 1 2 4\n";
  for (const std::string& command : {"decimate -q " + mesh + " -o " + (dir / "d.ply") + " --faces 1",
                                     "simplify -q " + mesh + " -o " + (dir / "s.ply") + " --faces 1",
                                     "lod -q " + mesh + " -o " + (dir / "l_{faces}.ply") + " --faces 1"}) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 2) << command;
    EXPECT_EQ(r.err, "ocsimp: " + mesh +
                         ": all 2 faces have a repeated corner once vertices at equal positions are joined: "
                         "nothing is left to simplify\n")
        << command;
  }
  EXPECT_EQ(names_in(dir.path),
            (std::vector<std::string>{"flat.obj", "stderr.txt", "stdout.txt"}));  // and run()'s captures
}

TEST(Cli, AFileSizeLimitIsAWriteError) {
  test::TempDir dir;
  const std::string mesh = dir / "in.ply", out = dir / "out.ply";
  write_mesh(mesh, test::sphere(5));  // 8 k faces: about 130 KB as binary PLY
  const std::string command =
      "ulimit -f 64; " + kOcsimp + " convert -q " + mesh + " " + out + " 2>" + (dir / "stderr.txt");
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2);
  const std::string err = file_bytes(dir / "stderr.txt");
  EXPECT_EQ(err, "ocsimp: " + out + ": write failed: File too large\n");
  EXPECT_EQ(names_in(dir.path), (std::vector<std::string>{"in.ply", "stderr.txt"}));
}

// decimate, simplify, cluster and convert wrote over their input when asked to (lod already refused): a
// simplified mesh in place of the scan it came from.
TEST(Cli, AnOutputThatWouldReplaceItsInputIsRefused) {
  test::TempDir dir;
  const std::string mesh = dir / "in.ply";
  write_mesh(mesh, test::sphere(3));
  std::filesystem::create_directories(dir / "sub");
  const std::string before = file_bytes(mesh);
  const std::string same = dir / "sub/../in.ply";
  for (const std::string& command :
       {"decimate -q " + mesh + " -o " + mesh + " --ratio 0.5",
        "simplify -q " + mesh + " -o " + same + " --ratio 0.5",
        "cluster -q " + mesh + " -o " + same + " --grid 8", "convert -q " + mesh + " " + mesh}) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 2) << command;
    EXPECT_NE(r.err.find("the output would replace the input"), std::string::npos) << r.err;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_EQ(file_bytes(mesh), before) << command;
  }
  EXPECT_EQ(run("decimate -q " + mesh + " -o " + (dir / "out.ply") + " --ratio 0.5", dir).exit_code, 0);
}

// CLI11 gives an option the next word even when it is a flag: `-o --faces 100` wrote the mesh to a file
// named "--faces" (in the working directory) and then called 100 an unexpected argument.
TEST(Cli, AFlagIsNotTakenForAnOutputFileName) {
  test::TempDir dir;
  const std::string mesh = dir / "in.ply", out = dir / "out.ply";
  write_mesh(mesh, test::sphere(3));
  for (const std::string& command :
       {"decimate -q " + mesh + " -o --faces 100", "simplify -q " + mesh + " -o --faces 100",
        "cluster -q " + mesh + " -o --grid 8", "lod -q " + mesh + " -o --faces 100",
        "decimate -q " + mesh + " -o " + out + " --faces 100 --report --threads 1"}) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 2) << command;
    EXPECT_NE(r.err.find("is an option, not a file name"), std::string::npos) << command << "\n" << r.err;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    for (const char* name : {"--faces", "--grid", "--threads"}) {
      EXPECT_FALSE(std::filesystem::exists(name)) << command;
      std::filesystem::remove(name);
    }
    EXPECT_FALSE(std::filesystem::exists(out)) << command;
  }
  const CommandResult empty = run("decimate -q " + mesh + " -o '' --faces 100", dir);
  EXPECT_EQ(empty.exit_code, 2);
  EXPECT_NE(empty.err.find("an empty file name"), std::string::npos) << empty.err;
  // convert takes its output as a word or, as every other command, after -o.
  const std::string as_word = dir / "word.obj", after_o = dir / "o.obj";
  ASSERT_EQ(run("convert -q " + mesh + " " + as_word, dir).exit_code, 0);
  ASSERT_EQ(run("convert -q " + mesh + " -o " + after_o, dir).exit_code, 0);
  EXPECT_EQ(file_bytes(after_o), file_bytes(as_word));
  EXPECT_FALSE(file_bytes(after_o).empty());
}

// bench took its lists through CLI11, which dropped empty items and kept repeated ones: "--ratios 0.5,,0.5"
// ran the target twice. bench and lod now read every list alike, and refuse both before reading the mesh.
TEST(Cli, ListsRefuseEmptyAndRepeatedItems) {
  test::TempDir dir;
  const std::string mesh = dir / "in.ply";
  write_mesh(mesh, test::sphere(3));
  const std::string bench = "bench -q " + mesh + " --samples 100 ",
                    lod = "lod -q " + mesh + " -o " + (dir / "l{faces}.ply") + " ";
  const std::pair<std::string, std::string> cases[] = {
      {bench + "--ratios 0.5,,0.25", "--ratios: '' is not a ratio"},
      {bench + "--ratios 0.5,0.25,0.5", "--ratios: '0.5' is given twice"},
      {bench + "--faces 100,", "--faces: '' is not a face count"},
      {bench + "--faces 100,100", "--faces: '100' is given twice"},
      {bench + "--faces 100 --methods decimate,decimate", "--methods: 'decimate' is given twice"},
      {bench + "--faces 100 --methods ,decimate", "--methods: '' is not a name"},
      {bench + "--faces 100 --methods ''", "--methods: '' is not a name"},
      {lod + "--faces 100,50,100", "--faces: '100' is given twice"},
      {lod + "--ratios 0.5,,0.25", "--ratios: '' is not a ratio"}};
  for (const auto& [command, message] : cases) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 2) << command;
    EXPECT_NE(r.err.find(message), std::string::npos) << command << "\n" << r.err;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_TRUE(r.out.empty()) << command << "\n" << r.out;
  }
  // What is well formed runs: one row per method and target.
  const CommandResult ok = run(bench + "--ratios 0.5,0.25 --methods decimate,grid-quadric", dir);
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  std::size_t rows = 0;
  for (std::size_t at = ok.out.find("\n| in |"); at != std::string::npos;
       at = ok.out.find("\n| in |", at + 1))
    ++rows;
  EXPECT_EQ(rows, 4u) << ok.out;
  // A target not below the input's faces runs too, and is said to leave the mesh as it is.
  const std::size_t all = test::sphere(3).face_count();
  const std::string whole = std::to_string(all);
  const CommandResult above = run(bench + "--faces " + whole + ",10 --methods decimate", dir);
  ASSERT_EQ(above.exit_code, 0) << above.err;
  EXPECT_NE(above.err.find("the target of " + whole + " faces is not below the mesh's " + whole),
            std::string::npos)
      << above.err;
  EXPECT_EQ(lines(above.err), 1u) << above.err;
  const CommandResult level = run(lod + "--faces " + std::to_string(all + 1) + ",10", dir);
  ASSERT_EQ(level.exit_code, 0) << level.err;
  EXPECT_NE(level.err.find("the target of " + std::to_string(all + 1) + " faces is not below the " + whole +
                           " it decimates: none is removed"),
            std::string::npos)
      << level.err;
  EXPECT_EQ(lines(level.err), 1u) << level.err;
  EXPECT_EQ(read_mesh(dir / ("l" + std::to_string(all + 1) + ".ply")).face_count(), all);
  // decimate and simplify say so as well (they wrote the input back without a word).
  const std::string& in = mesh;
  for (const std::string& command : {"decimate -q " + in + " -o " + (dir / "d.ply") + " --faces " + whole,
                                     "simplify -q " + in + " -o " + (dir / "d.ply") + " --ratio 1",
                                     "decimate -q " + in + " -o " + (dir / "d.ply") + " --vertices 100000"}) {
    const CommandResult r = run(command, dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find(" is not below the "), std::string::npos) << command << "\n" << r.err;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_EQ(read_mesh(dir / "d.ply").face_count(), all);
  }
}

// A summary printed after a report sent to standard output made it unreadable as JSON; simplify and lod
// printed theirs only on a terminal, unlike decimate and cluster.
TEST(Cli, AReportOnStandardOutputIsAllThatIsPrinted) {
  test::TempDir dir;
  const std::string mesh = dir / "in.ply", out = dir / "out.ply";
  write_mesh(mesh, test::sphere(4));
  for (const std::string& command :
       {"decimate " + mesh + " -o " + out + " --ratio 0.5",
        "simplify " + mesh + " -o " + out + " --ratio 0.5", "cluster " + mesh + " -o " + out + " --grid 8",
        "lod " + mesh + " -o " + out + " --faces 100", "compare " + mesh + " " + mesh + " --samples 1000",
        "compare --json " + mesh + " " + mesh + " --samples 1000"}) {
    const CommandResult summary = run(command, dir);
    ASSERT_EQ(summary.exit_code, 0) << command << "\n" << summary.err;
    EXPECT_FALSE(summary.out.empty()) << command;
    // Through a pipe: a report into stdout's file would be renamed over it, and what followed lost with
    // the old file.
    const CommandResult report = run(command + " --report /dev/stdout | cat", dir);
    ASSERT_EQ(report.exit_code, 0) << command << "\n" << report.err;
    EXPECT_TRUE(nlohmann::json::accept(report.out)) << command << "\n" << report.out;
  }
}

// What info --json, compare and bench print went nowhere, with exit 0, when standard output was a full disk
// or closed.
TEST(Cli, AFailedWriteToStandardOutputIsAnError) {
  test::TempDir dir;
  const std::string mesh = dir / "square.ply", err = dir / "stderr.txt";
  write_mesh(mesh, test::grid_square(4));
  for (const std::string to : {">/dev/full", ">&-"}) {
    const int status = std::system((kOcsimp + " info --json " + mesh + " " + to + " 2>" + err).c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 2) << to;
    EXPECT_EQ(file_bytes(err).rfind("ocsimp: standard output: write failed: ", 0), 0u) << file_bytes(err);
    EXPECT_EQ(lines(file_bytes(err)), 1u) << file_bytes(err);
  }
}

// A run whose summary or report could not be written failed (exit 2), and a failed run leaves no output:
// decimate, simplify, cluster and gen left their mesh behind, with the report at /dev/full or the summary
// on a full disk. A closed standard output is such a failure too (the summary went into the mesh).
TEST(Cli, AnUnwrittenSummaryOrReportLeavesNoMesh) {
  test::TempDir dir;
  const std::string mesh = dir / "square.ply", out = dir / "out.ply", err = dir / "stderr.txt";
  write_mesh(mesh, test::grid_square(8));
  const std::string mesh_commands[] = {"decimate " + mesh + " --faces 20", "simplify " + mesh + " --faces 20",
                                       "cluster " + mesh + " --grid 4", "gen --triangles 1000"};
  for (const std::string& command : mesh_commands) {
    for (const char* failing : {" >/dev/full", " >&-", " --report /dev/full >/dev/null"}) {
      if (command.rfind("gen", 0) == 0 && std::string(failing).find("--report") != std::string::npos)
        continue;
      const std::string line = kOcsimp + " " + command + " -o " + out + failing + " 2>" + err;
      const int status = std::system(line.c_str());
      ASSERT_TRUE(WIFEXITED(status)) << line;
      EXPECT_EQ(WEXITSTATUS(status), 2) << line;
      EXPECT_EQ(lines(file_bytes(err)), 1u) << line << "\n" << file_bytes(err);
      EXPECT_FALSE(std::filesystem::exists(out)) << line;
    }
  }
  // lod's levels, and compare's report, likewise.
  const std::string level = dir / "level_{faces}.ply", report = dir / "report.json";
  for (const std::string& command : {"lod " + mesh + " -o " + level + " --faces 40,20",
                                     "compare " + mesh + " " + mesh + " --report " + report}) {
    const int status = std::system((kOcsimp + " " + command + " >/dev/full 2>" + err).c_str());
    ASSERT_TRUE(WIFEXITED(status)) << command;
    EXPECT_EQ(WEXITSTATUS(status), 2) << command;
    EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path), {}), 2) << command;  // mesh, err
  }
}

// A warning to a closed standard error goes nowhere: the output mesh, opened on the lowest free descriptor,
// took the warning at its end and could not be read back.
TEST(Cli, AClosedStandardErrorLeavesTheMeshWhole) {
  test::TempDir dir;
  const std::string mesh = dir / "square.ply", out = dir / "out.ply";
  write_mesh(mesh, test::grid_square(8));
  // One cell: every face collapses, which is warned about.
  const int status = std::system((kOcsimp + " cluster -q " + mesh + " -o " + out + " --grid 1 2>&-").c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  ReadOptions options;
  options.faces_required = false;
  const IndexedMesh read = read_mesh(out, options);
  EXPECT_EQ(read.face_count(), 0u);
  EXPECT_EQ(read.vertex_count(), 1u);
}

// Killed while it writes, by a signal it can catch or by SIGKILL (as the out-of-memory killer does), gen
// leaves the folder as it was: its output is an unnamed file until it is complete.
TEST(Cli, InterruptedGenLeavesNoFile) {
  for (const int signal : {SIGTERM, SIGKILL}) {
    test::TempDir dir;
    const std::string out = dir / "big.ply";
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      execl(kOcsimp.c_str(), kOcsimp.c_str(), "gen", "-q", "-o", out.c_str(), "--triangles", "400000000",
            static_cast<char*>(nullptr));
      _exit(127);
    }
    // Wait until the output is open, so the kill lands mid-write.
    bool started = false;
    for (int i = 0; i < 400 && !started; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      started = writes_in(child, std::filesystem::canonical(dir.path).string());
    }
    EXPECT_TRUE(started) << signal;
    kill(child, signal);
    int status = 0;
    waitpid(child, &status, 0);
    EXPECT_TRUE(WIFSIGNALED(status)) << signal;
    EXPECT_TRUE(names_in(dir.path).empty()) << signal << ": left " << names_in(dir.path)[0];
  }
}

void expect_keys(const nlohmann::json& object, std::initializer_list<const char*> keys) {
  for (const char* key : keys) EXPECT_TRUE(object.contains(key)) << key << " missing in " << object.dump();
}

TEST(Cli, LodWritesEachLevelWithItsCountAndAReport) {
  test::TempDir dir;
  const std::string scan = dir / "scan.ply";
  ASSERT_EQ(run("gen -q --holes 2 --triangles 60000 -o " + scan, dir).exit_code, 0);
  const CommandResult r = run("lod " + scan + " -o '" + (dir / "lod_{faces}.ply") +
                                  "' --faces 20000,500,3001 --report " + (dir / "lod.json"),
                              dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // The summary of the levels, a line each, on a terminal or not (as decimate's and cluster's); no warning.
  for (const char* level : {"\n20000 ", "\n3001 ", "\n500 "})
    EXPECT_NE(r.out.find(level), std::string::npos) << level << "\n" << r.out;
  EXPECT_EQ(r.err, "");
  for (std::uint64_t faces : {20000u, 3001u, 500u}) {
    EXPECT_EQ(read_mesh(dir / ("lod_" + std::to_string(faces) + ".ply")).face_count(), faces);
  }
  const nlohmann::json report = nlohmann::json::parse(file_bytes(dir / "lod.json"));
  expect_keys(report,
              {"command", "input", "output", "input_faces", "clustered", "out_of_core", "intermediate_faces",
               "memory_limit_bytes", "peak_rss_bytes", "seconds", "max_error", "levels", "phases"});
  EXPECT_EQ(report["command"], "lod");
  EXPECT_EQ(report["input_faces"].get<std::uint64_t>(), read_mesh(scan).face_count());
  ASSERT_EQ(report["levels"].size(), 3u);
  const std::uint64_t expected[] = {20000, 3001, 500};
  double previous = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    const nlohmann::json& level = report["levels"][i];
    expect_keys(level, {"target_faces", "faces", "vertices", "file", "seconds", "max_error",
                        "level_max_error", "target_reached", "stop"});
    EXPECT_EQ(level["faces"].get<std::uint64_t>(), expected[i]);
    EXPECT_EQ(level["file"], dir / ("lod_" + std::to_string(expected[i]) + ".ply"));
    EXPECT_GE(level["max_error"].get<double>(), previous);
    previous = level["max_error"].get<double>();
  }
  EXPECT_EQ(report["max_error"].get<double>(), previous);
  ASSERT_GE(report["phases"].size(), 5u);  // open, read, three levels
  for (const nlohmann::json& phase : report["phases"])
    expect_keys(phase, {"name", "seconds", "triangles_in", "triangles_out", "peak_rss_bytes"});
  EXPECT_EQ(report["phases"].back()["name"], "level 500");
  EXPECT_EQ(report["phases"].back()["triangles_out"].get<std::uint64_t>(), 500u);
}

TEST(Cli, LodTakesItsLevelsAsRatiosOfTheFacesRead) {
  test::TempDir dir;
  const std::string scan = dir / "scan.ply";
  ASSERT_EQ(run("gen -q --holes 2 --triangles 60000 -o " + scan, dir).exit_code, 0);
  const std::uint64_t faces = read_mesh(scan).face_count();
  const CommandResult r = run("lod " + scan + " -o '" + (dir / "lod_{faces}.ply") +
                                  "' --ratios 0.01,0.1 --report " + (dir / "lod.json"),
                              dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const double ratios[] = {0.1, 0.01};
  const nlohmann::json report = nlohmann::json::parse(file_bytes(dir / "lod.json"));
  ASSERT_EQ(report["levels"].size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const auto expected = static_cast<std::uint64_t>(std::llround(ratios[i] * static_cast<double>(faces)));
    const std::string file = dir / ("lod_" + std::to_string(expected) + ".ply");
    EXPECT_EQ(read_mesh(file).face_count(), expected);
    const nlohmann::json& level = report["levels"][i];
    EXPECT_EQ(level["target_faces"].get<std::uint64_t>(), expected);
    EXPECT_EQ(level["target_ratio"].get<double>(), ratios[i]);
    EXPECT_EQ(level["file"], file);
  }
  // One list or the other, of ratios in (0, 1]; each refusal one line, before any output.
  // A comma at either end, or two together, leaves an empty item: "0.1," was taken as "0.1".
  for (const std::string levels : {"--faces 100 --ratios 0.1", "--ratios 0.1,1.5", "--ratios 0.1,x", "",
                                   "--ratios 0.1,", "--ratios ,0.1", "--faces 100,,10", "--faces 100,"}) {
    const CommandResult bad = run("lod " + scan + " -o '" + (dir / "bad_{faces}.ply") + "' " + levels, dir);
    EXPECT_EQ(bad.exit_code, 2) << levels;
    EXPECT_EQ(lines(bad.err), 1u) << levels << ": " << bad.err;
  }
  for (const auto& entry : std::filesystem::directory_iterator(dir.path))
    EXPECT_EQ(entry.path().filename().string().rfind("bad_", 0), std::string::npos) << entry.path();
  // A report named like a level's file, known only once the input is read, is refused before any level is
  // written, rather than written over it.
  const auto first = static_cast<std::uint64_t>(std::llround(0.1 * static_cast<double>(faces)));
  const std::string clash = dir / ("clash_" + std::to_string(first) + ".ply");
  const CommandResult refused = run(
      "lod " + scan + " -o '" + (dir / "clash_{faces}.ply") + "' --ratios 0.1,0.01 --report " + clash, dir);
  EXPECT_EQ(refused.exit_code, 2);
  EXPECT_EQ(lines(refused.err), 1u) << refused.err;
  EXPECT_NE(refused.err.find("would overwrite the mesh file"), std::string::npos) << refused.err;
  EXPECT_FALSE(std::filesystem::exists(clash));
}

// A pattern easily names the input itself (lod in_500.ply -o 'in_{faces}.ply'): the run is refused before any
// level is written, whether the clashing level is given as a count or comes from a ratio.
TEST(Cli, LodRefusesALevelFileThatWouldReplaceItsInput) {
  test::TempDir dir;
  const std::string scan = dir / "scan.ply";
  ASSERT_EQ(run("gen -q --triangles 20000 -o " + scan, dir).exit_code, 0);
  const std::uint64_t faces = read_mesh(scan).face_count();
  const auto tenth = static_cast<std::uint64_t>(std::llround(0.1 * static_cast<double>(faces)));
  const std::string input = dir / ("in_" + std::to_string(tenth) + ".ply");
  std::filesystem::copy_file(scan, input);
  const std::string before = file_bytes(input);
  for (const std::string& levels :
       {"--faces 5000," + std::to_string(tenth), std::string("--ratios 0.5,0.1")}) {
    SCOPED_TRACE(levels);
    // Spelled through ./ so that only the resolved paths agree.
    const CommandResult r =
        run("lod " + input + " -o '" + dir.path.string() + "/./in_{faces}.ply' " + levels, dir);
    EXPECT_EQ(r.exit_code, 2);
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_NE(r.err.find("would replace the input"), std::string::npos) << r.err;
    EXPECT_EQ(file_bytes(input), before);
    for (const auto& entry : std::filesystem::directory_iterator(dir.path)) {
      if (entry.path().string() == input) continue;
      EXPECT_NE(entry.path().filename().string().rfind("in_", 0), 0u) << entry.path() << " was written";
    }
  }
  // A level of another count beside the input is fine.
  const CommandResult ok = run("lod " + input + " -o '" + (dir / "in_{faces}.ply") + "' --faces 500", dir);
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_EQ(read_mesh(dir / "in_500.ply").face_count(), 500u);
  EXPECT_EQ(file_bytes(input), before);
}

// Two levels whose files are one (a symbolic link from one level's name to another's): the run went through
// and the file held the smaller level, the larger one lost without a word.
TEST(Cli, LodRefusesTwoLevelsInOneFile) {
  test::TempDir dir;
  const std::string mesh = dir / "square.ply";
  write_mesh(mesh, test::grid_square(16));
  std::ofstream(dir / "x_100.ply") << "old";
  std::filesystem::create_symlink("x_100.ply", dir / "x_50.ply");
  const CommandResult r = run("lod " + mesh + " -o '" + (dir / "x_{faces}.ply") + "' --faces 100,50", dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.err), 1u) << r.err;
  EXPECT_NE(r.err.find("x_50.ply: this level's file is also the level file"), std::string::npos) << r.err;
  EXPECT_EQ(file_bytes(dir / "x_100.ply"), "old");
}

TEST(Cli, LodRefusesAPatternWithoutFacesForSeveralLevels) {
  test::TempDir dir;
  const std::string scan = dir / "scan.ply";
  ASSERT_EQ(run("gen -q --triangles 5000 -o " + scan, dir).exit_code, 0);
  const CommandResult r = run("lod " + scan + " -o " + (dir / "out.ply") + " --faces 1000,100", dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.err), 1u) << r.err;
  EXPECT_NE(r.err.find("{faces}"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "out.ply"));
  const CommandResult bad = run("lod " + scan + " -o " + (dir / "out.ply") + " --faces 1000,x", dir);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(lines(bad.err), 1u) << bad.err;
  // One level needs no {faces}.
  EXPECT_EQ(run("lod " + scan + " -o " + (dir / "out.ply") + " --faces 1000", dir).exit_code, 0);
  EXPECT_EQ(read_mesh(dir / "out.ply").face_count(), 1000u);
}

TEST(Cli, SimplifyReportHasTheDocumentedFields) {
  test::TempDir dir;
  const std::string scan = dir / "scan.ply";
  ASSERT_EQ(run("gen -q --holes 1 --triangles 100000 -o " + scan, dir).exit_code, 0);
  const CommandResult r = run("simplify " + scan + " -o " + (dir / "out.obj") + " --faces 120 --two-stage " +
                                  "--memory-limit 256K --report " + (dir / "report.json"),
                              dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("120 faces"), std::string::npos) << r.out;  // the summary
  EXPECT_EQ(read_mesh(dir / "out.obj").face_count(), 120u);
  const nlohmann::json report = nlohmann::json::parse(file_bytes(dir / "report.json"));
  const auto fields = {"command",
                       "input",
                       "output",
                       "input_faces",
                       "output_faces",
                       "output_vertices",
                       "clustered",
                       "out_of_core",
                       "intermediate_faces",
                       "memory_limit_bytes",
                       "peak_rss_bytes",
                       "seconds",
                       "max_error",
                       "cluster_error",
                       "target_reached",
                       "stop",
                       "reason",
                       "phases"};
  expect_keys(report, fields);
  EXPECT_EQ(report["output_faces"].get<std::uint64_t>(), 120u);
  EXPECT_TRUE(report["clustered"].get<bool>());
  EXPECT_TRUE(report["out_of_core"].get<bool>());
  EXPECT_EQ(report["memory_limit_bytes"].get<std::uint64_t>(), 256u << 10);
  std::vector<std::string> phases;
  for (const nlohmann::json& phase : report["phases"]) phases.push_back(phase["name"]);
  EXPECT_EQ(phases, (std::vector<std::string>{"open", "cluster", "decimate", "write"}));
  EXPECT_EQ(report["phases"][1]["triangles_in"].get<std::uint64_t>(),
            report["input_faces"].get<std::uint64_t>());
  // Every field is documented in the help.
  const CommandResult help = run("simplify --help", dir);
  for (const char* field : fields) EXPECT_NE(help.out.find(field), std::string::npos) << field;
}

// How far a simplified scan from `gen --normals --colors` keeps its attributes: the mean distance of its
// colors' red, green and blue from gen's color function at each output vertex, and the share of vertices
// whose normal agrees with their faces' (a positive dot product with their area-weighted sum; 0 without
// normals).
struct AttributeFit {
  double color_error = 0;
  double normals_agreeing = 0;
};
AttributeFit attribute_fit(const IndexedMesh& mesh) {
  AttributeFit fit;
  auto channel = [](double v) { return std::clamp(127.5 + 127.5 * std::sin(v), 0.0, 255.0); };
  for (std::size_t v = 0; v < mesh.vertex_count(); ++v) {
    const Vec3d p = mesh.positions[v].cast<double>();
    const double expected[3] = {channel(3 * p.x()), channel(3 * p.y() + 2), channel(3 * p.z() + 4)};
    for (int c = 0; c < 3; ++c) fit.color_error += std::abs(mesh.colors[v][c] - expected[c]) / 3;
  }
  fit.color_error /= static_cast<double>(mesh.vertex_count());
  if (mesh.normals.empty()) return fit;
  std::vector<Vec3d> face_normals(mesh.vertex_count(), Vec3d::Zero());
  for (const Triangle& t : mesh.triangles) {
    const Vec3d a = mesh.positions[t[0]].cast<double>(), b = mesh.positions[t[1]].cast<double>(),
                c = mesh.positions[t[2]].cast<double>();
    const Vec3d n = (b - a).cross(c - a);
    for (Index v : t) face_normals[v] += n;
  }
  std::size_t agreeing = 0;
  for (std::size_t v = 0; v < mesh.vertex_count(); ++v)
    agreeing += mesh.normals[v].cast<double>().dot(face_normals[v]) > 0 ? 1 : 0;
  fit.normals_agreeing = static_cast<double>(agreeing) / static_cast<double>(mesh.vertex_count());
  return fit;
}

// Under a memory limit that sends the input out of core, a PLY's vertex attributes ride on the corners
// through the clustering stage and reach the output about as well as in core; so do an OBJ's vertex colors,
// but not its normals (indexed per corner), and the run says so.
TEST(Cli, SimplifyAndLodKeepAPlysAttributesOutOfCoreAndSayWhenAnObjsAreDropped) {
  test::TempDir dir;
  const std::string mesh = dir / "coloured.ply", obj = dir / "coloured.obj";
  const CommandResult g = run("gen -q --triangles 40000 --seed 2 --normals --colors -o " + mesh, dir);
  ASSERT_EQ(g.exit_code, 0) << g.err;
  const std::string out = dir / "out.ply";
  const CommandResult plain = run("simplify -q " + mesh + " -o " + out + " --faces 100", dir);
  EXPECT_EQ(plain.exit_code, 0) << plain.err;
  const IndexedMesh in_core = read_mesh(out);
  ASSERT_EQ(in_core.colors.size(), in_core.positions.size());
  ASSERT_EQ(in_core.normals.size(), in_core.positions.size());
  const AttributeFit reference = attribute_fit(in_core);

  const std::string report = dir / "report.json";
  const CommandResult limited =
      run("simplify -q " + mesh + " -o " + out + " --faces 100 --memory-limit 10000 --report " + report, dir);
  EXPECT_EQ(limited.exit_code, 0) << limited.err;
  EXPECT_EQ(limited.err.find("not in the output"), std::string::npos) << limited.err;
  EXPECT_TRUE(nlohmann::json::parse(file_bytes(report))["out_of_core"].get<bool>());
  const IndexedMesh kept = read_mesh(out);
  ASSERT_EQ(kept.colors.size(), kept.positions.size());
  ASSERT_EQ(kept.normals.size(), kept.positions.size());
  const AttributeFit fit = attribute_fit(kept);
  // Colors off by a few units, where a channel left at 0 or at its mean would be off by about 80 and 40 (in
  // core 2.6; clustered first, each cell's average, 11.6).
  EXPECT_LT(fit.color_error, 15) << reference.color_error;
  EXPECT_GT(fit.normals_agreeing, 0.98) << reference.normals_agreeing;

  const CommandResult levels =
      run("lod -q " + mesh + " -o " + (dir / "l_{faces}.ply") + " --faces 100,50 --memory-limit 10000", dir);
  EXPECT_EQ(levels.exit_code, 0) << levels.err;
  EXPECT_EQ(levels.err.find("not in the output"), std::string::npos) << levels.err;
  const IndexedMesh level = read_mesh(dir / "l_50.ply");
  EXPECT_EQ(level.colors.size(), level.positions.size());

  ASSERT_EQ(run("convert -q " + mesh + " " + obj, dir).exit_code, 0);
  const CommandResult from_obj =
      run("simplify -q " + obj + " -o " + out + " --faces 100 --memory-limit 10000", dir);
  EXPECT_EQ(from_obj.exit_code, 0) << from_obj.err;
  EXPECT_NE(from_obj.err.find("coloured.obj: its normals are not in the output"), std::string::npos)
      << from_obj.err;
  const IndexedMesh from_obj_mesh = read_mesh(out);
  EXPECT_TRUE(from_obj_mesh.normals.empty());
  // Its vertex colors ride with the positions, as a PLY's do.
  ASSERT_EQ(from_obj_mesh.colors.size(), from_obj_mesh.positions.size());
  EXPECT_LT(attribute_fit(from_obj_mesh).color_error, 15) << reference.color_error;
}

// A textured PLY as MeshLab writes it, with its texture coordinates per face corner (here u, v = x, y of the
// corner's vertex): they reach the output through decimation and through clustering in core; out of core,
// where the vertices are handed on before the faces are read, the run says they are left out.
TEST(Cli, APlysPerCornerTextureCoordinatesReachTheOutput) {
  test::TempDir dir;
  const std::string scan = dir / "scan.ply", textured = dir / "textured.ply";
  ASSERT_EQ(run("gen -q --triangles 40000 --seed 3 -o " + scan, dir).exit_code, 0);
  const IndexedMesh mesh = read_mesh(scan);
  {
    std::ofstream out(textured, std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\nelement vertex " << mesh.vertex_count()
        << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << mesh.face_count()
        << "\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n";
    out.write(reinterpret_cast<const char*>(mesh.positions.data()),
              static_cast<std::streamsize>(mesh.positions.size() * sizeof(Vec3f)));
    for (const Triangle& t : mesh.triangles) {
      const std::uint8_t three = 3, six = 6;
      out.write(reinterpret_cast<const char*>(&three), 1);
      for (Index v : t) out.write(reinterpret_cast<const char*>(&v), 4);
      out.write(reinterpret_cast<const char*>(&six), 1);
      for (Index v : t) out.write(reinterpret_cast<const char*>(mesh.positions[v].data()), 8);
    }
  }
  // The mean distance of each output vertex's uv from its own x, y; about 0.5 for uvs left at (0, 0), and
  // output edges are about 0.08 long.
  auto uv_error = [](const IndexedMesh& m) {
    double sum = 0;
    for (std::size_t v = 0; v < m.vertex_count(); ++v) sum += (m.uvs[v] - m.positions[v].head<2>()).norm();
    return sum / static_cast<double>(m.vertex_count());
  };
  const std::string out = dir / "out.ply";
  for (const std::string command : {"decimate", "cluster", "simplify"}) {
    SCOPED_TRACE(command);
    const std::string target = command == "cluster" ? " --grid 40" : " --faces 2000";
    const CommandResult r = run(command + " -q " + textured + " -o " + out + target, dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err, "");
    const IndexedMesh result = read_mesh(out);
    ASSERT_EQ(result.uvs.size(), result.vertex_count());
    EXPECT_LT(uv_error(result), 0.02);  // measured: 0.005 to 0.007
  }
  const CommandResult limited =
      run("simplify -q " + textured + " -o " + out + " --faces 100 --memory-limit 10000", dir);
  EXPECT_EQ(limited.exit_code, 0) << limited.err;
  EXPECT_NE(limited.err.find("textured.ply: its texture coordinates are not in the output"),
            std::string::npos)
      << limited.err;
  EXPECT_TRUE(read_mesh(out).uvs.empty());
}

// Where face corners disagree on a vertex's texture coordinates or normal, every command that reads the file
// and keeps one of each per vertex says so in one warning line, and still succeeds.
TEST(Cli, EveryCommandSaysWhereCornersDisagreed) {
  test::TempDir dir;
  const std::string obj = dir / "seam.obj";
  std::ofstream(obj)
      << ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\n"
          "f 1/1 2/2 3/3\nf 1/5 3/3 4/4\n");
  const std::string smears =
      "ocsimp: warning: " + obj +
      ": 1 vertex on texture seams (face corners giving different texture coordinates) "
      "keeps its first corner's in this command (convert keeps a vertex per side, as decimate, simplify and "
      "lod do without --no-weld)\n";
  const std::vector<std::string> decimating = {"decimate -q " + obj + " -o " + (dir / "d.ply") + " --faces 1",
                                               "simplify -q " + obj + " -o " + (dir / "s.ply") + " --faces 1",
                                               "lod -q " + obj + " -o " + (dir / "l.ply") + " --faces 1"};
  for (const std::string& command :
       {"info " + obj, "cluster -q " + obj + " -o " + (dir / "k.ply") + " --grid 4"}) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 0) << command << ": " << r.err;
    EXPECT_EQ(r.err, smears) << command;
  }
  // convert keeps both sides: a PLY output holds the seam's vertex once per side, each with its own uv.
  const CommandResult converted = run("convert -q " + obj + " " + (dir / "c.ply"), dir);
  EXPECT_EQ(converted.exit_code, 0) << converted.err;
  EXPECT_EQ(converted.err, "");
  const IndexedMesh c = read_mesh(dir / "c.ply");
  ASSERT_EQ(c.vertex_count(), 5u);
  EXPECT_EQ(c.positions[c.triangles[0][0]], c.positions[c.triangles[1][0]]);
  EXPECT_EQ(c.uvs[c.triangles[0][0]], Vec2f(0, 0));
  EXPECT_EQ(c.uvs[c.triangles[1][0]], Vec2f(0.5f, 0.5f));
  // The commands that decimate read each side of the seam as its own vertex and weld them back, keeping
  // both sides' texture coordinates: nothing smears, unless welding is off.
  for (const std::string& command : decimating) {
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 0) << command << ": " << r.err;
    EXPECT_EQ(r.err, "") << command;
    const CommandResult unwelded = run(command + " --no-weld", dir);
    EXPECT_EQ(unwelded.exit_code, 0) << command << ": " << unwelded.err;
    EXPECT_EQ(unwelded.err, smears) << command;
  }
}

// A face or vertex target's soup pass holds several times the indexed pass's bytes per fine cell, so a
// target-driven run stays in core where its vertex array is smaller than that difference (a 20 M scan to
// 400 k faces under 64M peaked at 1.7 GiB out of core, 350 MiB in core); a small octree still goes out of
// core under a small limit. So does a grid coarse against the input, but not one whose cells could take more
// than the vertex array (--grid 4096 under 50M took gen 20 M from 2.6 GB in core to 5.8 GB out of core). A
// --cell-size grid's cells are unknown before its pass: out of core is the one way to keep the limit.
TEST(Cli, ClusterStaysInCoreWhereTheSoupPassWouldTakeMore) {
  test::TempDir dir;
  const std::string mesh = dir / "scan.ply", out = dir / "out.ply", report = dir / "report.json";
  ASSERT_EQ(run("gen -q --triangles 100000 --seed 3 -o " + mesh, dir).exit_code, 0);  // 600 kB of vertices
  const struct {
    const char* target;
    bool out_of_core;
  } cases[] = {{"--faces 20000", false},
               {"--octree --vertices 10000", false},
               {"--octree --vertices 20", true},
               {"--grid 32", false},
               {"--grid 6", true},
               {"--cell-size 0.01", true}};
  for (const auto& c : cases) {
    const CommandResult r =
        run("cluster -q " + mesh + " -o " + out + " " + c.target + " --memory-limit 100K --report " + report,
            dir);
    ASSERT_EQ(r.exit_code, 0) << c.target << "\n" << r.err;
    EXPECT_EQ(nlohmann::json::parse(file_bytes(report))["out_of_core"].get<bool>(), c.out_of_core)
        << c.target;
  }
}

// cluster holds its input's vertex array only up to --memory-limit (a third of RAM by default); past it the
// faces are dereferenced on disk and clustered as soups, to the same cells: same counts, the colors kept,
// and distances to the original within a hair of the in-core run's.
TEST(Cli, ClusterDereferencesAVertexArrayOverItsMemoryLimit) {
  test::TempDir dir;
  const std::string mesh = dir / "scan.ply", report = dir / "report.json";
  ASSERT_EQ(run("gen -q --triangles 100000 --seed 3 --colors -o " + mesh, dir).exit_code, 0);  // 600 kB
  std::vector<IndexedMesh> outputs;
  for (const std::string limit : {"", " --memory-limit 100K"}) {
    SCOPED_TRACE(limit);
    const std::string out = dir / ("out" + std::to_string(outputs.size()) + ".ply");
    const CommandResult r =
        run("cluster -q --grid 6 " + mesh + " -o " + out + limit + " --report " + report, dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    // No process fits in 100 KiB: the run says it went over, as simplify and lod do.
    if (limit.empty()) {
      EXPECT_EQ(r.err, "");
    } else {
      EXPECT_NE(r.err.find("went over the memory limit of 100.0 KiB"), std::string::npos) << r.err;
    }
    const nlohmann::json fields = nlohmann::json::parse(file_bytes(report));
    EXPECT_EQ(fields["out_of_core"].get<bool>(), !limit.empty());
    // The file's vertices either way (out of core the clustering sees only corners; it said 0).
    EXPECT_EQ(fields["input"]["vertices"].get<std::uint64_t>(), read_mesh(mesh).vertex_count());
    outputs.push_back(read_mesh(out));
    EXPECT_EQ(outputs.back().colors.size(), outputs.back().positions.size());
  }
  EXPECT_EQ(outputs[1].face_count(), outputs[0].face_count());
  EXPECT_EQ(outputs[1].vertex_count(), outputs[0].vertex_count());
  const IndexedMesh original = read_mesh(mesh);
  CompareOptions compare;
  compare.samples = 100'000;
  const double in_core = measure_distance(original, outputs[0], compare).rms;
  EXPECT_NEAR(measure_distance(original, outputs[1], compare).rms, in_core, 0.01 * in_core);
}

// A command that holds whole meshes refuses at once a PLY whose header announces more faces than it could
// hold in this process's memory, rather than reading it and being killed when memory runs out. The file is
// sparse: a header, then zeros that take no disk space, as many as the announced faces need.
TEST(Cli, CommandsHoldingWholeMeshesRefuseAnInputBeyondMemory) {
  test::TempDir dir;
  const std::string huge = dir / "huge.ply";
  const std::uint64_t faces = physical_memory_bytes() / 16 + 1000;
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face " +
      std::to_string(faces) + "\nproperty list uchar int vertex_indices\nend_header\n";
  {
    std::ofstream out(huge, std::ios::binary);
    out << header;
  }
  std::filesystem::resize_file(huge, header.size() + 36 + 13 * faces);
  const std::string bunny_like = dir / "small.ply";
  write_mesh(bunny_like, test::sphere(2));
  for (const std::string& command :
       {"info " + huge, "decimate " + huge + " -o " + (dir / "out.ply") + " --ratio 0.1",
        "convert " + huge + " " + (dir / "out.stl"), "compare " + huge + " " + bunny_like,
        "compare " + bunny_like + " " + huge}) {
    SCOPED_TRACE(command);
    const CommandResult r = run(command, dir);
    EXPECT_EQ(r.exit_code, 2) << r.err;
    // The file named is the huge one, in either place (compare once named its first file, the small one).
    EXPECT_TRUE(r.err.starts_with("ocsimp: " + huge + ": ")) << r.err;
    EXPECT_NE(r.err.find(" in memory: about "), std::string::npos) << r.err;
    // compare counts both meshes' faces.
    const std::string counted = command.starts_with("compare")
                                    ? std::to_string(faces + test::sphere(2).face_count()) +
                                          " faces in all, " + std::to_string(faces) + " here"
                                    : std::to_string(faces) + " faces";
    EXPECT_NE(r.err.find(counted + ", more than the "), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out.ply"));
  EXPECT_FALSE(std::filesystem::exists(dir / "out.stl"));
  // The same commands take a mesh that fits.
  EXPECT_EQ(run("info " + bunny_like, dir).exit_code, 0);
}

// A memory limit below what clustering to the target needs cannot be kept: the target comes first (reached,
// out of core here), and the run says how much it may take. A limit that fits says nothing.
TEST(Cli, SimplifySaysWhenTheMemoryLimitIsTooSmallForTheTarget) {
  test::TempDir dir;
  const std::string mesh = dir / "scan.ply", out = dir / "out.ply";
  ASSERT_EQ(run("gen -q --triangles 200000 --seed 3 -o " + mesh, dir).exit_code, 0);
  for (const std::string command : {"simplify", "lod"}) {
    SCOPED_TRACE(command);
    const CommandResult tight =
        run(command + " -q " + mesh + " -o " + out + " --faces 20000 --memory-limit 2M", dir);
    ASSERT_EQ(tight.exit_code, 0) << tight.err;
    EXPECT_NE(tight.err.find("scan.ply: clustering to the target is expected to take about"),
              std::string::npos)
        << tight.err;
    EXPECT_NE(tight.err.find("over the memory limit of 2.0 MiB"), std::string::npos) << tight.err;
    const std::size_t faces = read_mesh(out).face_count();
    EXPECT_GE(faces, 19999u);
    EXPECT_LE(faces, 20000u);
    const CommandResult roomy =
        run(command + " -q " + mesh + " -o " + out + " --faces 20000 --memory-limit 1G", dir);
    ASSERT_EQ(roomy.exit_code, 0) << roomy.err;
    EXPECT_EQ(roomy.err.find("memory limit"), std::string::npos) << roomy.err;
  }
}

// The clustering pass's fine grid can hold up to about 4 times the cells planned for it; the estimate is
// made again from what the pass found, before it reads a face. The warning said 27 MiB for a run that took
// 44 (and 244 MiB for 547 on a 5 M scan to 500 k faces under 100 MB); decimating in core, where that takes
// less, is now chosen from the same count. AddressSanitizer's own memory would be counted in the peak.
TEST(Cli, SimplifyWarnsOfTheMemoryItThenTakes) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "the peak would include AddressSanitizer's shadow memory";
#endif
  test::TempDir dir;
  const std::string mesh = dir / "scan.ply", out = dir / "out.ply", report = dir / "r.json";
  ASSERT_EQ(run("gen -q --triangles 200000 --seed 5 -o " + mesh, dir).exit_code, 0);
  for (const char* faces : {"40000", "60000", "100000"}) {
    SCOPED_TRACE(faces);
    const CommandResult result = run(std::string("simplify -q ") + mesh + " -o " + out + " --faces " + faces +
                                         " --memory-limit 25M --report " + report,
                                     dir);
    ASSERT_EQ(result.exit_code, 0) << result.err;
    const nlohmann::json r = nlohmann::json::parse(file_bytes(report));
    const double peak = r["peak_rss_bytes"].get<double>();
    ASSERT_GT(peak, r["memory_limit_bytes"].get<double>());
    const std::string about = "expected to take about ";
    const std::size_t at = result.err.find(about);
    ASSERT_NE(at, std::string::npos) << result.err;
    const double expected = std::stod(result.err.substr(at + about.size())) * 1024 * 1024;  // MiB
    ASSERT_NE(result.err.find(" MiB", at), std::string::npos) << result.err;
    EXPECT_GT(expected, 0.8 * peak) << result.err;
    EXPECT_LT(expected, 1.25 * peak) << result.err;
  }
}

TEST(Cli, SimplifyAndLodWeldATriangleSoupByDefault) {
  // A sphere whose every triangle has its own three vertices, as some exporters write it. With --no-weld its
  // faces share no edge and are decimated as separate triangles (90 % of them deleted); welded (the
  // default), it is one closed surface again.
  test::TempDir dir;
  const IndexedMesh sphere = test::sphere(4);
  const std::string input = dir / "soup.ply";
  write_mesh(input, test::triangle_soup(sphere));
  const std::uint64_t target = sphere.face_count() / 10;
  for (const std::string command : {"simplify", "lod"}) {  // lod: one level, so a plain output name
    for (bool weld : {false, true}) {
      const std::string output = dir / (command + (weld ? "_welded.ply" : "_soup.ply"));
      const CommandResult r = run(command + " -q " + input + " -o " + output + " --faces " +
                                      std::to_string(target) + (weld ? "" : " --no-weld"),
                                  dir);
      ASSERT_EQ(r.exit_code, 0) << r.err;
      const IndexedMesh out = read_mesh(output);
      EXPECT_EQ(out.face_count(), target) << command;
      const MeshTopology t = analyze_topology(out);
      if (weld) {
        EXPECT_EQ(t.components, 1u) << command;
        EXPECT_EQ(t.boundary_edges, 0u) << command;
      } else {
        EXPECT_EQ(t.components, target) << command;
      }
    }
  }
}

// Starts `ocsimp args...` with TMPDIR set, kills it with `signal` after `delay`, and says whether the signal
// is what ended it (it was still running).
bool killed_mid_run(const std::vector<std::string>& args, const std::string& tmpdir, int signal,
                    std::chrono::milliseconds delay) {
  const pid_t child = fork();
  if (child < 0) return false;
  if (child == 0) {
    ::setenv("TMPDIR", tmpdir.c_str(), 1);
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(kOcsimp.c_str()));
    for (const std::string& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
    argv.push_back(nullptr);
    execv(kOcsimp.c_str(), argv.data());
    _exit(127);
  }
  std::this_thread::sleep_for(delay);
  kill(child, signal);
  int status = 0;
  waitpid(child, &status, 0);
  return WIFSIGNALED(status) && WTERMSIG(status) == signal;
}

// killed_mid_run at half of what a whole run takes here, then at ever shorter delays until the signal lands
// while the command still runs; outputs of runs that finished first are removed in between. Fixed delays
// (400 ms first) could land after the output's rename, in the last moments of a run that then took about
// 400 ms, and the output rightly existed.
bool killed_while_running(const std::vector<std::string>& args, const std::string& tmpdir, int signal,
                          const std::vector<std::string>& outputs) {
  const auto start = std::chrono::steady_clock::now();
  if (killed_mid_run(args, tmpdir, 0, std::chrono::milliseconds(0))) return false;  // signal 0: a whole run
  const auto whole =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - start);
  for (auto delay = whole / 2; delay.count() > 0; delay /= 2) {
    for (const std::string& output : outputs) std::filesystem::remove(output);
    if (killed_mid_run(args, tmpdir, signal, delay)) return true;
  }
  return false;
}

TEST(Cli, InterruptedSimplifyAndLodLeaveNoOutput) {
  test::TempDir dir;
  const std::string scan = dir / "scan.ply", tmp = dir / "tmp", out = dir / "out.ply";
  std::filesystem::create_directories(tmp);
  ASSERT_EQ(run("gen -q --triangles 1500000 -o " + scan, dir).exit_code, 0);
  const auto before = names_in(dir.path);

  // SIGTERM: the AtomicFile handler removes its temporary too, so the folder is as it was.
  EXPECT_TRUE(
      killed_while_running({"simplify", "-q", scan, "-o", out, "--faces", "1000"}, tmp, SIGTERM, {out}));
  EXPECT_EQ(names_in(dir.path), before);
  // SIGKILL through the out-of-core path: the dereferencing files were unlinked when created, so TMPDIR is
  // empty, and the output's temporary has no name until it is complete, so the folder is as it was too.
  EXPECT_TRUE(killed_while_running(
      {"simplify", "-q", scan, "-o", out, "--faces", "1000", "--memory-limit", "8M"}, tmp, SIGKILL, {out}));
  EXPECT_FALSE(std::filesystem::exists(out));
  EXPECT_TRUE(names_in(tmp).empty());
  EXPECT_EQ(names_in(dir.path), before);
  // lod's first level is done early, and was then left on its own; the levels now appear together.
  const std::string lod_big = dir / "lod_1400000.ply", lod_100 = dir / "lod_100.ply";
  for (int signal : {SIGTERM, SIGKILL}) {
    EXPECT_TRUE(
        killed_while_running({"lod", "-q", scan, "-o", dir / "lod_{faces}.ply", "--faces", "1400000,100"},
                             tmp, signal, {lod_big, lod_100}));
    EXPECT_FALSE(std::filesystem::exists(lod_big));
    EXPECT_FALSE(std::filesystem::exists(lod_100));
    EXPECT_EQ(names_in(dir.path), before);
  }
}

}  // namespace
}  // namespace ocsimp
