// libFuzzer entry point shared by the per-format targets (fuzz_ply, fuzz_obj, fuzz_stl, fuzz_drc): the input
// bytes become a file with the target's extension and go through read_mesh(), the path every real input
// takes. Bad input must end in ocsimp::Error. Anything else is a bug: a crash or sanitizer report, an
// allocation past libFuzzer's -malloc_limit_mb (memory sized by what a file claims), a hang, or a mesh that
// breaks the invariants checked below.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"

#ifndef OCSIMP_FUZZ_EXTENSION
#error "define OCSIMP_FUZZ_EXTENSION, e.g. \".obj\""
#endif

namespace {

const std::string& input_path() {
  static const std::string path = [] {
    const char* dir = std::getenv("TMPDIR");
    std::string p = std::string(dir && *dir ? dir : "/tmp") + "/ocsimp-fuzz-" + std::to_string(::getpid()) +
                    OCSIMP_FUZZ_EXTENSION;
    std::atexit([] { std::remove(input_path().c_str()); });
    return p;
  }();
  return path;
}

// A broken invariant is a finding: stop the way a sanitizer would, so libFuzzer saves the input.
void require(bool condition, const char* what) {
  if (!condition) {
    std::fprintf(stderr, "invariant broken: %s\n", what);
    std::abort();
  }
}

void check(const ocsimp::IndexedMesh& mesh) {
  const std::size_t n = mesh.positions.size();
  require(!mesh.triangles.empty(), "read_mesh returned a mesh without faces");
  for (const ocsimp::Triangle& t : mesh.triangles)
    for (ocsimp::Index v : t) require(v < n, "face index past the vertices");
  require(mesh.normals.empty() || mesh.normals.size() == n, "normal count");
  require(mesh.colors.empty() || mesh.colors.size() == n, "color count");
  require(mesh.uvs.empty() || mesh.uvs.size() == n, "uv count");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string& path = input_path();
  std::FILE* file = std::fopen(path.c_str(), "wb");
  require(file != nullptr, "cannot create the temporary input file");
  require(std::fwrite(data, 1, size, file) == size && std::fclose(file) == 0, "cannot write the input file");

  ocsimp::IndexedMesh mesh;
  try {
    mesh = ocsimp::read_mesh(path);
  } catch (const ocsimp::Error&) {
    return 0;
  }
  check(mesh);

  // The same file through the stream with tiny batches (polygon fans split across batches, a soup's bounds
  // pre-scan mid-stream) must give the same number of triangles.
  ocsimp::ReadOptions options;
  options.batch_capacity = 5;
  std::size_t triangles = 0;
  try {
    auto stream = ocsimp::open_triangle_stream(path, options);
    ocsimp::TriangleBatch batch;
    bool first = true;
    while (stream->next(batch)) {
      require(batch.size() <= options.batch_capacity, "batch over capacity");
      if (first) stream->bounds();
      first = false;
      triangles += batch.size();
    }
  } catch (const ocsimp::Error&) {
    require(false, "the stream failed on a file read_mesh accepted");
  }
  require(triangles == mesh.triangles.size(), "stream and read_mesh disagree on the triangle count");
  return 0;
}
