#include "ocsimp/tools/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"

namespace ocsimp {
namespace {

// Peak bytes per face of reading a mesh and decimating it in core (the decimator's working set plus the
// mesh it was read into), measured with `bench/pipeline_memory.sh`; used only to choose the path.
constexpr double kInCoreBytesPerFace = 160.0;
// Bytes per occupied fine cell while clustering (cluster.h documents about 190).
constexpr double kClusterBytesPerCell = 200.0;
constexpr double kMaxIntermediate = 8.0;

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

}  // namespace

SimplifyResult simplify(const std::string& input_path, const SimplifyOptions& options) {
  const bool has_count = options.target_faces > 0 || options.target_ratio > 0;
  if (!has_count && !std::isfinite(options.max_error)) {
    throw Error("simplify needs a target: a face count, a ratio or a maximum error");
  }
  if (options.target_ratio < 0 || options.target_ratio > 1) throw Error("--ratio must be in (0, 1]");
  if (options.intermediate != 0 && options.intermediate < 1) throw Error("--intermediate must be at least 1");

  SimplifyResult result;
  result.memory_limit = options.memory_limit > 0 ? options.memory_limit : physical_memory_bytes() / 3;
  const double budget = static_cast<double>(result.memory_limit);

  auto start = Clock::now();
  ReadOptions read;
  read.progress = options.progress;
  std::unique_ptr<TriangleStream> stream = open_triangle_stream(input_path, read);
  const double vertex_bytes = static_cast<double>(stream->vertices().positions.size()) * 12.0;
  // OBJ does not say its face count up front; its size does, roughly (at least ~20 bytes a face line).
  std::uint64_t faces_hint = stream->triangles_hint();
  if (faces_hint == 0) faces_hint = stream->bytes_total() / 40;
  result.input_faces = faces_hint;
  result.phases.push_back({"open", seconds_since(start), 0, 0, peak_rss_bytes()});

  std::uint64_t target = options.target_faces;
  if (options.target_ratio > 0) {
    const auto by_ratio = static_cast<std::uint64_t>(std::llround(options.target_ratio * static_cast<double>(faces_hint)));
    target = target > 0 ? std::min(target, std::max<std::uint64_t>(by_ratio, 1)) : std::max<std::uint64_t>(by_ratio, 1);
  }

  DecimateOptions decimate_options = options.decimate;
  decimate_options.max_error = options.max_error;
  decimate_options.threads = options.threads;
  decimate_options.progress = options.progress;

  const double in_core_bytes = vertex_bytes + kInCoreBytesPerFace * static_cast<double>(faces_hint);
  const bool in_core = !options.two_stage && in_core_bytes <= budget;
  QuadricMesh intermediate;
  if (in_core) {
    start = Clock::now();
    intermediate.mesh = read_mesh(*stream);
    stream.reset();
    result.input_faces = intermediate.mesh.face_count();
    result.phases.push_back({"read", seconds_since(start), result.input_faces, result.input_faces, peak_rss_bytes()});
    // The decimator applies the ratio to the exact face count it sees.
    decimate_options.target_faces = options.target_faces;
    decimate_options.target_ratio = options.target_ratio;
  } else {
    // Intermediate size: a few times the target, as large as both stages' memory allows.
    const double per_target_face_cluster = kClusterBytesPerCell * options.cluster.fine_cells_per_target / 2.0;
    const double cluster_room = std::max(0.0, budget - vertex_bytes) / per_target_face_cluster;
    const double decimate_room = budget / kInCoreBytesPerFace;
    const double room = std::min(cluster_room, decimate_room);
    std::uint64_t intermediate_faces;
    if (target > 0) {
      double multiple = options.intermediate > 0 ? options.intermediate
                                                 : std::clamp(std::floor(room / static_cast<double>(target)), 1.0,
                                                              kMaxIntermediate);
      intermediate_faces = static_cast<std::uint64_t>(multiple * static_cast<double>(target));
    } else {
      intermediate_faces = static_cast<std::uint64_t>(std::max(room, 1000.0));
    }
    intermediate_faces = std::min(intermediate_faces, faces_hint);
    ClusterOptions cluster_options = options.cluster;
    cluster_options.octree = true;
    cluster_options.target_vertices = 0;
    cluster_options.target_faces = std::max<std::uint64_t>(intermediate_faces, 4);
    cluster_options.threads = static_cast<unsigned>(std::max(options.threads, 0));
    cluster_options.progress = options.progress;
    start = Clock::now();
    intermediate = cluster(*stream, cluster_options, &result.cluster);
    stream.reset();
    result.clustered = true;
    result.input_faces = result.cluster.input_triangles;
    result.intermediate_faces = intermediate.mesh.face_count();
    result.phases.push_back(
        {"cluster", seconds_since(start), result.input_faces, result.intermediate_faces, peak_rss_bytes()});
    if (options.target_ratio > 0) {
      target = std::max<std::uint64_t>(
          1, static_cast<std::uint64_t>(std::llround(options.target_ratio * static_cast<double>(result.input_faces))));
      if (options.target_faces > 0) target = std::min(target, options.target_faces);
    }
    decimate_options.target_faces = target;
    decimate_options.target_ratio = 0;
  }

  start = Clock::now();
  const std::uint64_t decimate_in = intermediate.mesh.face_count();
  DecimateResult decimated = decimate(std::move(intermediate), decimate_options);
  result.mesh = std::move(decimated.mesh);
  result.decimate = decimated.stats;
  result.phases.push_back({"decimate", seconds_since(start), decimate_in, result.mesh.face_count(), peak_rss_bytes()});
  return result;
}

}  // namespace ocsimp
