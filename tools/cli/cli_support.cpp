// What the commands share: the progress bar, timing, the summary table and JSON reports.
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.h"
#include "ocsimp/core/error.h"
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
    // A rate over less than a tenth of a second says nothing ("write 100.0%  0 faces/s"): left blank.
    const bool timed = seconds >= 0.1;
    const std::string speed = timed ? human(rate) + unit(phase) + "/s" : "";
    // A line longer than the terminal wraps, and the next '\r' then returns only to its last row: every
    // redraw scrolled a row on an 80-column terminal. So the bar narrows to fit, and the line is cut to the
    // width if that is not enough; the width is asked each time, since the window may be resized.
    std::size_t columns = 0;
    winsize size{};
    if (::ioctl(STDERR_FILENO, TIOCGWINSZ, &size) == 0) columns = size.ws_col;
    char line[160];
    if (total > 0) {
      const double fraction = std::min(1.0, static_cast<double>(done) / static_cast<double>(total));
      const double left = rate > 0 ? static_cast<double>(total - std::min(done, total)) / rate : 0.0;
      char rest[96];
      if (timed) {
        std::snprintf(rest, sizeof rest, " %5.1f%%  %s  %4.0fs left ", 100.0 * fraction, speed.c_str(), left);
      } else {
        std::snprintf(rest, sizeof rest, " %5.1f%% ", 100.0 * fraction);
      }
      // The widest the rest gets (human() gives at most 6 characters below 1000G, and 4 digits of seconds),
      // so that the bar keeps its width from one redraw to the next.
      const std::size_t others = std::max<std::size_t>(phase.size(), 17) + 3 +
                                 std::strlen(" 100.0%  999.9k/s  9999s left ") + std::strlen(unit(phase));
      const std::size_t width =
          columns > others + 10 ? std::min<std::size_t>(30, columns - 1 - others) : std::size_t{10};
      char bar[31];
      const auto filled = static_cast<std::size_t>(fraction * static_cast<double>(width));
      for (std::size_t i = 0; i < width; ++i) bar[i] = i < filled ? '#' : '.';
      bar[width] = 0;
      std::snprintf(line, sizeof line, "\r%-17s [%s]%s", phase.c_str(), bar, rest);
    } else {
      std::snprintf(line, sizeof line, "\r%-17s %s%s  %s ", phase.c_str(),
                    human(static_cast<double>(done)).c_str(), unit(phase), speed.c_str());
    }
    // Columns, plus the leading '\r', less one so the cursor stays on the row.
    if (columns > 1 && std::strlen(line) > columns) line[columns] = 0;
    std::fputs(line, stderr);
    line_open = true;
    if (complete) finish_line();
  }

  void finish_line() {
    if (line_open) std::fputc('\n', stderr);
    line_open = false;
  }

  ~ProgressBar() { finish_line(); }

  // What the stages count (core/system.h leaves units to the phase): readers and the cluster pass report
  // bytes of input, the decimator collapses, writers faces.
  static const char* unit(std::string_view phase) {
    if (phase.starts_with("read") || phase == "cluster: faces") return "B";
    if (phase == "dereference") return " partitions";  // of the vertex array, each a pass over the faces
    if (phase == "decimate") return " collapses";
    if (phase == "write" || phase == "generate") return " faces";
    return "";
  }

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

// A check of a floating-point flag: the whole text is a decimal number (or "inf"; never NaN) that passes
// `accepts`, or the message says the flag takes `wanted`. Decimal, as from_chars reads it: CLI11 would also
// take strtod's hexadecimal ("0x10" for 16), which the integer flags and the file readers refuse.
template <class Accepts>
CLI::Validator number_check(const std::string& wanted, Accepts accepts) {
  return CLI::Validator(
      [wanted, accepts](std::string& text) -> std::string {
        double value = 0;
        const char* end = text.data() + text.size();
        const auto [stop, error] = std::from_chars(text.data(), end, value);
        if (error == std::errc() && stop == end && !std::isnan(value) && accepts(value)) return {};
        return "'" + text + "' is not " + wanted;
      },
      wanted);
}

