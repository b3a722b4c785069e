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
//
// lod() runs the same first stage once and then decimates a chain of levels, each from the previous one with
// its quadrics carried, so every level's error is a distance to the original surface.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "ocsimp/cluster/cluster.h"
#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/core/system.h"
#include "ocsimp/decimate/decimate.h"

namespace ocsimp {

// Receives a warning as one sentence, without the input's name.
using WarningFn = std::function<void(const std::string& message)>;

struct SimplifyOptions {
  // Stopping criteria, as DecimateOptions has them: an exact face count, a ratio of the input's faces, an
  // error bound as a distance in model units. At least one; with several, whichever comes first.
  std::uint64_t target_faces = 0;
  double target_ratio = 0;
  double max_error = std::numeric_limits<double>::infinity();

  // Bound on peak memory, in bytes. 0: a third of physical memory. It decides whether the input is decimated
  // in core or clustered first, how large the intermediate mesh may be, and whether the input's vertex array
  // may be held at all: it gets what clustering to twice the target leaves (at least half the budget, and
  // more where clustering it in core would still take less than clustering its faces as a soup), and past
  // that the faces are dereferenced on disk under TMPDIR (io.h, ReadOptions::memory_budget).
  std::uint64_t memory_limit = 0;
  // Cluster first even when the input would fit in core (to study the stages on any mesh). Unless
  // `intermediate` is set, an input no larger than the intermediate (at least 2^18 faces) is still decimated
  // directly: clustering it would merge nothing and only approximate the decimator's own quadrics. With
  // `intermediate` set, it is clustered to at most its own size, as asked.
  bool two_stage = false;
  // Intermediate face count as a multiple of the target. 0: chosen from the memory budget (at most 8).
  double intermediate = 0;

  // Advanced: the stages' own options. Targets and progress in them are set by the pipeline.
  ClusterOptions cluster;
  DecimateOptions decimate;

  int threads = 0;  // 0: all cores; the output does not depend on it
  ProgressFn progress;
  // Called with each warning as soon as the run can tell, before its long stages: the memory plan is over the
  // limit (SimplifyResult::memory_needed), an OBJ's attributes are left out (attributes_left_out). The result
  // records both either way.
  WarningFn warn;
};

// The warning that an input read out of core left out its `left_out` attributes
// (TriangleStream::attributes_left_out), and why.
std::string attributes_left_out_warning(const std::string& left_out);

// After decimating the input read from `path` directly (not a clustered intermediate): throws an Error naming
// the file when no face was left to decimate (nothing_to_decimate_reason), and tells `warn` of the repeated
// faces left out and of a soup's separate faces.
void check_input_faces(const std::string& path, const WarningFn& warn, bool weld, const DecimateStats& stats);

// The memory budget in force for `memory_limit` (0: a third of physical memory, or half the address-space
// limit where that is less).
std::uint64_t effective_memory_limit(std::uint64_t memory_limit);

// The vertex array `cluster` may hold in core under `budget` (ReadOptions::memory_budget) before its faces
// are dereferenced on disk and clustered as soups. A target-driven soup pass holds far more per fine cell
// than the indexed pass, so with a face or vertex target the input stays in core unless its vertex array
// outweighs that difference: --memory-limit 64M made a 20 M scan clustered to 400 k faces peak at 1.7 GiB
// out of core, against 350 MiB in core.
std::uint64_t cluster_vertex_allowance(const ClusterOptions& options, std::uint64_t budget);

// One phase of a run, for the summary table and the JSON report.
struct PhaseReport {
  std::string name;  // "open", "read", "cluster", "decimate", "level N" (lod), "write" (added by the CLI)
  double seconds = 0;
  std::uint64_t triangles_in = 0;
  std::uint64_t triangles_out = 0;
  std::uint64_t peak_rss_bytes = 0;  // of the process at the end of the phase
};

struct SimplifyResult {
  IndexedMesh mesh;
  bool clustered = false;  // whether the clustering stage ran
  std::uint64_t input_faces = 0;
  std::uint64_t intermediate_faces = 0;  // 0 when not clustered
  std::vector<PhaseReport> phases;
  ClusterStats cluster;
  // The clustering stage's largest vertex error, measured as DecimateStats::max_error measures a collapse
  // (0 when not clustered).
  double cluster_error = 0;
  DecimateStats decimate;
  // The largest error of the result as a distance to the original surface: the larger of cluster_error and
  // the decimator's max_error.
  double max_error() const { return std::max(cluster_error, decimate.max_error); }
  std::uint64_t memory_limit = 0;  // the budget in force
  bool out_of_core = false;        // the input's vertices were dereferenced on disk (io.h, memory_budget)
  // The input's vertex attributes that the out-of-core reading left out, as a list ("normals and colors");
  // empty when the result carries all the input has.
  std::string attributes_left_out;
  // The memory the chosen path is expected to take, in bytes, when that is over memory_limit: the
  // clustering stage's plan (even the coarsest that reaches the target did not fit), or decimating in core
  // where that goes over the limit by less than clustering would; 0 when the plan fit.
  std::uint64_t memory_needed = 0;
};

// Runs the pipeline on a file (any format ocsimp reads). Throws Error on bad input or impossible options.
SimplifyResult simplify(const std::string& input_path, const SimplifyOptions& options);

struct LodOptions {
  // Face counts of the levels, in any order (they run largest first); each must be at least 1 and distinct.
  std::vector<std::uint64_t> level_faces;
  // Or, instead, ratios of the input's faces, each in (0, 1] and distinct: a level's count is the ratio of
  // the triangles read (polygons fan-triangulated), rounded, at least 1, once the input is read or clustered.
  // Ratios that round to the same count are refused, naming both.
  std::vector<double> level_ratios;

