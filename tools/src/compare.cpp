// Metro-style surface distance: sampling one surface, querying the other, and summarizing.
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "compare_index.h"
#include "ocsimp/core/error.h"
#include "ocsimp/tools/compare.h"

namespace ocsimp {

namespace {

// Samples are cut into fixed chunks (the unit of parallel work and of the ordered merge); rounds of chunks
// run in parallel between progress reports from the calling thread.
constexpr std::size_t chunk_samples = 2048;
constexpr std::size_t chunks_per_round = 64;

struct ChunkStats {
  double sum = 0;
  double sum_squares = 0;
  double max = -1;
  Vec3d farthest = Vec3d::Zero();
  std::size_t count = 0;

  void add(double d, const Vec3d& p) {
    sum += d;
    sum_squares += d * d;
    if (d > max) max = d, farthest = p;
    ++count;
  }
  // Merged in chunk order, so ties keep the earliest sample.
  void merge(const ChunkStats& other) {
    sum += other.sum;
    sum_squares += other.sum_squares;
    if (other.max > max) max = other.max, farthest = other.farthest;
    count += other.count;
  }
};

// Distances from `points` (moved by `shift` into `to`'s frame) to `to`, each search bounded by the distance
// to the previous point's closest point, which lies on the surface: neighbouring samples are close, so this
// prunes most of the BVH at once.
ChunkStats measure_points(const DistanceIndex& to, Vec3d* points, std::size_t count, const Vec3d& shift) {
  if (shift != Vec3d::Zero()) {
    for (std::size_t i = 0; i < count; ++i) points[i] += shift;
  }
  ChunkStats stats;
  Vec3d previous = Vec3d::Zero();
  bool have_previous = false;
  for (std::size_t i = 0; i < count; ++i) {
    const Vec3d& p = points[i];
    // Widened a little: `previous` was computed, so it may sit a rounding error off its triangle.
    const double bound = have_previous
                             ? (p - previous).norm() * (1 + 1e-9) +
                                   1e-12 * std::max(p.cwiseAbs().maxCoeff(), previous.cwiseAbs().maxCoeff())
                             : std::numeric_limits<double>::infinity();
    ClosestPoint closest = to.closest_point(p, bound);
    if (!(closest.distance_squared < std::numeric_limits<double>::infinity()))
      closest = to.closest_point(p);  // only if rounding defeated the widening above
    stats.add(std::sqrt(closest.distance_squared), p);
    previous = closest.point;
    have_previous = true;
  }
  return stats;
}

}  // namespace

OneSidedDistance measure_one_sided(const DistanceIndex& from, const DistanceIndex& to,
                                   const CompareOptions& options, const std::string& phase) {
  const DistanceIndex::Impl& source = from.impl();
  const bool has_area = source.total_area() > 0;
  // A surface without area is measured at its vertices alone (see compare.h).
  const std::size_t area_count = has_area ? options.samples : 0;
  const std::size_t vertex_count =
      (options.include_vertices || !has_area) ? source.referenced_vertices.size() : 0;
  if (area_count + vertex_count == 0)
    throw Error(from.name(), {},
                "nothing to measure: no area samples were asked for and vertices are excluded");

  const Vec3d shift = from.origin() - to.origin();
  const std::size_t area_chunks = (area_count + chunk_samples - 1) / chunk_samples;
  const std::size_t vertex_chunks = (vertex_count + chunk_samples - 1) / chunk_samples;
  const std::size_t chunks = area_chunks + vertex_chunks;
  std::vector<ChunkStats> stats(chunks);
  const std::uint64_t total = area_count + vertex_count;
  std::uint64_t done = 0;
  report(options.progress, phase, 0, total);
  for (std::size_t round = 0; round < chunks; round += chunks_per_round) {
    const std::size_t round_end = std::min(chunks, round + chunks_per_round);
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(round, round_end, 1),
        [&](const tbb::blocked_range<std::size_t>& range) {
          std::array<Vec3d, chunk_samples> points;
          for (std::size_t chunk = range.begin(); chunk < range.end(); ++chunk) {
            std::size_t n = 0;
            if (chunk < area_chunks) {
              const std::size_t first = chunk * chunk_samples;
              const std::size_t last = std::min(area_count, first + chunk_samples);
              source.area_samples(area_count, options.seed, first, last, points.data());
              n = last - first;
            } else {
              const std::size_t first = (chunk - area_chunks) * chunk_samples;
              const std::size_t last = std::min(vertex_count, first + chunk_samples);
              for (std::size_t i = first; i < last; ++i)
                points[i - first] = source.vertex(source.referenced_vertices[i]);
              n = last - first;
            }
            stats[chunk] = measure_points(to, points.data(), n, shift);
          }
        },
        tbb::simple_partitioner());
    for (std::size_t chunk = round; chunk < round_end; ++chunk) done += stats[chunk].count;
    report(options.progress, phase, done, total);
  }

  ChunkStats area_stats, vertex_stats;
  for (std::size_t chunk = 0; chunk < area_chunks; ++chunk) area_stats.merge(stats[chunk]);
  for (std::size_t chunk = area_chunks; chunk < chunks; ++chunk) vertex_stats.merge(stats[chunk]);
  const ChunkStats& averaged = area_count > 0 ? area_stats : vertex_stats;
  ChunkStats all = area_stats;
  all.merge(vertex_stats);

  OneSidedDistance result;
  result.hausdorff = all.max;
  result.farthest = all.farthest + to.origin();  // measured in `to`'s frame
  result.mean = averaged.sum / double(averaged.count);
  result.rms = std::sqrt(averaged.sum_squares / double(averaged.count));
  result.samples = area_count;
  result.vertex_samples = vertex_count;
  return result;
}

SurfaceDistance combine_distances(const OneSidedDistance& forward, const OneSidedDistance& backward,
                                  double diagonal) {
  SurfaceDistance result;
  result.forward = forward;
  result.backward = backward;
  result.hausdorff = std::max(forward.hausdorff, backward.hausdorff);
  result.mean = 0.5 * (forward.mean + backward.mean);
  result.rms = std::sqrt(0.5 * (forward.rms * forward.rms + backward.rms * backward.rms));
  result.diagonal = diagonal;
  return result;
}

SurfaceDistance measure_distance(const DistanceIndex& original, const DistanceIndex& simplified,
                                 const CompareOptions& options) {
  const OneSidedDistance forward = measure_one_sided(original, simplified, options, "forward");
  const OneSidedDistance backward = measure_one_sided(simplified, original, options, "backward");
  return combine_distances(forward, backward, original.bounds().diagonal());
}

SurfaceDistance measure_distance(const IndexedMesh& original, const IndexedMesh& simplified,
                                 const CompareOptions& options) {
  report(options.progress, "index original", 0, original.face_count());
  const DistanceIndex original_index(original, "original");
  report(options.progress, "index original", original.face_count(), original.face_count());
  report(options.progress, "index simplified", 0, simplified.face_count());
  const DistanceIndex simplified_index(simplified, "simplified");
  report(options.progress, "index simplified", simplified.face_count(), simplified.face_count());
  return measure_distance(original_index, simplified_index, options);
}

}  // namespace ocsimp
