#include "ocsimp/tools/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>

#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"

namespace ocsimp {
namespace {

// Peak bytes per face of reading a mesh and decimating it in core: the decimator's peak, 135-137 bytes per
// input triangle on the 10 M scan (bench/decimate_vs_meshopt.sh), plus the 12-byte face and ~6-byte vertex
// arrays it was read into, rounded up. Used only to choose the path.
constexpr double kInCoreBytesPerFace = 160.0;
// Peak bytes per occupied fine cell of the octree clustering of an indexed input, cells and merge state
// together; the pass releases the vertex array as it goes, so by the peak it is mostly gone. Measured with
// `simplify --two-stage` on generated scans: 4 M triangles at 262 k and 906 k fine cells, 170 and 572 MiB
// (654 bytes a cell over 7 MiB); 20 M triangles at 275 k and 1.04 M cells, 198 and 635 MiB. (The 340 taken
// before, from a billion-triangle run, let --memory-limit 400M peak at 631 MiB on the 20 M scan.)
constexpr double kClusterBytesPerCell = 660.0;
// Peak bytes per occupied fine cell while the indexed pass accumulates, the whole vertex array still beside
// it (it is released once the pass is over, before the octree's merge state grows): on the 20 M scan at 276 k
// cells, 214 over the array and the process, and 333 with normals and colors, whose per-cell sums (44 bytes:
// cluster/ keeps normals in floats, colors and texture coordinates in wider sums) are held about three times
// over in chunks and growing arrays.
constexpr double kPassBytesPerCell = 220.0;
constexpr double kPassBytesPerAttributeSumByte = 3.0;
double pass_bytes_per_cell(bool normals, bool colors, bool uvs) {
  return kPassBytesPerCell + kPassBytesPerAttributeSumByte * (12.0 * normals + 32.0 * colors + 16.0 * uvs);
}
// The fine grid is a power of two, of the level whose occupied cells come nearest the plan: up to about twice
// the planned number (gen 4 M and 20 M at 140 k and 147 k planned: 262 k and 276 k cells).
constexpr double kLevelMargin = 2.0;
// Peak bytes per occupied fine cell of a triangle soup's clustering (an out-of-core dereferenced input, STL):
// its pass keys the cells by their coordinates, keeps their first-seen order and sorts them at the end.
// Measured on the 20 M scan out of core at 276 k cells: 413 MiB, and 469 MiB with normals and colors on the
// corners (1.5 and 1.7 KiB a cell). It cannot count its cells before the pass, so it halves its grid whenever
// they outgrow twice the plan, which leaves up to twice the planned number, as the indexed pass's level
// choice does.
constexpr double kSoupClusterBytesPerCell = 1800.0;
// The same on a given grid (--grid), where the pass neither refines nor coarsens: 740 bytes a cell at 68 k
// cells, 460 at 2 M (gen 4 M), taken at the high end.
constexpr double kSoupGridBytesPerCell = 740.0;
// The most cells a surface occupies on a grid of n cells along its box's longest axis, in units of n^2: a
// closed blob takes about 4 (gen's, at n = 128 and 256), a sphere pi, a plane across the box 1 to 3; a scan
// of a folded statue more.
constexpr double kGridSurfaceCells = 16.0;
// What the process holds before it reads anything (code, libraries, thread pools; about 9 MB measured here)
// as the plan counts it: a constant, as the plan and so the output must not depend on the run (the measured
// size grows from one run to the next in a process, and with the threads).
constexpr double kProcessBytes = 16 << 20;
constexpr double kMaxIntermediate = 8.0;
// The clustering stage stops at the largest face count it reaches not above its own target, often a few short
// of it: an intermediate a quarter over the final target leaves the decimator the slack to meet it exactly
// (a 40 k-face scan to 2,000 faces under a 256 KiB limit, with the intermediate at the target, ended at
// 1,999).
constexpr double kMinMultiple = 1.25;
// What an intermediate may ask of an input of a given face count, where the count is a hint of polygons: up
// to six corners each, four triangles.
constexpr double kTrianglesPerPolygon = 4.0;
// However small the target, an intermediate the decimator takes in a fraction of a second (about 0.2 s for
// 2^18 faces) is not worth making coarser: clustering to a few hundred faces loses what decimation keeps.
// Measured with --two-stage through 8x the target: fandisk to 129 faces, RMS 2.2x pure decimation's (its
// creases do not survive a 1,000-face octree); homer and rocker-arm to 0.1 %, 1.2x.
constexpr double kMinIntermediate = 1 << 18;
// The octree merge costs several times a decimator collapse (a 10 M scan clustered to 800 k faces: 2.8 M
// merges, 28 s), and its adaptivity buys little once the decimator is to take the intermediate much further:
// the pipeline caps the fine grid near this many cells (the grid's level then holds at most twice as many),
// but never below kMinFinePerVertex cells per intermediate vertex. Measured on that scan to 1 % of its faces:
// 8 fine cells a vertex, cluster 29.9 s, final RMS 1.290e-4; capped, cluster 1.7 s, RMS 1.296e-4 (pure
// decimation 1.285e-4). The shared meshes stay under the cap and keep the full 8, which they need (bunny to
// 1 % with 2 a vertex: RMS 1.20x pure decimation's instead of 1.07x).
constexpr double kMaxFineCells = 300'000;
constexpr double kMinFinePerVertex = 1.2;

// Fine cells the octree accumulates for an intermediate of `faces` faces (about faces / 2 vertices): the full
// count per vertex, capped at `cap` cells (kMaxFineCells, or fewer where the memory budget has less room)
// but never below the minimum per vertex.
double fine_cells_for(double faces, double fine_per_vertex, double cap = kMaxFineCells,
                      double min_per_vertex = kMinFinePerVertex) {
  const double vertices = faces / 2;
  const double low = std::min(min_per_vertex, fine_per_vertex) * vertices;
  return std::max(low, std::min(cap, fine_per_vertex * vertices));
}

// A soup's pass halves its grid while it holds more than twice the planned cells, which can leave half of
// them: it plans twice the minimum, so that every intermediate vertex still has a cell (a 20 M scan out of
// core, planned at the minimum, came out of the clustering with 142 k faces for a target of 200 k).
double min_fine_per_vertex(bool soup) {
  return soup ? 2 * kMinFinePerVertex : kMinFinePerVertex;
}

using Clock = std::chrono::steady_clock;

// The face count the options ask for of an input of `faces` faces: the face target, or the ratio of them (at
// least 1), whichever is smaller; 0 without a count target, or with only a ratio of an unknown (0) count.
std::uint64_t count_target(const SimplifyOptions& options, std::uint64_t faces) {
  std::uint64_t target = options.target_faces;
  if (options.target_ratio > 0 && faces > 0) {
    const std::uint64_t by_ratio = ratio_target(options.target_ratio, faces);
    target = target > 0 ? std::min(target, by_ratio) : by_ratio;
  }
  return target;
}

// The bytes of vertex array the input may hold in core (ReadOptions::memory_budget); past them its faces are
// dereferenced on disk and clustered as a triangle soup. It may hold what the indexed clustering's full plan
// for twice the target leaves of the budget (at least half of it), and more while the indexed pass at its
// least plan, the whole vertex array beside its cells, takes no more than the soup's pass at its own least
// plan: the soup's cells take 8 times the bytes a vertex of the target (1,800 bytes a cell at twice the cells
// a vertex, against 220 at the margin's count), so out of core pays only for targets far below the input,
// and where neither path keeps the limit, staying in core is the smaller overshoot (gen 20 M to 200 k faces
// under 200M: 409 MiB out of core, 179 MiB in core). For a ratio the target comes from the file's announced
// count; without a count target, half the budget.
std::uint64_t vertex_allowance(const std::string& input_path, const SimplifyOptions& options, double budget) {
  const std::uint64_t target = count_target(options, triangles_hint(input_path));
  double allowance = budget / 2;
  if (target > 0) {
    const double fine_per_vertex = options.cluster.fine_cells_per_target;
    const double full_plan = kLevelMargin * kClusterBytesPerCell *
                             fine_cells_for(2.0 * static_cast<double>(target), fine_per_vertex);
    const double least_intermediate = kMinMultiple * static_cast<double>(target);
    const double indexed_least =
        kLevelMargin * pass_bytes_per_cell(false, false, false) *
        fine_cells_for(least_intermediate, fine_per_vertex, 0, min_fine_per_vertex(false));
    const double soup_least = kSoupClusterBytesPerCell * fine_cells_for(least_intermediate, fine_per_vertex,
                                                                        0, min_fine_per_vertex(true));
    allowance = std::max(budget - std::min(budget / 2, full_plan), soup_least - indexed_least);
  }
  // At least a byte: 0 would mean no bound at all (a --memory-limit of 1 byte read the input in core).
  return std::max<std::uint64_t>(1, static_cast<std::uint64_t>(allowance));
}

// The most memory the process can hold: the machine's (or its container's), and half its address-space
// limit (ulimit -v) where it has one, as code, thread stacks and the allocator's arenas take address space
// too.
std::uint64_t memory_room() {
  const std::uint64_t physical = physical_memory_bytes(), address_space = address_space_limit();
  return address_space > 0 ? std::min(physical, address_space / 2) : physical;
}

}  // namespace

std::uint64_t cluster_vertex_allowance(const ClusterOptions& options, std::uint64_t budget) {
  auto cells = static_cast<double>(planned_fine_cells(options));
  double indexed = kLevelMargin * pass_bytes_per_cell(false, false, false) * cells;
  double soup = kSoupClusterBytesPerCell * cells;
  if (cells == 0 && !(options.cell_size > 0)) {
    // --grid: no plan, but the grid bounds the cells a surface can occupy. The in-core pass's cells cost
    // about 280 bytes, the soup's 460-740 (gen 1 M and 4 M on grids of 128 to 1024), so out of core pays only
    // for a grid coarse against the input: gen 4 M on --grid 128 peaked at 53 MiB in core and 60 out of
    // core. Counted at the most a surface takes, staying in core costs at most its vertex array too many;
    // counted too few, the soup's cells could cost many times that (`--grid 4096 --memory-limit 50M` took
    // gen 20 M from 2.6 GB in core to 5.8 GB out of core).
    cells = kGridSurfaceCells * static_cast<double>(options.grid) * static_cast<double>(options.grid);
    indexed = kPassBytesPerCell * cells;
    soup = kSoupGridBytesPerCell * cells;
  }
  // A --cell-size grid's cells are unknown until its pass has found the box, and the vertex array is over
  // the budget for certain in core: out of core is then the one way to keep it.
  double allowance = std::max(static_cast<double>(budget), soup - indexed);
  // Never more than half of what the machine can hold (nor less than the limit asked for): an array larger
  // than that leaves no room for the cells beside it.
  allowance =
      std::max(static_cast<double>(budget), std::min(allowance, 0.5 * static_cast<double>(memory_room())));
  return std::max<std::uint64_t>(1, static_cast<std::uint64_t>(std::min(allowance, 1.8e19)));
}

namespace {

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// What the first stage leaves for the decimator, and what the run learned on the way.
struct FirstStage {
  QuadricMesh mesh;
  bool clustered = false;
  bool out_of_core = false;
  std::string attributes_left_out;
  std::uint64_t memory_needed = 0;  // SimplifyResult::memory_needed
  std::uint64_t input_faces = 0;
  std::uint64_t intermediate_faces = 0;
  std::uint64_t cluster_target_faces = 0;  // what the clustering stage was asked for
  bool intermediate_given = false;         // --intermediate, rather than the memory limit, set it
  std::vector<PhaseReport> phases;
  ClusterStats cluster;
  std::uint64_t memory_limit = 0;
  // Once clustered: what reading the input whole and decimating it in core is expected to take.
  double whole_peak = 0;
  // The decimator's targets: in core the ratio is left to the decimator, which applies it to the exact face
  // count it sees; after clustering it is resolved against the input's count here.
  std::uint64_t target_faces = 0;
  double target_ratio = 0;
};

// What a run that gives up on clustering says it does next, at `whole_peak` bytes against `limit`.
std::string reread_note(double whole_peak, std::uint64_t limit) {
  return "reading the input again to decimate it in core, which is expected to take about " +
         format_bytes(static_cast<std::uint64_t>(whole_peak)) +
         (whole_peak > static_cast<double>(limit) ? ", over the memory limit of " + format_bytes(limit)
                                                  : std::string());
}

// `whole`: read the whole input for the decimator, whatever the limit (see simplify's second try).
FirstStage first_stage(const std::string& input_path, const SimplifyOptions& options, bool whole = false) {
  FirstStage stage;
  stage.memory_limit = effective_memory_limit(options.memory_limit);
  // The process before it reads anything (code, libraries, thread pools): the estimate below adds to it.
  const auto process_bytes = static_cast<double>(peak_rss_bytes());
  const double budget = static_cast<double>(stage.memory_limit);

  auto start = Clock::now();
  ReadOptions read;
  read.progress = options.progress;
  read.warn = options.warn;
  read.memory_budget = whole ? 0 : vertex_allowance(input_path, options, budget);
  // The decimator welds the sides of a seam back together and keeps each one's attributes.
  read.split_corner_attributes = options.decimate.weld;
  std::unique_ptr<TriangleStream> stream = open_triangle_stream(input_path, read);
  const double fine_per_vertex = options.cluster.fine_cells_per_target;
  stage.out_of_core = dereferenced_out_of_core(*stream);
  stage.attributes_left_out = stream->attributes_left_out();
  if (!stage.attributes_left_out.empty() && options.warn)
    options.warn(attributes_left_out_warning(stage.attributes_left_out));
  // The vertex array held through the clustering pass: positions and whatever attributes the reader kept.
  const IndexedMesh& held = stream->vertices();
  const double vertex_bytes = static_cast<double>(
      held.positions.size() * ocsimp::vertex_bytes(held.has_normals(), held.has_colors(), held.has_uvs()));
  // OBJ does not say its face count up front; its size does, roughly (at least ~20 bytes a face line).
  std::uint64_t faces_hint = stream->triangles_hint();
  if (faces_hint == 0) faces_hint = stream->bytes_total() / 40;
  stage.input_faces = faces_hint;
  stage.phases.push_back({"open", seconds_since(start), 0, 0, peak_rss_bytes()});

  const std::uint64_t target = count_target(options, faces_hint);

  // Intermediate size: a few times the target, as large as both stages' memory allows.
  // The largest intermediate whose fine cells fit beside the vertex array: fine_cells_for is the full
  // per-vertex count below the cap, flat at the cap, then the minimum per-vertex count, so its inverse is
  // room / full below the cap and room / minimum from it on (vertices; twice that in faces).
  const bool soup = !stream->indexed();
  // Bytes per occupied fine cell, and what the stream holds beside the cells.
  const double cell_bytes = soup ? kSoupClusterBytesPerCell : kClusterBytesPerCell;
  const double held_bytes = soup ? static_cast<double>(dereference_buffer_bytes(*stream)) : vertex_bytes;
  const double min_per_vertex = min_fine_per_vertex(soup);
  // The indexed pass holds the vertex array beside its accumulating cells only, and releases it before the
  // merge state grows; a soup's buffers stay beside all of it. Both beside the process itself.
  const double pass_bytes = pass_bytes_per_cell(held.has_normals(), held.has_colors(), held.has_uvs());
  const double free_bytes = std::max(0.0, budget - kProcessBytes);
  const double cell_room =
      soup ? std::max(0.0, free_bytes - held_bytes) / (kLevelMargin * cell_bytes)
           : std::min(std::max(0.0, free_bytes - vertex_bytes) / (kLevelMargin * pass_bytes),
                      free_bytes / (kLevelMargin * cell_bytes));
  const double cluster_room =
      2.0 * cell_room /
      (cell_room < kMaxFineCells ? fine_per_vertex : std::min(min_per_vertex, fine_per_vertex));
  const double decimate_room = budget / kInCoreBytesPerFace;
  const double room = std::min(cluster_room, decimate_room);
  std::uint64_t intermediate_faces;
  if (target > 0) {
    const double multiple =
        options.intermediate > 0
            ? options.intermediate
            : std::clamp(std::floor(room / static_cast<double>(target)), kMinMultiple, kMaxIntermediate);
    double faces = multiple * static_cast<double>(target);
    if (options.intermediate == 0) faces = std::max(faces, std::min(kMinIntermediate, room));
    // Never more than the input's triangles can be (a multiple of 1e30 asks for all of them): the cast of a
    // larger double overflowed, and the octree was then asked for its minimum of 4 faces.
    intermediate_faces =
        static_cast<std::uint64_t>(std::min(faces, kTrianglesPerPolygon * static_cast<double>(faces_hint)));
  } else {
    // An error bound alone: as large as the budget allows, which leaves the clustering stage the least
    // error. --two-stage asks for the stage where the input fits, which that size would leave out; it gets
    // the size a count target gets at least.
    double faces = std::max(room, 1000.0);
    if (options.two_stage && options.intermediate == 0) faces = std::min(faces, kMinIntermediate);
    intermediate_faces = static_cast<std::uint64_t>(faces);
  }
  const double in_core_bytes = vertex_bytes + kInCoreBytesPerFace * static_cast<double>(faces_hint);
  // Clustering to an intermediate at least as large as the input merges nothing, and its quadrics, rebuilt
  // without connectivity, only approximate the decimator's own: an input that small is decimated directly,
  // --two-stage or not, unless --intermediate asks for a size. On fandisk (13 k faces) to 9-40 faces, with an
  // intermediate of the whole mesh, the carried quadrics alone moved the final RMS by 0.83-1.24x of pure
  // decimation's (the greedy order at a few dozen faces turns on ties).
  const bool whole_input = options.intermediate == 0 && intermediate_faces >= faces_hint;
  // An intermediate asked for may exceed the hint, which counts polygons, not their triangles: 2,400 quads
  // (4,800 triangles) capped an --intermediate of 4,500 at 2,400, under the target of 3,000.
  if (options.intermediate == 0) intermediate_faces = std::min(intermediate_faces, faces_hint);
  const std::uint64_t cluster_target_faces = std::max<std::uint64_t>(intermediate_faces, 4);
  // Fewer fine cells a vertex where the budget has no room for the full count, down to the minimum.
  const double fine_cells = fine_cells_for(static_cast<double>(cluster_target_faces), fine_per_vertex,
                                           std::min(kMaxFineCells, cell_room), min_per_vertex);
  // Even the fewest fine cells the intermediate can have may not fit: the run goes on (the target comes
  // first), and says what it expects to take, with the planned number of cells rather than the margin's
  // (a warning at every run whose grid merely could come out larger would be noise). An indexed pass holds
  // the vertex array beside its accumulating cells, counted at the margin's number as they are the smaller
  // part, and releases it before the merge state grows.
  // The peak of an indexed clustering whose merge state holds `cells` and whose pass holds `pass_cells`.
  auto indexed_peak = [&](double cells, double pass_cells) {
    return process_bytes + std::max(vertex_bytes + pass_cells * pass_bytes, cells * cell_bytes);
  };
  const double expected_peak = soup ? process_bytes + held_bytes + fine_cells * cell_bytes
                                    : indexed_peak(fine_cells, kLevelMargin * fine_cells);
  // In core when the decimation fits the limit, and also when it does not but clustering first would take
  // more: a 2 M-triangle scan to 1.5 M faces under a 300 MB limit was clustered (757 MiB, 4.4 s) where
  // decimating directly took 297 MiB and 1.6 s.
  const double in_core_peak = process_bytes + in_core_bytes;
  const bool may_decimate_directly = (!options.two_stage || whole_input) && !stage.out_of_core;
  const bool in_core = may_decimate_directly && (in_core_bytes <= budget || in_core_peak < expected_peak);
  // Reads the whole input for the decimator.
  auto read_all = [&] {
    start = Clock::now();
    stage.mesh.mesh = read_mesh(*stream);
    stream.reset();
    stage.input_faces = stage.mesh.mesh.face_count();
    stage.phases.push_back(
        {"read", seconds_since(start), stage.input_faces, stage.input_faces, peak_rss_bytes()});
    stage.target_faces = options.target_faces;
    stage.target_ratio = options.target_ratio;
  };
  // The same, instead of clustering; `cluster_peak`: what clustering first was expected to take.
  auto read_whole = [&](double cluster_peak) {
    stage.memory_needed = 0;
    if (in_core_bytes > budget) {
      stage.memory_needed = static_cast<std::uint64_t>(in_core_peak);
      if (options.warn) {
        options.warn("decimating in core is expected to take about " + format_bytes(stage.memory_needed) +
                     ", over the memory limit of " + format_bytes(stage.memory_limit) +
                     ", which clustering first would exceed further (about " +
                     format_bytes(static_cast<std::uint64_t>(cluster_peak)) + ")");
      }
    }
    read_all();
  };
  if (whole) {
    stage.memory_needed = in_core_bytes > budget ? static_cast<std::uint64_t>(in_core_peak) : 0;
    read_all();
    return stage;
  }
  if (in_core) {
    read_whole(expected_peak);
    return stage;
  }
  // Clustering knows no seams: a cell on one averages both sides' texture coordinates.
  if (held.has_uvs() && options.warn) {
    options.warn(
        "the clustering stage averages texture coordinates over each of its cells, so the texture smears "
        "along uv seams; decimating directly (without --two-stage, an input that fits the memory limit) "
        "keeps each side's");
  }
  ClusterOptions cluster_options = options.cluster;
  cluster_options.octree = true;
  cluster_options.target_vertices = 0;
  // The original's border planes ride in the quadrics; the decimator's own would see the clustered mesh's
  // spurious borders and folds (see borders_carried).
  cluster_options.border_in_quadrics = cluster_options.preserve_boundary;
  cluster_options.carried_border_weight = options.decimate.boundary_weight;
  cluster_options.target_faces = cluster_target_faces;
  stage.cluster_target_faces = cluster_options.target_faces;
  stage.intermediate_given = options.intermediate > 0;
  cluster_options.fine_cells_per_target =
      fine_cells / (static_cast<double>(cluster_options.target_faces) / 2);
  auto warn_over = [&](double peak) {
    stage.memory_needed = static_cast<std::uint64_t>(peak);
    if (options.warn) {
      options.warn("clustering to the target is expected to take about " + format_bytes(stage.memory_needed) +
                   ", over the memory limit of " + format_bytes(stage.memory_limit) +
                   " (a larger memory limit or a smaller target keeps within it)");
    }
  };
  // An indexed pass counts its fine cells before it reads a face, and the count can be well off the plan:
  // the level that holds the cells the target needs can have up to about 4 times as many (a surface's cells
  // grow 4x a level). 2 M triangles to 500 k faces under 260 MB planned 375 k cells, got 782 k and peaked at
  // 466 MiB, where decimating in core takes about 300. So the pass says what it got, and the estimate is
  // made again from it: over the limit, and over what decimating in core takes, the stream is read whole
  // instead (the pass has then read no face); over the limit only, the warning gives the new estimate.
  double declined_peak = 0;
  if (soup) {
    if (expected_peak > budget) warn_over(expected_peak);
  } else {
    cluster_options.accept_fine_cells = [&](std::uint64_t cells) {
      const double peak = indexed_peak(static_cast<double>(cells), static_cast<double>(cells));
      if (peak <= budget) return true;
      if (may_decimate_directly && in_core_peak < peak) {
        declined_peak = peak;
        return false;
      }
      warn_over(peak);
      return true;
    };
  }
  // The capped fine grid above is the point, so the pass refines it only where it could not even give the
  // decimator its final target (far-apart parts, a far stray point): then the intermediate came out empty.
  // With an error bound alone, a quarter of the intermediate's vertices: a surface spanning its box gets
  // at least kMinFinePerVertex cells a vertex, less what rounding to a whole level takes.
  cluster_options.refine_until_cells =
      std::max<std::uint64_t>(1, target > 0 ? target : cluster_options.target_faces / 8);
  cluster_options.threads = static_cast<unsigned>(std::max(options.threads, 0));
  cluster_options.progress = options.progress;
  start = Clock::now();
  stage.mesh = cluster(*stream, cluster_options, &stage.cluster);
  if (stage.cluster.declined) {
    read_whole(declined_peak);
    return stage;
  }
  // The in-memory path's reader refuses such a file; the streaming one only knows once the pass is done.
  if (stage.cluster.input_triangles == 0) throw Error(stream->path(), {}, "the mesh has no faces");
  stream.reset();
  // Cells keep no face across a part thinner than they are: a 1000 x 0.01 strip of 8,000 faces clustered to
  // none for a target of 800, its finest grid short of its target, and the decimator could not then reach
  // its own. (An octree that met its target, the largest count it reaches not above it, did its part.) The
  // target comes first, as for a limit too small for any intermediate: the input is read again, whole, and
  // decimated in core over the limit, when the process can have that memory (also when the limit had sent
  // its vertices to disk: a 4,000-face strip under a 1 KiB limit was written with no face at all).
  const std::uint64_t clustered_faces = stage.mesh.mesh.face_count();
  const std::uint64_t final_target = count_target(options, stage.cluster.input_triangles);
  const double whole_peak =
      process_bytes + vertex_bytes + kInCoreBytesPerFace * static_cast<double>(stage.cluster.input_triangles);
  stage.whole_peak = whole_peak;
  // With an error bound alone there is no count to fall short of, but a clustering that kept no face at all
  // still gave an empty output.
  const bool short_of_count = !stage.cluster.target_met && final_target > 0 &&
                              clustered_faces < final_target && stage.cluster.input_triangles > final_target;
  const bool lost_everything = final_target == 0 && clustered_faces == 0;
  if ((short_of_count || lost_everything) && whole_peak <= static_cast<double>(memory_room())) {
    const bool over = whole_peak > budget;
    stage.memory_needed = over ? static_cast<std::uint64_t>(whole_peak) : 0;
    if (options.warn) {
      options.warn(
          "clustering kept " + std::to_string(clustered_faces) + " faces" +
          (lost_everything ? std::string() : ", under the target of " + std::to_string(final_target)) +
          " (a face whose corners share a cell collapses, and thin or small parts lose all theirs): " +
          reread_note(whole_peak, stage.memory_limit));
    }
    stage.mesh = {};
    stage.cluster = {};
    read.warn = {};          // what the first read had to say is said
    read.memory_budget = 0;  // in core, over the limit, as the warning says
    stage.out_of_core = false;
    stream = open_triangle_stream(input_path, read);
    read_all();
    return stage;
  }
  stage.clustered = true;
  stage.input_faces = stage.cluster.input_triangles;
  stage.intermediate_faces = clustered_faces;
  stage.phases.push_back(
      {"cluster", seconds_since(start), stage.input_faces, stage.intermediate_faces, peak_rss_bytes()});
  stage.target_faces = count_target(options, stage.input_faces);
  stage.target_ratio = 0;
  return stage;
}

// Whether the first stage's quadrics already hold the original's border planes (clustering with boundary
// preservation puts them there): the decimator then adds none of its own (boundary_weight 0), since on a
// clustered mesh it would also constrain spurious borders and the folds of overlapping triangles. Measured on
// a 10 M scan to 0.1 % through a 1.28 M-face octree intermediate: RMS 0.00119 with the decimator's own border
// planes, 0.00085 without; pure decimation 0.00065.
bool borders_carried(const FirstStage& stage, const ClusterOptions& cluster) {
  return stage.clustered && cluster.preserve_boundary;
}

void check_common(const SimplifyOptions& options) {
  // The library's own words (the command line checks its flags first); a NaN ratio passed the old test.
  if (!(options.target_ratio >= 0 && options.target_ratio <= 1))
    throw Error("the ratio must be in (0, 1] (or 0: none)");
  if (options.intermediate != 0 && !(options.intermediate >= 1 && std::isfinite(options.intermediate)))
    throw Error(
        "the intermediate multiple must be a finite number of at least 1 (or 0: chosen from the memory "
        "limit)");
}

// The clustering stage's error, measured as the decimator measures a collapse (DecimateStats::max_error):
// the largest over the intermediate's vertices of sqrt(Q(p) / S), each vertex's carried quadric at its own
// position over its surface area. A vertex no collapse takes keeps that error into the output. 0 when not
// clustered.
double intermediate_error(const FirstStage& stage) {
  if (!stage.clustered) return 0;
  const QuadricMesh& m = stage.mesh;
  double largest = 0;
  for (std::size_t v = 0; v < m.quadrics.size(); ++v) {
    const double error = m.quadrics[v].evaluate(m.mesh.positions[v].cast<double>());
    largest = std::max(largest, error_distance(error, surface_area(m, v)));
  }
  return largest;
}

// The fields simplify() and lod() report alike, from the first stage.
template <class Result>
void report_first_stage(FirstStage& stage, Result& result) {
  result.clustered = stage.clustered;
  result.cluster_error = intermediate_error(stage);
  result.out_of_core = stage.out_of_core;
  result.attributes_left_out = std::move(stage.attributes_left_out);
  result.memory_needed = stage.memory_needed;
  result.input_faces = stage.input_faces;
  result.intermediate_faces = stage.intermediate_faces;
  result.phases = std::move(stage.phases);
  result.cluster = stage.cluster;
  result.memory_limit = stage.memory_limit;
}

// A decimation that started below its face target because the clustering stage went there (its grid
// merges whole small parts at once, so "the largest count not above" can be far below) did not reach it,
// whatever the decimator, which saw only the intermediate mesh, says.
void check_intermediate_reached(const FirstStage& stage, std::uint64_t target, std::uint64_t decimate_in,
                                DecimateStats& stats) {
  if (!stage.clustered || target == 0 || decimate_in >= target || stage.input_faces <= target) return;
  stats.target_reached = false;
  stats.stop = DecimateStop::blocked;
  stats.reason = "stopped at " + std::to_string(stats.faces) + " faces (target " + std::to_string(target) +
                 " faces): the clustering stage left only " + std::to_string(decimate_in) + " faces, ";
  if (stage.cluster_target_faces > target) {
    stats.reason += "as its grid merged whole small parts (a larger --intermediate keeps more)";
  } else {
    // Clustering stops at the largest face count not above its own target: with no room above the final
    // target, that is short of it whatever the mesh.
    stats.reason += std::string("the largest count not above its own target, which ") +
                    (stage.intermediate_given ? "--intermediate" : "the memory limit") +
                    " kept at the final target (a larger one keeps more)";
  }
}

// A clustered mesh's merged walls and folds can block the decimator above a target the input reaches: a
// cup of 980 k faces with walls 0.01 thick (3 across), to 10,000 faces under 120M, stopped at 15,579 faces
// of 4,158 vertices, non-manifold everywhere, where decimating in core gets there at a tenth of the
// Hausdorff distance. The target comes first, as where the clustering kept too few faces: the input is to
// be read again, whole, and decimated in core, over the limit, when the process can have that memory.
// (Only above the target: a clustering that left fewer faces than it is reported by
// check_intermediate_reached.) Says so through `warn` when it is.
bool gives_way_to_in_core(const FirstStage& stage, const DecimateStats& stats, std::uint64_t target,
                          const WarningFn& warn) {
  if (!stage.clustered || stats.stop != DecimateStop::blocked || target == 0 || stats.faces <= target ||
      stage.whole_peak > static_cast<double>(memory_room()))
    return false;
  if (warn) {
    warn("decimating the clustered mesh stopped at " + std::to_string(stats.faces) +
         " faces, above the target of " + std::to_string(target) +
         " (clustering merges walls thinner than its cells, and the folds left block collapses): " +
         reread_note(stage.whole_peak, stage.memory_limit));
  }
  return true;
}

}  // namespace

// Called for inputs only: a clustered intermediate is indexed whatever the input was, and has no repeated or
// degenerate faces.
void check_input_faces(const std::string& path, const WarningFn& warn, bool weld,
                       const DecimateStats& stats) {
  if (const std::string reason = nothing_to_decimate_reason(stats, weld); !reason.empty())
    throw Error(path, {}, reason);
  if (!warn) return;
  if (const std::string note = dropped_faces_note(stats); !note.empty()) warn(note);
  if (const std::string note = separate_faces_note(stats, weld); !note.empty()) warn(note);
  // As lod and bench say of a level: a target the input already meets removes nothing.
  const bool faces = stats.target_faces > 0 && stats.target_faces >= stats.input_faces;
  if (faces || (stats.target_vertices > 0 && stats.target_vertices >= stats.input_vertices)) {
    warn("the target of " + std::to_string(faces ? stats.target_faces : stats.target_vertices) +
         (faces ? " faces" : " vertices") + " is not below the " +
         std::to_string(faces ? stats.input_faces : stats.input_vertices) + " it decimates: none is removed");
  }
}

std::string attributes_left_out_warning(const std::string& left_out) {
  return "its " + left_out +
         " are not in the output: past the memory limit the faces are read from disk with their vertices' "
         "attributes, but not those a file gives per face corner (an OBJ's normals and texture coordinates, "
         "a PLY's texcoord lists), and an OBJ's vertex colors only when its first 65,536 vertices have some";
}

std::uint64_t effective_memory_limit(std::uint64_t memory_limit) {
  // A third of the machine's memory, and never more than the room the process has: under `ulimit -v`, a third
  // of the machine planned an in-core run that the address-space limit then refused (a 3 M-triangle scan
  // under 400 MB: out of memory at 250 MiB, where clustering first fits).
  return memory_limit > 0 ? memory_limit : std::min(physical_memory_bytes() / 3, memory_room());
}

SimplifyResult simplify(const std::string& input_path, const SimplifyOptions& options) {
  const bool has_count = options.target_faces > 0 || options.target_ratio > 0;
  if (!has_count && !std::isfinite(options.max_error)) {
    throw Error("simplify needs a target: a face count, a ratio or a maximum error");
  }
  check_common(options);

  FirstStage stage = first_stage(input_path, options);
  SimplifyResult result;
  report_first_stage(stage, result);

  DecimateOptions decimate_options = options.decimate;
  decimate_options.max_error = options.max_error;
  decimate_options.threads = options.threads;
  decimate_options.progress = options.progress;
  decimate_options.target_faces = stage.target_faces;
  decimate_options.target_ratio = stage.target_ratio;
  if (borders_carried(stage, options.cluster)) decimate_options.boundary_weight = 0;

  auto start = Clock::now();
  std::uint64_t decimate_in = stage.mesh.mesh.face_count();
  DecimateResult decimated = decimate(std::move(stage.mesh), decimate_options);
  check_intermediate_reached(stage, stage.target_faces, decimate_in, decimated.stats);
  if (gives_way_to_in_core(stage, decimated.stats, stage.target_faces, options.warn)) {
    std::vector<PhaseReport> first_try = std::move(result.phases);
    first_try.push_back(
        {"decimate", seconds_since(start), decimate_in, decimated.stats.faces, peak_rss_bytes()});
    decimated = {};
    stage = first_stage(input_path, options, true);
    report_first_stage(stage, result);
    result.phases.insert(result.phases.begin(), first_try.begin(), first_try.end());
    decimate_options.target_faces = stage.target_faces;
    decimate_options.target_ratio = stage.target_ratio;
    decimate_options.boundary_weight = options.decimate.boundary_weight;
    start = Clock::now();
    decimate_in = stage.mesh.mesh.face_count();
    decimated = decimate(std::move(stage.mesh), decimate_options);
  }
  check_input_faces(input_path, options.warn, options.decimate.weld, decimated.stats);
  result.mesh = std::move(decimated.mesh);
  result.decimate = decimated.stats;
  // The decimator kept its own collapses within the bound, but the intermediate it started from was
  // clustered to a size, not to an error.
  if (result.cluster_error > options.max_error) {
    char text[384];
    std::snprintf(text, sizeof text,
                  "the clustering stage's vertices already lie up to %.6g from the original's planes, over "
                  "--max-error %.6g (%s)",
                  result.cluster_error, options.max_error,
                  options.two_stage
                      ? "--two-stage clustered it first; without it, an input that fits the memory "
                        "limit is decimated directly"
                      : "the input did not fit the memory limit and was clustered first, as finely "
                        "as the limit allows; a larger --memory-limit keeps more of it");
    result.decimate.target_reached = false;
    result.decimate.reason = text;
  }
  result.phases.push_back(
      {"decimate", seconds_since(start), decimate_in, result.mesh.face_count(), peak_rss_bytes()});
  return result;
}

namespace {

std::string format_ratio(double ratio) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", ratio);
  return text;
}

// Ratio levels: in (0, 1] and distinct, largest first.
std::vector<double> sorted_ratios(const LodOptions& options) {
  std::vector<double> ratios = options.level_ratios;
  for (double r : ratios) {
    if (!(r > 0 && r <= 1)) throw Error("lod: a ratio of " + format_ratio(r) + ": ratios must be in (0, 1]");
  }
  std::sort(ratios.begin(), ratios.end(), std::greater<>());
  if (const auto twice = std::adjacent_find(ratios.begin(), ratios.end()); twice != ratios.end())
    throw Error("lod: the ratio " + format_ratio(*twice) + " is given twice");
  return ratios;
}

}  // namespace