// Every comma separates two items, so "0.1," has an empty one, as ",0.1" does; each item must be `valid`,
// and no item may come twice (CLI11's own lists dropped empty items and kept repeated ones, so bench ran a
// target twice). `parse` reads an item as std::stoull and std::stod do (the value, and the characters
// used), which must be the whole item; `expected` says what an item must be.
template <class T, class Parse, class Valid>
std::vector<T> parse_list(const std::string& text, const std::string& flag, const Parse& parse,
                          const Valid& valid, const std::string& expected) {
  std::vector<T> items;
  for (std::size_t start = 0; start <= text.size();) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    const std::string item = text.substr(start, comma - start);
    start = comma + 1;
    T value{};
    bool whole = false;
    try {
      std::size_t used = 0;
      value = parse(item, &used);
      whole = used != 0 && used == item.size();
    } catch (const std::exception&) {
    }
    if (!whole || !valid(item, value)) throw Error(flag + ": '" + item + "' is not " + expected);
    if (std::find(items.begin(), items.end(), value) != items.end())
      throw Error(flag + ": '" + item + "' is given twice");
    items.push_back(value);
  }
  return items;
}

}  // namespace

CLI::Validator whole_number(std::uint64_t low, std::uint64_t high) {
  const std::string wanted =
      high == std::numeric_limits<std::uint64_t>::max()
          ? "a whole number >= " + std::to_string(low)
          : "a whole number from " + std::to_string(low) + " to " + std::to_string(high);
  return CLI::Validator(
      [low, high, wanted](std::string& text) -> std::string {
        std::uint64_t value = 0;
        const char* end = text.data() + text.size();
        const auto [stop, error] = std::from_chars(text.data(), end, value);
        // (from_chars refuses an empty string, a sign and anything but digits.)
        if (error != std::errc() || stop != end || value < low || value > high)
          return "'" + text + "' is not " + wanted;
        // CLI11 then converts the text as strtoull with base 0 does, reading "010" as octal 8: it gets the
        // decimal digits alone (whole_number is a transform, so the text it leaves is what is converted).
        text = std::to_string(value);
        return {};
      },
      wanted);
}

CLI::Validator file_name() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        if (text.empty()) return "an empty file name";
        // CLI11 gives an option the next word even when it is a flag: `-o --faces 100` wrote the mesh to a
        // file named "--faces" and then called 100 unexpected. A file of that name is still ./--faces.
        if (text.size() > 1 && text[0] == '-')
          return "'" + text + "' is an option, not a file name (./" + text + " names such a file)";
        return {};
      },
      "FILE");
}

std::vector<std::uint64_t> parse_face_list(const std::string& text, const std::string& flag) {
  return parse_list<std::uint64_t>(
      text, flag, [](const std::string& item, std::size_t* used) { return std::stoull(item, used); },
      [](const std::string& item, std::uint64_t value) { return value > 0 && item[0] != '-'; },
      "a face count (give positive integers separated by commas)");
}

std::vector<double> parse_ratio_list(const std::string& text, const std::string& flag) {
  return parse_list<double>(
      text, flag, [](const std::string& item, std::size_t* used) { return std::stod(item, used); },
      [](const std::string&, double value) { return value > 0 && value <= 1; },
      "a ratio of the input's faces (give numbers in (0, 1] separated by commas)");
}

std::vector<std::string> parse_name_list(const std::string& text, const std::string& flag) {
  return parse_list<std::string>(
      text, flag,
      [](const std::string& item, std::size_t* used) {
        *used = item.size();
        return item;
      },
      [](const std::string& item, const std::string&) { return !item.empty(); },
      "a name (give names separated by commas)");
}

void add_weld_flag(CLI::App* cmd, bool& weld) {
  // Two flags rather than CLI11's "--weld,!--no-weld", whose help read "--weld,--no-weld{false}", as if
  // welding were off by default.
  CLI::Option* on = cmd->add_flag_callback(
      "--weld", [&weld] { weld = true; },
      "Merge vertices at exactly equal positions before decimating, so seams and the corners of a triangle "
      "soup move as one (the default; each side of a texture or normal seam keeps its attributes)");
  cmd->add_flag_callback(
         "--no-weld", [&weld] { weld = false; }, "Do not weld: each copy is a separate border")
      ->excludes(on);
}

CLI::Validator byte_size() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        try {
          if (parse_byte_size(text) == 0) return "'" + text + "' is less than a byte";
        } catch (const Error& e) {
          return e.reason();
        }
        return {};
      },
      "a size such as 2G, 512M or 100000 (bytes)");
}

