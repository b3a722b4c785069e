// What the commands share: the progress bar and JSON reports.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "ocsimp/streaming/atomic_file.h"

namespace ocsimp::cli {
namespace {

// Redraws at most ten times a second; remembers the phase so a new phase starts a new line.
struct ProgressBar {
  using Clock = std::chrono::steady_clock;
  std::string phase;
  Clock::time_point phase_start = Clock::now();
  Clock::time_point last_draw{};
  bool line_open = false;

  void update(std::string_view new_phase, std::uint64_t done, std::uint64_t total) {
    const auto now = Clock::now();
    if (new_phase != phase) {
      finish_line();
      phase = std::string(new_phase);
      phase_start = now;
      last_draw = {};
    }
    const bool complete = total > 0 && done >= total;
    if (!complete && now - last_draw < std::chrono::milliseconds(100)) return;
    last_draw = now;
    const double seconds = std::chrono::duration<double>(now - phase_start).count();
    const double rate = seconds > 0 ? static_cast<double>(done) / seconds : 0.0;
    char line[160];
    if (total > 0) {
      const double fraction = std::min(1.0, static_cast<double>(done) / static_cast<double>(total));
      char bar[31];
      const int filled = static_cast<int>(fraction * 30);
      for (int i = 0; i < 30; ++i) bar[i] = i < filled ? '#' : '.';
      bar[30] = 0;
      const double left = rate > 0 ? static_cast<double>(total - std::min(done, total)) / rate : 0.0;
      std::snprintf(line, sizeof line, "\r%-10s [%s] %5.1f%%  %s/s  %4.0fs left ", phase.c_str(), bar,
                    100.0 * fraction, human(rate).c_str(), left);
    } else {
      std::snprintf(line, sizeof line, "\r%-10s %s  %s/s ", phase.c_str(),
                    human(static_cast<double>(done)).c_str(), human(rate).c_str());
    }
    std::fputs(line, stderr);
    line_open = true;
    if (complete) finish_line();
  }

  void finish_line() {
    if (line_open) std::fputc('\n', stderr);
    line_open = false;
  }

  ~ProgressBar() { finish_line(); }

  static std::string human(double value) {
    char text[32];
    if (value >= 1e9)
      std::snprintf(text, sizeof text, "%.2fG", value / 1e9);
    else if (value >= 1e6)
      std::snprintf(text, sizeof text, "%.2fM", value / 1e6);
    else if (value >= 1e3)
      std::snprintf(text, sizeof text, "%.1fk", value / 1e3);
    else
      std::snprintf(text, sizeof text, "%.0f", value);
    return text;
  }
};

}  // namespace

ProgressFn make_progress(bool quiet) {
  if (quiet || !::isatty(STDERR_FILENO)) return {};
  auto bar = std::make_shared<ProgressBar>();
  return [bar](std::string_view phase, std::uint64_t done, std::uint64_t total) {
    bar->update(phase, done, total);
  };
}

void write_json_report(const std::string& path, const nlohmann::json& report) {
  AtomicFile file(path);
  file.write(report.dump(2));
  file.write("\n");
  file.commit();
}

}  // namespace ocsimp::cli
