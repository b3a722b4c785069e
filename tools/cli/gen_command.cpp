// ocsimp gen: stream a scan-like test mesh of any size to disk.
#include <chrono>
#include <cstdio>

#include "commands.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/tools/generate.h"

namespace ocsimp::cli {

void add_gen_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "gen",
      "Generate a scan-like mesh (closed blobby surface, multi-frequency "
      "displacement, scanner noise) of any size, in bounded memory (at most about 130 MB)");
  struct Flags {
    std::string output;
    GenerateOptions options;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  cmd->add_option("-o,--output", flags->output, "Output file (.ply; other formats go through memory)")
      ->check(file_name())
      ->required();
  cmd->add_option("--triangles", flags->options.triangles,
                  "Triangles wanted; the lattice reaches the nearest 12 n^2 per component (n at least 12 "
                  "with --holes: 1,728 triangles a component)")
      ->capture_default_str()
      // 12 n^2 at the largest n whose 6 n^2 + 2 vertices 32-bit indices number (n = 26,754).
      ->transform(whole_number(12, 8'589'318'192));
  cmd->add_option("--seed", flags->options.seed, "Random seed (same seed, same bytes)")
      ->capture_default_str()
      ->transform(whole_number(0));
  cmd->add_option("--components", flags->options.components, "Separate blobs")
      ->capture_default_str()
      ->transform(whole_number(1, 1000));
  cmd->add_option("--holes", flags->options.holes, "Holes cut into each blob, leaving open borders")
      ->capture_default_str()
      ->transform(whole_number(0, 6));
  cmd->add_option("--noise", flags->options.noise, "Scanner noise, in mean edge lengths (0..10)")
      ->capture_default_str();
  cmd->add_option_function<std::vector<double>>(
         "--offset",
         [flags](const std::vector<double>& xyz) { flags->options.offset = Vec3d(xyz[0], xyz[1], xyz[2]); },
         "Place the mesh around this point (X Y Z, each within 1e9 of zero), in double coordinates, as a "
         "georeferenced scan")
      ->expected(3)
      ->check(CLI::Number);
  cmd->add_flag("--normals", flags->options.normals, "Write per-vertex normals");
  cmd->add_flag("--colors", flags->options.colors, "Write per-vertex colors");
  cmd->add_flag("--ascii", flags->options.ascii, "ASCII PLY instead of binary");
  cmd->add_option("--threads", flags->options.threads,
                  "Threads (0 = all cores); output does not depend on it")
      ->capture_default_str()
      ->transform(thread_count());
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress bar");
  cmd->callback([flags] {
    const auto start = std::chrono::steady_clock::now();
    GenerateOptions options = flags->options;  // a copy, as in convert: the bar ends with the command
    options.progress = make_progress(flags->quiet);
    GeneratedCounts counts;
    HeldCommits held;  // the mesh appears once the summary is out (see publish)
    if (check_mesh_destination(flags->output) == FileFormat::ply) {
      counts = generate_scan_ply(flags->output, options);
    } else {
      const IndexedMesh mesh = generate_scan_mesh(options);
      counts = {0, mesh.vertex_count(), mesh.face_count()};
      WriteOptions write;
      write.ascii = options.ascii;
      write_result(flags->output, mesh, write);
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!flags->quiet) {
      std::printf("generated %s: %llu vertices, %llu triangles in %.2f s\n", flags->output.c_str(),
                  static_cast<unsigned long long>(counts.vertices),
                  static_cast<unsigned long long>(counts.faces), seconds);
    }
    publish(held);
  });
}

}  // namespace ocsimp::cli
