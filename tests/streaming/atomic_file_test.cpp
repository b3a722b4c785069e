#include "ocsimp/streaming/atomic_file.h"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <string>

#include "ocsimp/core/error.h"
#include "test_support.h"

namespace ocsimp {
namespace {

// A second commit renamed a temporary whose name had been spent (a heap write past a string's end, then a
// double free); writing after a commit went nowhere yet counted as written. Both are errors now, and the
// committed file stays as it was.
TEST(AtomicFile, NothingIsWrittenOrCommittedTwice) {
  test::TempDir dir;
  const std::string path = dir / "out.txt";
  AtomicFile file(path);
  file.write("abc");
  file.commit();
  EXPECT_THROW(file.commit(), Error);
  EXPECT_THROW(file.write("def"), Error);
  EXPECT_THROW(file.reserve(3), Error);
  EXPECT_EQ(test::file_bytes(path), "abc");
  std::size_t entries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path)) {
    (void)entry;
    ++entries;
  }
  EXPECT_EQ(entries, 1u);  // no temporary left beside it
}

// lod's levels appear together: a run that failed or was interrupted after its first level left it behind.
TEST(AtomicFile, HeldCommitsAppearTogetherOrNotAtAll) {
  test::TempDir dir;
  auto entries = [&] {
    std::size_t n = 0;
    for (const auto& entry : std::filesystem::directory_iterator(dir.path)) n += !entry.path().empty();
    return n;
  };
  {
    HeldCommits held;
    AtomicFile a(dir / "a.txt"), b(dir / "b.txt");
    a.write("a");
    a.commit();
    b.write("b");
    b.commit();
    EXPECT_EQ(entries(), 0u);            // complete, but not there yet
    EXPECT_THROW(HeldCommits(), Error);  // one at a time
    held.release();
    EXPECT_EQ(test::file_bytes(dir / "a.txt"), "a");
    EXPECT_EQ(test::file_bytes(dir / "b.txt"), "b");
  }
  {
    HeldCommits held;
    AtomicFile c(dir / "c.txt");
    c.write("c");
    c.commit();
  }  // never released: gone
  EXPECT_EQ(entries(), 2u);
  AtomicFile d(dir / "d.txt");  // no HeldCommits alive: at once
  d.write("d");
  d.commit();
  EXPECT_EQ(test::file_bytes(dir / "d.txt"), "d");
}

// A signal in the moment a set of held outputs is renamed into place waits for the last rename: a SIGINT
// between the mesh's rename and its report's left the mesh without the report (and one between naming a
// temporary and registering it left the temporary). Here the signal comes from inside the scope, where the
// renames would be; the process finishes the scope, then dies of it.
TEST(AtomicFile, ASignalWaitsForTheRenamesInPlace) {
  test::TempDir dir;
  const std::string marker = dir / "after.txt";
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    with_signals_deferred([&] {
      ::raise(SIGTERM);
      AtomicFile file(marker);  // still running: the signal waits
      file.write("x");
      file.commit();
    });
    _exit(0);  // not reached: the call's end raised the signal again
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << status;
  EXPECT_EQ(test::file_bytes(marker), "x");
}

}  // namespace
}  // namespace ocsimp
