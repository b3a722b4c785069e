// The `ocsimp` binary end to end: exit codes, one-line errors, atomic outputs, determinism of `gen`.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

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
  for (const char* command : {"info", "convert", "gen"}) EXPECT_NE(top.out.find(command), std::string::npos) << command;
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
}

TEST(Cli, GenIsDeterministicAndInfoCountsIt) {
  test::TempDir dir;
  ASSERT_EQ(run("gen -q -o " + (dir / "a.ply") + " --triangles 20000 --seed 3", dir).exit_code, 0);
  ASSERT_EQ(run("gen -q -o " + (dir / "b.ply") + " --triangles 20000 --seed 3 --threads 1", dir).exit_code, 0);
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

TEST(Cli, BadInputGivesOneLineNamingTheFileAndExit2) {
  test::TempDir dir;
  const std::string bad = dir / "bad.ply";
  std::ofstream(bad) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
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

TEST(Cli, InterruptedGenLeavesNoFile) {
  test::TempDir dir;
  const std::string out = dir / "big.ply";
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    execl(kOcsimp.c_str(), kOcsimp.c_str(), "gen", "-q", "-o", out.c_str(), "--triangles", "400000000",
          static_cast<char*>(nullptr));
    _exit(127);
  }
  // Wait until the temporary exists, so the kill lands mid-write.
  bool started = false;
  for (int i = 0; i < 200 && !started; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    for (const auto& entry : std::filesystem::directory_iterator(dir.path)) {
      if (entry.path().filename().string().find("big.ply") != std::string::npos) started = true;
    }
  }
  EXPECT_TRUE(started);
  kill(child, SIGTERM);
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_TRUE(WIFSIGNALED(status));
  for (const auto& entry : std::filesystem::directory_iterator(dir.path)) {
    EXPECT_EQ(entry.path().filename().string().find("big.ply"), std::string::npos) << entry.path();
  }
}

}  // namespace
}  // namespace ocsimp
