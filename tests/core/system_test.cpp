#include "ocsimp/core/system.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <string>

#include "ocsimp/core/error.h"

namespace ocsimp {
namespace {

TEST(System, ParsesByteSizes) {
  EXPECT_EQ(parse_byte_size("2G"), 2ull << 30);
  EXPECT_EQ(parse_byte_size("512m"), 512ull << 20);
  EXPECT_EQ(parse_byte_size("1.5GiB"), 3ull << 29);
  EXPECT_EQ(parse_byte_size("100000"), 100000ull);
  // Every size up to the largest 64 bits hold has a unit: 1P was refused where 1099511627776K was taken.
  EXPECT_EQ(parse_byte_size("1P"), 1ull << 50);
  EXPECT_EQ(parse_byte_size("1099511627776K"), 1ull << 50);
  EXPECT_EQ(parse_byte_size("8EiB"), 8ull << 60);
  EXPECT_THROW(parse_byte_size("16E"), Error);  // past 64 bits
  EXPECT_THROW(parse_byte_size("lots"), Error);
  EXPECT_THROW(parse_byte_size("2X"), Error);
  EXPECT_THROW(parse_byte_size("-1G"), Error);
  EXPECT_EQ(parse_byte_size(".5K"), 512u);
  EXPECT_EQ(parse_byte_size("0.3K"), 307u);  // a fraction of a unit rounds down to the byte
  // Only plain decimals: these were read as 16, 1000, 1 and 2 GiB.
  EXPECT_THROW(parse_byte_size(std::string(400, '9')), Error);  // past the doubles: it was read as 0
  for (const char* odd : {"0x10", "1e3", "1.5", " 2G", "2 G", "inf", "nan", "", ".", "+1G", "1..5G"})
    EXPECT_THROW(parse_byte_size(odd), Error) << odd;
}

TEST(System, ReportsMemory) {
  EXPECT_GT(physical_memory_bytes(), 0u);
  // Never more than the machine has, nor than a control group allows.
  EXPECT_LE(physical_memory_bytes(), static_cast<std::uint64_t>(sysconf(_SC_PHYS_PAGES)) *
                                         static_cast<std::uint64_t>(sysconf(_SC_PAGE_SIZE)));
  if (control_group_memory_limit() > 0) {
    EXPECT_LE(physical_memory_bytes(), control_group_memory_limit());
  }
  EXPECT_GT(peak_rss_bytes(), 0u);
  EXPECT_GE(peak_rss_bytes(), current_rss_bytes() / 2);
}

TEST(System, WorkerThreadsNeverExceedTheCores) {
  const int cores = worker_threads(0);
  EXPECT_GE(cores, 1);
  EXPECT_EQ(worker_threads(-3), cores);
  EXPECT_EQ(worker_threads(1), 1);
  EXPECT_EQ(worker_threads(cores), cores);
  EXPECT_EQ(worker_threads(100000), cores);
}

TEST(Error, MessageNamesFilePlaceAndReason) {
  EXPECT_STREQ(Error("a.ply", FilePosition::byte(12), "bad").what(), "a.ply: byte 12: bad");
  EXPECT_STREQ(Error("a.obj", FilePosition::line(3), "bad").what(), "a.obj: line 3: bad");
  EXPECT_STREQ(Error("just this").what(), "just this");
}

TEST(Error, ControlCharactersQuotedFromAFilePrintAsQuestionMarks) {
  // A NUL ended the printed message early; an escape sequence reached the terminal.
  const Error e("a.ply", FilePosition::line(11),
                std::string("'0\0x' and '\x1b[2Jz\nx\x7f' are not numbers", 36));
  EXPECT_STREQ(e.what(), "a.ply: line 11: '0?x' and '?[2Jz?x?' are not numbers");
}

}  // namespace
}  // namespace ocsimp