CLI::Validator non_negative_number(bool or_infinity) {
  return number_check(or_infinity ? "a number >= 0 (inf: no bound)" : "a finite number >= 0",
                      [or_infinity](double v) { return v >= 0 && (or_infinity || !std::isinf(v)); });
}

CLI::Validator positive_number() {
  return number_check("a finite number > 0", [](double v) { return v > 0 && !std::isinf(v); });
}

CLI::Validator fraction() {
  return number_check("a number in (0, 1]", [](double v) { return v > 0 && v <= 1; });
}

CLI::Validator thread_count() {
  return whole_number(0, 4096);
}

ProgressFn make_progress(bool quiet) {
  return make_console(quiet, "").progress;
}

Console make_console(bool quiet, const std::string& input) {
  Console console;
  auto bar = (quiet || !::isatty(STDERR_FILENO)) ? nullptr : std::make_shared<ProgressBar>();
  if (bar) {
    console.progress = [bar](std::string_view phase, std::uint64_t done, std::uint64_t total) {
      bar->update(phase, done, total);
    };
  }
  console.warn = [bar, input](const std::string& message) {
    if (bar) bar->finish_line();
    std::fprintf(stderr, "ocsimp: warning: %s: %s\n", input.c_str(), message.c_str());
  };
  return console;
}

void warn_if_over_memory_limit(const Console& console, std::uint64_t memory_limit) {
  const std::uint64_t peak = peak_rss_bytes();
  if (memory_limit > 0 && peak > memory_limit && console.warn) {
    console.warn("the run's peak memory, " + format_bytes(peak) + ", went over the memory limit of " +
                 format_bytes(memory_limit));
  }
}

std::unique_ptr<tbb::global_control> limit_threads(int threads) {
  if (threads <= 0) return nullptr;
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               worker_threads(threads));
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

bool is_standard_output(const std::string& path) {
  struct stat file {
  }, out{};
  return !path.empty() && ::stat(path.c_str(), &file) == 0 && ::fstat(STDOUT_FILENO, &out) == 0 &&
         file.st_dev == out.st_dev && file.st_ino == out.st_ino;
}

bool show_summary(bool quiet, const std::string& report) {
  return !quiet && !is_standard_output(report);
}

std::string seam_copies_note(std::uint64_t copies) {
  return copies > 0 ? " (+" + std::to_string(copies) + " copies along seams)" : "";
}

void print_phase_table(const std::vector<PhaseReport>& phases) {
  std::printf("%-14s %10s %14s %14s %12s\n", "phase", "seconds", "triangles in", "triangles out", "peak RSS");
  for (const PhaseReport& p : phases) {
    std::printf("%-14s %10.3f %14llu %14llu %12s\n", p.name.c_str(), p.seconds,
                static_cast<unsigned long long>(p.triangles_in),
                static_cast<unsigned long long>(p.triangles_out), format_bytes(p.peak_rss_bytes).c_str());
  }
}

nlohmann::json phases_json(const std::vector<PhaseReport>& phases) {
  nlohmann::json array = nlohmann::json::array();
  for (const PhaseReport& p : phases) {
    array.push_back({{"name", p.name},
                     {"seconds", p.seconds},
                     {"triangles_in", p.triangles_in},
                     {"triangles_out", p.triangles_out},
                     {"peak_rss_bytes", p.peak_rss_bytes}});
  }
  return array;
}