  // As in SimplifyOptions; they decide how the input becomes the first level's decimator input.
  std::uint64_t memory_limit = 0;
  bool two_stage = false;
  double intermediate = 0;
  ClusterOptions cluster;
  DecimateOptions decimate;  // targets and output_quadrics are set per level
  int threads = 0;
  ProgressFn progress;
  WarningFn warn;

  // Called once with every level's face target, largest first, as soon as all are known (with ratios, once
  // the input is read or clustered) and before the first level is made: e.g. to check the names of the
  // files they will go to. An Error it throws ends the run with nothing written.
  std::function<void(const std::vector<std::uint64_t>& target_faces)> on_targets;
  // Called with each level as soon as it exists, largest first (e.g. to write it), with its face target
  // (resolved from its ratio when ratios are given). When set, the meshes are not kept in LodResult, so
  // memory holds at most two levels at a time.
  std::function<void(std::size_t level, std::uint64_t target_faces, const IndexedMesh& mesh)> on_level;
};

struct LodLevel {
  std::uint64_t target_faces = 0;
  double target_ratio = 0;  // the ratio target_faces comes from (0: given as a count)
  IndexedMesh mesh;         // empty when LodOptions::on_level is set
  std::uint64_t faces = 0;
  double seconds = 0;  // decimating this level (and on_level)
  // Largest collapse cost so far down the chain, as a distance to the original surface in model units
  // (DecimateStats::max_error, carried quadrics, maximum over this and every larger level, and over
  // LodResult::cluster_error).
  double max_error = 0;
  DecimateStats decimate;  // this level's own run
};

struct LodResult {
  std::vector<LodLevel> levels;  // largest first
  bool clustered = false;
  std::uint64_t input_faces = 0;
  std::uint64_t intermediate_faces = 0;
  std::vector<PhaseReport> phases;
  ClusterStats cluster;
  double cluster_error = 0;  // as in SimplifyResult; every level's max_error starts from it
  std::uint64_t memory_limit = 0;
  bool out_of_core = false;
  std::string attributes_left_out;  // as in SimplifyResult
  std::uint64_t memory_needed = 0;  // as in SimplifyResult
};

// One read of the input (in core or clustered, as simplify() decides for the largest level), then each level
// decimated from the previous one with its quadrics carried. As in simplify(), a level whose decimation the
// clustered mesh's folds block above its target is made again from the input read whole and decimated in
// core (with a warning, when the machine has the memory); the levels after it start from that one, and
// `clustered` stays true when a level before it came from the clustering. Throws Error on bad input or
// options.
LodResult lod(const std::string& input_path, const LodOptions& options);

// `pattern` with "{faces}" replaced by `faces`. Throws Error when it has no "{faces}" and `several` is true.
std::string lod_level_path(const std::string& pattern, std::uint64_t faces, bool several);

}  // namespace ocsimp
