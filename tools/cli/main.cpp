// ocsimp: simplify triangle meshes of any size. One subcommand per file in this folder.
#include <csignal>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include <fcntl.h>

#include "commands.h"
#include "ocsimp/core/error.h"
#include "ocsimp/core/system.h"

namespace {

// A standard descriptor the caller closed (`>&-`, `2>&-`) would be the lowest free one, so the next file
// opened, the output mesh's temporary, would take it, and the summary or a warning would be written into the
// mesh. Each closed one is taken by /dev/null opened for reading (the lowest free descriptor is that one):
// writing to it still fails, so a closed standard output is still a failed write (exit 2, no output).
void hold_closed_standard_descriptors() {
  for (int fd = 0; fd <= 2; ++fd) {
    if (fcntl(fd, F_GETFD) == -1) open("/dev/null", O_RDONLY);
  }
}

}  // namespace

int main(int argc, char** argv) {
  hold_closed_standard_descriptors();
  // Past the shell's file-size limit (ulimit -f) a write fails with EFBIG, reported like any other failed
  // write, rather than the kernel killing the process without a word.
  std::signal(SIGXFSZ, SIG_IGN);
  CLI::App app{"ocsimp: simplify triangle meshes of any size (streaming clustering + QEM decimation)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "ocsimp 0.1.0");
  // Registration order is the order `ocsimp --help` lists the commands in.
  ocsimp::cli::add_info_command(app);
  ocsimp::cli::add_convert_command(app);
  ocsimp::cli::add_gen_command(app);
  ocsimp::cli::add_compare_command(app);
  ocsimp::cli::add_cluster_command(app);
  ocsimp::cli::add_decimate_command(app);
  ocsimp::cli::add_simplify_command(app);
  ocsimp::cli::add_lod_command(app);
  ocsimp::cli::add_bench_command(app);
  // New commands: add their registration above this line.
  // A usage error is one line like every other error, naming the command whose help lists its flags.
  app.failure_message([](const CLI::App* top, const CLI::Error& e) {
    std::string help = "ocsimp";
    const std::vector<CLI::App*> used = top->get_subcommands();
    if (!used.empty()) help += " " + used.front()->get_name();
    std::string message = e.what();
    // CLI11 2.1 lists unexpected arguments last first ("not expected: c b a"): they are listed again here
    // in the order they were given.
    if (dynamic_cast<const CLI::ExtrasError*>(&e) != nullptr) {
      const std::vector<std::string> extras = (used.empty() ? top : used.front())->remaining();
      if (!extras.empty()) {
        message = extras.size() > 1 ? "The following arguments were not expected:"
                                    : "The following argument was not expected:";
        for (const std::string& extra : extras) message += " " + extra;
      }
    }
    return "ocsimp: " + message + " (see " + help + " --help)\n";
  });
  // CLI11 reports a misspelt command as a missing one.
  const std::string first = argc > 1 ? argv[1] : "";
  if (!first.empty() && first[0] != '-' &&
      app.get_subcommands([&](CLI::App* command) { return command->check_name(first); }).empty()) {
    std::fprintf(stderr, "ocsimp: unknown command '%s' (see ocsimp --help)\n", argv[1]);
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Help and version exit 0; usage errors exit 2 with the message above.
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  } catch (const ocsimp::Error& e) {
    std::fprintf(stderr, "ocsimp: %s\n", e.what());
    return 2;
  } catch (const std::bad_alloc&) {
    // One line naming what was being read, as every other error does, and how far memory had got.
    std::string subject, command_name;
    for (const CLI::App* command : app.get_subcommands()) {
      command_name = command->get_name();
      for (const char* name : {"input", "original"}) {
        const CLI::Option* option = command->get_option_no_throw(name);
        if (subject.empty() && option && option->count() > 0) subject = option->as<std::string>() + ": ";
      }
    }
    std::fprintf(
        stderr, "ocsimp: %sout of memory in %s (the system refused an allocation, at a peak of %s)\n",
        subject.c_str(), command_name.c_str(), ocsimp::format_bytes(ocsimp::peak_rss_bytes()).c_str());
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ocsimp: %s\n", e.what());
    return 1;
  }
  // What info --json, compare and bench print goes to standard output: on a full disk, or with it closed,
  // that output is lost, which is a failed write like any other rather than a success.
  try {
    ocsimp::cli::flush_standard_output();
  } catch (const ocsimp::Error& e) {
    std::fprintf(stderr, "ocsimp: %s\n", e.what());
    return 2;
  }
  return 0;
}