LodResult lod(const std::string& input_path, const LodOptions& options) {
  const bool by_ratio = !options.level_ratios.empty();
  if (options.level_faces.empty() == !by_ratio)
    throw Error("lod needs its levels as face counts or as ratios, one of the two (--faces or --ratios)");
  std::vector<std::uint64_t> levels = options.level_faces;
  const std::vector<double> ratios = by_ratio ? sorted_ratios(options) : std::vector<double>{};
  std::sort(levels.begin(), levels.end(), std::greater<>());
  if (!by_ratio && levels.back() == 0) throw Error("lod: a level of 0 faces");
  if (std::adjacent_find(levels.begin(), levels.end()) != levels.end()) {
    throw Error("lod: the level " + std::to_string(*std::adjacent_find(levels.begin(), levels.end())) +
                " is given twice");
  }

  SimplifyOptions first;
  if (by_ratio) {
    first.target_ratio = ratios.front();
  } else {
    first.target_faces = levels.front();
  }
  first.memory_limit = options.memory_limit;
  first.two_stage = options.two_stage;
  first.intermediate = options.intermediate;
  first.cluster = options.cluster;
  first.decimate.weld = options.decimate.weld;  // the first stage reads seams split only for a welding run
  first.warn = options.warn;
  first.threads = options.threads;
  first.progress = options.progress;
  check_common(first);
  FirstStage stage = first_stage(input_path, first);
  if (by_ratio) {
    // The input's count is exact now: read, or counted by the clustering pass.
    for (std::size_t i = 0; i < ratios.size(); ++i) {
      levels.push_back(ratio_target(ratios[i], stage.input_faces));
      if (i > 0 && levels[i] == levels[i - 1]) {
        throw Error(input_path, {},
                    "the ratios " + format_ratio(ratios[i - 1]) + " and " + format_ratio(ratios[i]) +
                        " both give " + std::to_string(levels[i]) + (levels[i] == 1 ? " face" : " faces") +
                        " of its " + std::to_string(stage.input_faces) +
                        " (give fewer or farther-apart levels)");
      }
    }
  }
  if (options.on_targets) options.on_targets(levels);
  LodResult result;
  report_first_stage(stage, result);

  QuadricMesh input = std::move(stage.mesh);
  double max_error = result.cluster_error;
  for (std::size_t i = 0; i < levels.size(); ++i) {
    auto start = Clock::now();
    DecimateOptions decimate_options = options.decimate;
    decimate_options.target_faces = levels[i];
    decimate_options.target_vertices = 0;
    decimate_options.target_ratio = 0;
    decimate_options.max_error = std::numeric_limits<double>::infinity();
    decimate_options.threads = options.threads;
    decimate_options.progress = options.progress;
    // The next level starts from this one; its vertices' quadrics are what make its costs distances to the
    // original surface rather than to this level's.
    decimate_options.output_quadrics = i + 1 < levels.size();
    // Levels after the first take quadrics that already hold the border planes of the level before.
    if (i > 0 || borders_carried(stage, options.cluster)) decimate_options.boundary_weight = 0;
    std::uint64_t faces_in = input.mesh.face_count();
    DecimateResult decimated = decimate(std::move(input), decimate_options);
    check_intermediate_reached(stage, levels[i], faces_in, decimated.stats);
    const std::string name = "level " + std::to_string(levels[i]);
    // As in simplify, and from the level that stopped on: the levels before it are made, and those after
    // it start from it.
    const bool gave_way = gives_way_to_in_core(stage, decimated.stats, levels[i], options.warn);
    if (gave_way) {
      result.phases.push_back(
          {name, seconds_since(start), faces_in, decimated.stats.faces, peak_rss_bytes()});
      decimated = {};
      std::vector<PhaseReport> phases = std::move(result.phases);
      stage = first_stage(input_path, first, true);
      if (i == 0) {
        // Nothing out of the clustering stage remains in the chain.
        report_first_stage(stage, result);
        max_error = result.cluster_error;
      } else {
        result.memory_needed = std::max(result.memory_needed, stage.memory_needed);
        result.phases = std::move(stage.phases);
      }
      // The new read's phases after those of the first try.
      phases.insert(phases.end(), result.phases.begin(), result.phases.end());
      result.phases = std::move(phases);
      decimate_options.boundary_weight = options.decimate.boundary_weight;
      start = Clock::now();
      faces_in = stage.mesh.mesh.face_count();
      decimated = decimate(std::move(stage.mesh), decimate_options);
    }
    if (i == 0 || gave_way)
      check_input_faces(input_path, options.warn, options.decimate.weld, decimated.stats);

    LodLevel level;
    level.target_faces = levels[i];
    if (by_ratio) level.target_ratio = ratios[i];
    level.faces = decimated.mesh.face_count();
    level.decimate = decimated.stats;
    max_error = std::max(max_error, decimated.stats.max_error);
    level.max_error = max_error;
    if (options.on_level) {
      options.on_level(i, levels[i], decimated.mesh);
    } else {
      level.mesh = decimated.mesh;
    }
    input.mesh = std::move(decimated.mesh);
    input.quadrics = std::move(decimated.quadrics);
    input.areas = std::move(decimated.areas);
    level.seconds = seconds_since(start);
    result.phases.push_back({name, level.seconds, faces_in, level.faces, peak_rss_bytes()});
    result.levels.push_back(std::move(level));
  }
  return result;
}

std::string lod_level_path(const std::string& pattern, std::uint64_t faces, bool several) {
  const std::string key = "{faces}";
  std::string path = pattern;
  std::size_t at = path.find(key);
  if (at == std::string::npos) {
    if (several) throw Error(pattern, {}, "the output pattern needs {faces} to name several levels");
    return path;
  }
  while (at != std::string::npos) {
    path.replace(at, key.size(), std::to_string(faces));
    at = path.find(key, at);
  }
  return path;
}

}  // namespace ocsimp