void write_result(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options) {
  write_mesh(path, mesh, options);
  const FileFormat format = options.format ? *options.format : format_from_extension(path);
  if (mesh.origin != Vec3d::Zero() && !holds_origin(format)) {
    std::fprintf(stderr,
                 "ocsimp: warning: %s holds float coordinates only: the mesh's coordinates, far from zero "
                 "(%.17g, %.17g, %.17g), lose precision there; write PLY or OBJ to keep it\n",
                 path.c_str(), mesh.origin.x(), mesh.origin.y(), mesh.origin.z());
  }
  if (mesh.triangles.empty()) {
    std::fprintf(stderr,
                 "ocsimp: warning: %s has no faces (%zu vertices): only info and convert read such a file\n",
                 path.c_str(), mesh.positions.size());
  }
  // What the format has no place for: lost without a word, the user had no reason to look.
  std::vector<const char*> parts;
  if (format == FileFormat::stl) {
    if (mesh.has_normals()) parts.push_back("normals");
    if (mesh.has_colors()) parts.push_back("colors");
    if (mesh.has_uvs()) parts.push_back("texture coordinates");
  } else if (format == FileFormat::obj && mesh.has_colors() &&
             std::any_of(mesh.colors.begin(), mesh.colors.end(),
                         [](const Color& c) { return c[3] != 255; })) {
    parts.push_back("color alpha");  // OBJ's "v x y z r g b" has no fourth channel
  }
  if (!parts.empty()) {
    std::string lost;
    for (std::size_t i = 0; i < parts.size(); ++i)
      lost.append(i == 0 ? "" : i + 1 == parts.size() ? " and " : ", ").append(parts[i]);
    std::fprintf(stderr, "ocsimp: warning: %s: %s has no place for the mesh's %s: not written\n",
                 path.c_str(), format_name(format), lost.c_str());
  }
  if (format == FileFormat::drc) {
    // Draco's encoder leaves them out, without a word of its own.
    const auto repeated = std::count_if(mesh.triangles.begin(), mesh.triangles.end(), has_repeated_corner);
    if (repeated > 0) {
      std::fprintf(stderr, "ocsimp: warning: %s: %s with a repeated corner %s left out (Draco drops them)\n",
                   path.c_str(), counted(static_cast<std::uint64_t>(repeated), "face").c_str(),
                   repeated == 1 ? "is" : "are");
    }
  }
}

void check_destination(const std::string& path) {
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) throw Error(path, {}, "is a folder, not a file name");
  check_writable(path);
}

FileFormat check_mesh_destination(const std::string& path, const std::string& input) {
  const FileFormat format = format_from_extension(path);
  if (!input.empty() && same_file(path, input)) {
    throw Error(path, {},
                "the output would replace the input; write another file, then rename it over the input");
  }
  check_destination(path);
  return format;
}

bool same_file(const std::string& a, const std::string& b) {
  // Compared by resolved path rather than by inode: a destination need not exist yet.
  auto resolved = [](const std::string& path) {
    std::error_code error;
    const std::filesystem::path canonical = std::filesystem::weakly_canonical(path, error);
    return error ? std::filesystem::absolute(path).lexically_normal() : canonical;
  };
  return resolved(a) == resolved(b);
}

void check_report_destination(const std::string& report, const std::vector<std::string>& meshes) {
  check_destination(report);
  for (const std::string& mesh : meshes) {
    if (same_file(mesh, report)) throw Error(report, {}, "the report would overwrite the mesh file " + mesh);
  }
}

void check_whole_mesh_fits(const std::vector<std::string>& paths, double bytes_per_face,
                           const std::string& holding, const std::string& instead) {
  std::uint64_t faces = 0, most = 0;
  std::size_t largest = 0;  // the file named: the one that claims the most faces
  for (std::size_t i = 0; i < paths.size(); ++i) {
    try {
      const std::uint64_t claimed = detect_format(paths[i]) == FileFormat::ply ? triangles_hint(paths[i]) : 0;
      faces += claimed;
      if (claimed > most) {
        most = claimed;
        largest = i;
      }
    } catch (const Error&) {
      // The reader reports it.
    }
  }
  const std::uint64_t memory = physical_memory_bytes();
  const double needed = bytes_per_face * static_cast<double>(faces);
  if (memory == 0 || needed <= static_cast<double>(memory)) return;
  const std::string counted =
      std::to_string(faces) + (most == faces ? " faces" : " faces in all, " + std::to_string(most) + " here");
  throw Error(paths[largest], {},
              holding + " in memory: about " + format_bytes(static_cast<std::uint64_t>(needed)) + " for " +
                  counted + ", more than the " + format_bytes(memory) + " this process can have" +
                  (instead.empty() ? "" : "; " + instead));
}

std::string json_text(const nlohmann::json& value) {
  return value.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

void write_json_report(const std::string& path, const nlohmann::json& report) {
  AtomicFile file(path);
  file.write(json_text(report));
  file.write("\n");
  file.commit();
}

void flush_standard_output() {
  errno = 0;
  const bool flushed = std::fflush(stdout) == 0;
  if (!flushed || std::ferror(stdout)) {
    throw Error("standard output: write failed: " +
                std::string(errno != 0 ? std::strerror(errno) : "an earlier write did not complete"));
  }
}

void publish(HeldCommits& held) {
  flush_standard_output();
  held.release();
}

}  // namespace ocsimp::cli
