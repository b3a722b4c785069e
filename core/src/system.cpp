#include "ocsimp/core/system.h"

#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#if defined(__linux__)
#include <sys/mman.h>
#endif
#include <sys/resource.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "ocsimp/core/big_vector.h"
#include "ocsimp/core/error.h"

namespace ocsimp {

int worker_threads(int requested) {
  const int cores = std::max(1, tbb::info::default_concurrency());
  return requested > 0 ? std::min(requested, cores) : cores;
}

namespace {

// The limit in a control group's memory file, 0 for none ("max", or v1's page-rounded 2^63).
std::uint64_t limit_in(const std::string& file) {
  std::ifstream in(file);
  std::string text;
  if (!(in >> text) || text.empty() || !std::isdigit(static_cast<unsigned char>(text[0]))) return 0;
  const std::uint64_t bytes = std::strtoull(text.c_str(), nullptr, 10);
  return bytes < (std::uint64_t{1} << 60) ? bytes : 0;
}

}  // namespace

std::uint64_t control_group_memory_limit() {
  // The groups this process is in (/proc/self/cgroup: "0::/path" for v2, "N:...memory...:/path" for v1), and
  // every group above them, whose limits apply too. A container usually sees its own group as the root.
  std::vector<std::string> files;
  std::ifstream groups("/proc/self/cgroup");
  std::string line;
  while (std::getline(groups, line)) {
    const std::size_t first = line.find(':'), second = line.find(':', first + 1);
    if (first == std::string::npos || second == std::string::npos) continue;
    const std::string controllers = line.substr(first + 1, second - first - 1);
    std::string path = line.substr(second + 1);
    std::vector<std::string> roots;
    std::string file;
    if (controllers.empty()) {
      roots = {"/sys/fs/cgroup", "/sys/fs/cgroup/unified"};
      file = "/memory.max";
    } else if (("," + controllers + ",").find(",memory,") != std::string::npos) {
      roots = {"/sys/fs/cgroup/memory"};
      file = "/memory.limit_in_bytes";
    } else {
      continue;
    }
    while (true) {
      for (const std::string& root : roots) files.push_back(root + (path == "/" ? "" : path) + file);
      const std::size_t slash = path.rfind('/');
      if (path == "/" || slash == std::string::npos) break;
      path = path.substr(0, std::max<std::size_t>(slash, 1));
    }
  }
  std::uint64_t limit = 0;
  for (const std::string& file : files) {
    const std::uint64_t bytes = limit_in(file);
    if (bytes > 0) limit = limit == 0 ? bytes : std::min(limit, bytes);
  }
  return limit;
}

std::uint64_t address_space_limit() {
  rlimit limit{};
  if (getrlimit(RLIMIT_AS, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return 0;
  return static_cast<std::uint64_t>(limit.rlim_cur);
}

std::uint64_t physical_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page_size = sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page_size <= 0) return 0;
  const std::uint64_t physical = static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page_size);
  const std::uint64_t group = control_group_memory_limit();
  return group > 0 ? std::min(physical, group) : physical;
}

namespace {

std::uint64_t status_field_kib(const char* field) {
  std::ifstream status("/proc/self/status");
  std::string line;
  const std::size_t length = std::strlen(field);
  while (std::getline(status, line)) {
    if (line.compare(0, length, field) == 0) return std::strtoull(line.c_str() + length, nullptr, 10) * 1024;
  }
  return 0;
}

}  // namespace

std::uint64_t peak_rss_bytes() {
  return status_field_kib("VmHWM:");
}
std::uint64_t current_rss_bytes() {
  return status_field_kib("VmRSS:");
}

