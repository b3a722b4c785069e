#include "ocsimp/streaming/atomic_file.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace ocsimp
