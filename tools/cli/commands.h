// The subcommands of `ocsimp`, one file each (cli/<name>_command.cpp), and what they share.
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>

#include "ocsimp/core/system.h"

namespace ocsimp::cli {

void add_info_command(CLI::App& app);
void add_convert_command(CLI::App& app);
void add_gen_command(CLI::App& app);
void add_compare_command(CLI::App& app);
void add_cluster_command(CLI::App& app);
void add_decimate_command(CLI::App& app);
void add_simplify_command(CLI::App& app);
void add_bench_command(CLI::App& app);

// A progress callback that draws a bar on stderr when it is a terminal and `quiet` is false; otherwise
// a callback that does nothing.
ProgressFn make_progress(bool quiet);

// Writes `report` as pretty JSON to `path`, atomically.
void write_json_report(const std::string& path, const nlohmann::json& report);

}  // namespace ocsimp::cli
