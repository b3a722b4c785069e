// The subcommands of `ocsimp`, one file each (cli/<name>_command.cpp), and what they share.
#pragma once

#include <tbb/global_control.h>
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "ocsimp/core/system.h"
#include "ocsimp/streaming/atomic_file.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/pipeline.h"

namespace ocsimp::cli {

void add_info_command(CLI::App& app);
void add_convert_command(CLI::App& app);
void add_gen_command(CLI::App& app);
void add_compare_command(CLI::App& app);
void add_cluster_command(CLI::App& app);
void add_decimate_command(CLI::App& app);
void add_simplify_command(CLI::App& app);
void add_lod_command(CLI::App& app);
void add_bench_command(CLI::App& app);

// Checks for numeric flags, with messages that say what the flag takes. (CLI11's Range prints a double's
// bounds with std::to_string, as "0.000000" or a few hundred digits, and an unsigned flag parses "-3" as
// 2^64 - 3, which passed an upper bound of 2^64 - 1.)
// Digits only, from `low` to `high`, read as decimal: a transform (give it to ->transform, not ->check),
// which hands CLI11 the digits without leading zeros, as CLI11 reads "010" as octal.
CLI::Validator whole_number(std::uint64_t low,
                            std::uint64_t high = std::numeric_limits<std::uint64_t>::max());
// A finite number >= 0; `or_infinity` also takes "inf" (no bound).
CLI::Validator non_negative_number(bool or_infinity = false);
// A finite number > 0.
CLI::Validator positive_number();
// A number in (0, 1].
CLI::Validator fraction();
// A --threads value: 0 (all cores) to 4096 (a transform, as whole_number).
CLI::Validator thread_count();
// A memory size parse_byte_size() takes, of at least one byte ("0" and "0.5" meant the default before).
CLI::Validator byte_size();

// Comma-separated lists for `flag` ("--faces", "--ratios", "--methods"): each item checked, none empty, none
// given twice; throw Error naming the flag and the item.
std::vector<std::uint64_t> parse_face_list(const std::string& text, const std::string& flag);
std::vector<double> parse_ratio_list(const std::string& text, const std::string& flag);
std::vector<std::string> parse_name_list(const std::string& text, const std::string& flag);

// An output or report file name: not empty, and not a word that starts with '-' (a flag taken for the name).
CLI::Validator file_name();

// --weld / --no-weld, for each command that decimates (DecimateOptions::weld).
void add_weld_flag(CLI::App* cmd, bool& weld);

// A progress callback that draws a bar on stderr when it is a terminal and `quiet` is false; otherwise
// a callback that does nothing.
ProgressFn make_progress(bool quiet);
// That progress callback, and the warnings of a command on `input` (SimplifyOptions::warn): printed on
// stderr as they come, even with --quiet, naming `input`, on a line of their own below the bar.
struct Console {
  ProgressFn progress;
  WarningFn warn;
};
Console make_console(bool quiet, const std::string& input);

// Warns through `console` when the process's peak memory went over `memory_limit`: the pipeline plans its
// stages from measured bytes per cell, and a grid that comes out larger than planned, or an input unlike
// those measured, can pass the limit after a plan that fit, or past the overshoot it announced.
void warn_if_over_memory_limit(const Console& console, std::uint64_t memory_limit);

// Writes a simplified mesh to `path` (atomically, as write_mesh does), and warns on stderr, even with
// --quiet, when it has no faces: every triangle collapsed, as on an input too thin for the resolution or with
// a target below what its topology allows, or on converting a file without faces. The vertices are still
// written (except to Draco, whose writer refuses a mesh without faces with an error); `info` and `convert`
// read such a file, the simplifying commands refuse it as input.
void write_result(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options);

// Refuses, before any work, a destination the command could not write at the end: a folder, or a path in a
// folder that does not exist or cannot take a new file (hours of clustering would otherwise be lost, or the
// mesh written and the command then fail on its report).
void check_destination(const std::string& path);
// A mesh destination: its extension must name a format (returned), and check_destination must pass. With
// `input`, it must not be that file: a simplified mesh written over its original (a typo in a script) loses
// what may have taken hours to scan, so replacing it takes a second step.
FileFormat check_mesh_destination(const std::string& path, const std::string& input = {});

// Whether two paths name the same file however they are spelled (./a.ply, a symbolic link to it); either
// may not exist yet.
bool same_file(const std::string& a, const std::string& b);

// check_destination for a --report path, which must also not name any of the command's mesh files: the
// JSON would replace the result, or the input itself.
void check_report_destination(const std::string& report, const std::vector<std::string>& meshes);

// Refuses, before anything is read, an input that a command holding whole meshes in memory could not hold:
// `bytes_per_face` (a floor under the command's measured peak) times the faces the PLY headers of `paths`
// announce, over the memory this process can have (physical_memory_bytes). The system would otherwise end
// the process when its memory ran out, after the reading, without a word. `holding` says what the command
// holds ("decimate holds the whole mesh"), `instead` what takes such an input (may be empty). Other formats
// announce no count to go by, and are left to run.
void check_whole_mesh_fits(const std::vector<std::string>& paths, double bytes_per_face,
                           const std::string& holding, const std::string& instead);

// `value` as pretty JSON. File names are bytes, not always UTF-8: a byte that is not is written as U+FFFD
// rather than failing the whole command after its work is done.
std::string json_text(const nlohmann::json& value);

// Writes `report` as pretty JSON (json_text) to `path`, atomically.
void write_json_report(const std::string& path, const nlohmann::json& report);

// Flushes standard output; throws Error when anything written to it was lost (a full disk, a closed pipe).
void flush_standard_output();
// Ends a command that writes files under `held`: once its summary has gone out, the files appear together.
// A summary or report that could not be written fails the run, which then leaves no output behind.
void publish(HeldCommits& held);

double seconds_since(std::chrono::steady_clock::time_point start);

// Keeps every parallel loop of the command, the readers' included, to `threads` cores (at most the
// machine's: see worker_threads) while the result lives; 0 (or less): all cores, and nothing is returned.
std::unique_ptr<tbb::global_control> limit_threads(int threads);

// Whether `path` is where standard output goes (--report /dev/stdout, or the file stdout is redirected to).
bool is_standard_output(const std::string& path);
// Whether the end-of-run summary goes to stdout: not with --quiet, and not when the report goes there (it
// would follow the JSON and make it unreadable).
bool show_summary(bool quiet, const std::string& report);
// What a summary says after a count of positions when the decimator wrote a texture seam's vertex once per
// side (DecimateStats::seam_copies): " (+N copies along seams)", or nothing.
std::string seam_copies_note(std::uint64_t copies);

// The phases as the summary table (phase, time, triangles in and out, peak RSS) on stdout, and as the JSON
// array of {name, seconds, triangles_in, triangles_out, peak_rss_bytes} the reports share.
void print_phase_table(const std::vector<PhaseReport>& phases);
nlohmann::json phases_json(const std::vector<PhaseReport>& phases);

}  // namespace ocsimp::cli
