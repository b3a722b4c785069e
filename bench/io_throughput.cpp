// Times one mesh read or write and prints it, for bench/io_throughput.sh to set beside `cat` in the same run.
//
//   bench_io_throughput read  FILE            read_mesh(FILE): vertices and all triangles in memory
//   bench_io_throughput drain FILE            pull every batch of the TriangleStream, keeping nothing
//   bench_io_throughput write IN OUT [--ascii]  load IN (untimed), then time write_mesh(OUT)
//   bench_io_throughput gen   OUT --triangles N [--ascii] [--normals]
//                                              a wavy, noisy torus written through PlyStreamWriter, for when
//                                              `ocsimp gen` is not built
//
// Prints one line: "seconds=S cpu=C bytes=B triangles=T": wall and process CPU seconds of the call, B being
// the bytes read or written. CPU time tells apart our cost from waiting for a core on a busy machine.

#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <string>
#include <string_view>

#include "bench_support.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/ply_writer.h"

namespace {

using ocsimp::bench::cpu_seconds;

using Clock = std::chrono::steady_clock;

// Wall and CPU time from construction to print().
struct Timer {
  Clock::time_point wall = Clock::now();
  double cpu = cpu_seconds();

  void print(std::uint64_t bytes, std::uint64_t triangles) const {
    const double seconds = std::chrono::duration<double>(Clock::now() - wall).count();
    std::printf("seconds=%.6f cpu=%.6f bytes=%llu triangles=%llu\n", seconds, cpu_seconds() - cpu,
                static_cast<unsigned long long>(bytes), static_cast<unsigned long long>(triangles));
  }
};

// A deterministic hash in [-0.5, 0.5) for scanner-like noise: full-precision floats, as real scans have,
// so ascii files carry realistic digit counts.
float noise(std::uint64_t i) {
  i = (i ^ (i >> 30)) * 0xBF58476D1CE4E5B9ull;
  i = (i ^ (i >> 27)) * 0x94D049BB133111EBull;
  i ^= i >> 31;
  return static_cast<float>(static_cast<double>(i >> 11) / 9007199254740992.0 - 0.5);
}

void generate(const std::string& path, std::uint64_t triangles, bool ascii, bool normals) {
  // A torus grid of rows x columns quads, closed in both directions: 2 rows columns triangles.
  const std::uint64_t quads = std::max<std::uint64_t>(triangles / 2, 12);
  const auto rows = static_cast<std::uint64_t>(std::sqrt(static_cast<double>(quads) / 2.0)) + 1;
  const std::uint64_t columns = (quads + rows - 1) / rows;
  ocsimp::PlyLayout layout;
  layout.vertices = rows * columns;
  layout.faces = 2 * rows * columns;
  layout.normals = normals;
  layout.ascii = ascii;
  ocsimp::PlyStreamWriter writer(path, layout);
  const double two_pi = 6.283185307179586;
  for (std::uint64_t r = 0; r < rows; ++r) {
    const double v = two_pi * static_cast<double>(r) / static_cast<double>(rows);
    for (std::uint64_t c = 0; c < columns; ++c) {
      const double u = two_pi * static_cast<double>(c) / static_cast<double>(columns);
      const std::uint64_t id = r * columns + c;
      const double tube = 0.35 + 0.03 * std::sin(7 * u) * std::cos(5 * v) + 0.0005 * noise(id);
      const double ring = 1.0 + tube * std::cos(v);
      const ocsimp::Vec3f p(static_cast<float>(ring * std::cos(u)), static_cast<float>(ring * std::sin(u)),
                            static_cast<float>(tube * std::sin(v)));
      const ocsimp::Vec3f n(static_cast<float>(std::cos(v) * std::cos(u)),
                            static_cast<float>(std::cos(v) * std::sin(u)), static_cast<float>(std::sin(v)));
      writer.add_vertex(p, normals ? &n : nullptr);
    }
  }
  auto id = [columns, rows](std::uint64_t r, std::uint64_t c) {
    return static_cast<ocsimp::Index>((r % rows) * columns + (c % columns));
  };
  for (std::uint64_t r = 0; r < rows; ++r) {
    for (std::uint64_t c = 0; c < columns; ++c) {
      writer.add_face({id(r, c), id(r, c + 1), id(r + 1, c + 1)});
      writer.add_face({id(r, c), id(r + 1, c + 1), id(r + 1, c)});
    }
  }
  writer.finish();
}

int usage() {
  std::fprintf(stderr,
               "usage: bench_io_throughput read|drain FILE\n"
               "       bench_io_throughput write IN OUT [--ascii]\n"
               "       bench_io_throughput gen OUT --triangles N [--ascii] [--normals]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) return usage();
  const std::string_view command = argv[1];
  bool ascii = false, normals = false;
  std::uint64_t triangles = 0;
  for (int i = 3; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--ascii") ascii = true;
    if (arg == "--normals") normals = true;
    if (arg == "--triangles" && i + 1 < argc) {
      const std::string_view value = argv[++i];
      std::from_chars(value.data(), value.data() + value.size(), triangles);
    }
  }
  try {
    if (command == "read") {
      const Timer timer;
      const ocsimp::IndexedMesh mesh = ocsimp::read_mesh(argv[2]);
      timer.print(std::filesystem::file_size(argv[2]), mesh.triangles.size());
    } else if (command == "drain") {
      const Timer timer;
      auto stream = ocsimp::open_triangle_stream(argv[2]);
      ocsimp::TriangleBatch batch;
      std::uint64_t count = 0;
      while (stream->next(batch)) count += batch.size();
      timer.print(stream->bytes_total(), count);
    } else if (command == "write" && argc >= 4) {
      const ocsimp::IndexedMesh mesh = ocsimp::read_mesh(argv[2]);
      ocsimp::WriteOptions options;
      options.ascii = ascii;
      const Timer timer;
      ocsimp::write_mesh(argv[3], mesh, options);
      timer.print(std::filesystem::file_size(argv[3]), mesh.triangles.size());
    } else if (command == "gen" && triangles > 0) {
      const Timer timer;
      generate(argv[2], triangles, ascii, normals);
      timer.print(std::filesystem::file_size(argv[2]), triangles);
    } else {
      return usage();
    }
  } catch (const ocsimp::Error& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}
