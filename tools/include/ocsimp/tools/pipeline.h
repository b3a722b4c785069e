// The two-stage simplification pipeline (Garland & Shaffer 2002): a mesh that fits the in-core budget goes
// straight to the decimator; a larger one is first clustered in one streaming pass to an intermediate mesh of
// a few times the target, and the cluster quadrics (sums over the *original* triangles) are carried into the
// decimator, so its costs still measure distance to the original surface. This is what `ocsimp simplify`
// runs; programs can call it directly.
//
//   ocsimp::SimplifyOptions options;
//   options.target_faces = 1'000'000;
//   ocsimp::SimplifyResult result = ocsimp::simplify("scan.ply", options);
//   ocsimp::write_mesh("scan-1m.ply", result.mesh);
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"
#include "ocsimp/decimate/decimate.h"

namespace ocsimp {

struct SimplifyOptions {
  // Stopping criteria, as DecimateOptions has them: an exact face count, a ratio of the input's faces, an error
  // bound as a distance in model units. At least one; with several, whichever comes first.
  std::uint64_t target_faces = 0;
  double target_ratio = 0;
  double max_error = std::numeric_limits<double>::infinity();

  // Bound on peak memory, in bytes. 0: a third of physical memory. It decides whether the input is decimated
  // in core or clustered first, and how large the intermediate mesh may be.
  std::uint64_t memory_limit = 0;
  // Cluster first even when the input would fit in core (to study the stages on any mesh).
  bool two_stage = false;
  // Intermediate face count as a multiple of the target. 0: chosen from the memory budget (at most 8).
  double intermediate = 0;

  // Advanced: the stages' own options. Targets and progress in them are set by the pipeline.
  ClusterOptions cluster;
  DecimateOptions decimate;

  int threads = 0;  // 0: all cores; the output does not depend on it
  ProgressFn progress;
};

// One phase of a run, for the summary table and the JSON report.
struct PhaseReport {
  std::string name;  // "read", "cluster", "decimate"
  double seconds = 0;
  std::uint64_t triangles_in = 0;
  std::uint64_t triangles_out = 0;
  std::uint64_t peak_rss_bytes = 0;  // of the process at the end of the phase
};

struct SimplifyResult {
  IndexedMesh mesh;
  bool clustered = false;         // whether the clustering stage ran
  std::uint64_t input_faces = 0;
  std::uint64_t intermediate_faces = 0;  // 0 when not clustered
  std::vector<PhaseReport> phases;
  ClusterStats cluster;
  DecimateStats decimate;
  std::uint64_t memory_limit = 0;  // the budget in force
};

// Runs the pipeline on a file (any format ocsimp reads). Throws Error on bad input or impossible options.
SimplifyResult simplify(const std::string& input_path, const SimplifyOptions& options);

}  // namespace ocsimp