std::uint64_t parse_byte_size(std::string_view text) {
  const std::string s(text);
  auto refuse = [&s](const std::string& why) {
    throw Error("not a size: '" + s + "' (" + why + "; expected e.g. 2G, 512M, 1.5GiB, 100000)");
  };
  // Plain decimal digits only: strtod also took "0x10", "1e3", " 2G" and "inf", and read them by the locale.
  auto is_digit = [&s](std::size_t i) {
    return i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]));
  };
  std::size_t used = 0, digits = 0;
  for (; is_digit(used); ++used) ++digits;
  if (used < s.size() && s[used] == '.') {
    for (++used; is_digit(used); ++used) ++digits;
  }
  if (digits == 0) refuse("no number");
  double value = 0;
  // Out of range only past the doubles (hundreds of digits), where it left `value` at 0.
  if (std::from_chars(s.data(), s.data() + used, value).ec != std::errc()) refuse("past 64 bits");
  std::string unit;
  for (std::size_t i = used; i < s.size(); ++i)
    unit += static_cast<char>(std::toupper(static_cast<unsigned char>(s[i])));
  double scale = 0;
  if (unit.empty() || unit == "B")
    scale = 1;
  else if (unit == "K" || unit == "KB" || unit == "KIB")
    scale = 1024.0;
  else if (unit == "M" || unit == "MB" || unit == "MIB")
    scale = 1024.0 * 1024;
  else if (unit == "G" || unit == "GB" || unit == "GIB")
    scale = 1024.0 * 1024 * 1024;
  else if (unit == "T" || unit == "TB" || unit == "TIB")
    scale = 1024.0 * 1024 * 1024 * 1024;
  else if (unit == "P" || unit == "PB" || unit == "PIB")  // the same size in K was accepted
    scale = 1024.0 * 1024 * 1024 * 1024 * 1024;
  else if (unit == "E" || unit == "EB" || unit == "EIB")
    scale = 1024.0 * 1024 * 1024 * 1024 * 1024 * 1024;
  if (scale == 0) refuse("an unknown unit '" + s.substr(used) + "'");
  // "1.5" bytes was taken as 1; a fraction of a larger unit is rounded down to the byte.
  if (scale == 1 && value != std::floor(value)) refuse("a fraction of a byte");
  if (value * scale > 1.8e19) refuse("past 64 bits");
  return static_cast<std::uint64_t>(value * scale);
}

std::string format_bytes(std::uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double value = static_cast<double>(bytes);
  int unit = 0;
  while (value >= 1024 && unit < 4) {
    value /= 1024;
    ++unit;
  }
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, unit == 0 ? "%.0f %s" : "%.1f %s", value, units[unit]);
  return buffer;
}

// The kernel zeroes a page at its first touch, which on a VM costs far more than writing the page (about
// 0.5 GB/s here). Touched in the loops that fill these arrays, that cost fell on whichever thread wrote
// first: the decimator's vertex records are zeroed one by one as `resize` constructs them, so on a 10
// M-triangle mesh a serial loop took a tenth of the decimation's CPU time in page faults. Touching every page
// here, on all cores, keeps it off the serial loops. (Fresh pages read as zero: writing a zero changes
// nothing.)
void* allocate_huge(std::size_t bytes) {
#if defined(__linux__)
  void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
  madvise(p, bytes, MADV_HUGEPAGE);  // advice only: without huge pages the memory works the same
  constexpr std::size_t kPage = 4096, kPiece = std::size_t{2} << 20;
  tbb::parallel_for(std::size_t{0}, (bytes + kPiece - 1) / kPiece, [&](std::size_t piece) {
    const std::size_t end = std::min(bytes, (piece + 1) * kPiece);
    for (std::size_t at = piece * kPiece; at < end; at += kPage) static_cast<volatile char*>(p)[at] = 0;
  });
  return p;
#else
  return ::operator new (bytes, std::align_val_t{64});
#endif
}

void free_huge(void* p, std::size_t bytes) noexcept {
#if defined(__linux__)
  munmap(p, bytes);
#else
  (void)bytes;
  ::operator delete (p, std::align_val_t{64});
#endif
}

}  // namespace ocsimp
