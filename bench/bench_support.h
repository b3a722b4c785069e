// Small helpers the end-to-end benchmark programs share: process CPU time, medians, comma lists, distances.
#pragma once

#include <time.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

namespace ocsimp::bench {

// CPU seconds of the whole process (all threads): on a shared machine, wall time also counts other users'
// load.
inline double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// The upper median (the middle element after sorting; 0 for none).
inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// "0.1,0.02" -> {0.1, 0.02}; throws std::invalid_argument on a malformed number.
inline std::vector<double> parse_list(const std::string& text) {
  std::vector<double> out;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = text.find(',', start);
    out.push_back(std::stod(text.substr(start, comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

// A Hausdorff distance printed with `format`, and a "+" when it is a lower bound: `settled` false says a
// refinement ran out of queries before settling its maximum (tools/compare.h: SurfaceDistance's
// hausdorff_settled()).
inline std::string hausdorff_text(double value, bool settled, const char* format) {
  char text[48];
  std::snprintf(text, sizeof text, format, value);
  return settled ? std::string(text) : std::string(text) + "+";
}

}  // namespace ocsimp::bench
