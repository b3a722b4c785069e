#include "ocsimp/cluster/cluster.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>
#include <limits>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <queue>
#include <string>

#include "cells.h"
#include "ocsimp/core/error.h"
#include "ocsimp/core/system.h"
#include "place.h"
#include "regroup.h"

namespace ocsimp {

const char* representative_name(Representative representative) {
  switch (representative) {
    case Representative::quadric:
      return "quadric";
    case Representative::constrained:
      return "constrained";
    case Representative::mean:
      return "mean";
  }
  return "unknown";
}

std::uint64_t planned_fine_cells(const ClusterOptions& options) {
  if (!options.octree && options.target_faces == 0) return 0;
  const double vertices = options.octree && options.target_vertices > 0
                              ? static_cast<double>(options.target_vertices)
                              : std::max(1.0, static_cast<double>(options.target_faces) / 2.0);
  // A uniform grid's face target picks among the coarser grids that groups of fine cells make, so a small
  // target needs more fine cells than its vertices would ask for to have resolutions to choose from: at 64
  // cells, bunny --faces 10 had 4 fine cells along its box and every choice gave 0 faces or over 10. The
  // octree merges one cell at a time and reaches any count from its target's own cells.
  const double least = options.octree ? 64.0 : 4096.0;
  return static_cast<std::uint64_t>(
      std::min(std::max(least, options.fine_cells_per_target * vertices), 1.8e19));
}

namespace cluster_detail {
namespace {

// Removes cells no triangle touched (they only hold unreferenced vertices) and renumbers the triangles.
void drop_untouched(FineCells& cells) {
  const std::size_t n = cells.size();
  std::vector<std::uint32_t> renumber(n);
  std::size_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    renumber[i] = static_cast<std::uint32_t>(kept);
    if (!cells.touched[i]) continue;
    if (kept != i) {
      cells.keys[kept] = cells.keys[i];
      cells.quadrics[kept] = cells.quadrics[i];
      if (cells.has_border()) cells.border[kept] = cells.border[i];
      cells.points[kept] = cells.points[i];
      cells.point_sum[kept] = cells.point_sum[i];
      cells.point_box[kept] = cells.point_box[i];
      if (!cells.normal_sum.empty()) cells.normal_sum[kept] = cells.normal_sum[i];
      if (!cells.color_sum.empty()) cells.color_sum[kept] = cells.color_sum[i];
      if (!cells.uv_sum.empty()) cells.uv_sum[kept] = cells.uv_sum[i];
    }
    ++kept;
  }
  if (kept == n) return;
  auto shrink = [kept](auto& v) {
    if (!v.empty()) {
      v.resize(kept);
      v.shrink_to_fit();
    }
  };
  shrink(cells.keys);
  shrink(cells.quadrics);
  shrink(cells.border);
  shrink(cells.points);
  shrink(cells.point_sum);
  shrink(cells.point_box);
  shrink(cells.normal_sum);
  shrink(cells.color_sum);
  shrink(cells.uv_sum);
  cells.touched.assign(kept, 1);
  // Renumbering keeps the order of cells, so the triangles stay ascending and sorted.
  for (CellTriangle& t : cells.triangles) {
    t = CellTriangle{renumber[t.first()], renumber[t.second()] | (t.b & CellTriangle::kFlag),
                     renumber[t.third()] | (t.c & CellTriangle::kFlag)};
  }
}

struct Attributes {
  Vec3d normal = Vec3d::Zero();
  std::array<std::uint64_t, 4> color{0, 0, 0, 0};
  Vec2d uv = Vec2d::Zero();
};

void write_attributes(const FineCells& cells, std::size_t cell, Attributes& a) {
  if (!cells.normal_sum.empty()) a.normal += cells.normal_sum[cell].cast<double>();
  if (!cells.color_sum.empty()) {
    for (int c = 0; c < 4; ++c) a.color[c] += cells.color_sum[cell][c];
  }
  if (!cells.uv_sum.empty()) a.uv += cells.uv_sum[cell];
}

void store_attributes(const FineCells& cells, const Attributes& a, double points, std::size_t out,
                      IndexedMesh& mesh) {
  if (!cells.normal_sum.empty()) {
    const double length = a.normal.norm();
    mesh.normals[out] = length > 0 ? Vec3f((a.normal / length).cast<float>()) : Vec3f::Zero();
  }
  const double divide = points > 0 ? points : 1.0;
  if (!cells.color_sum.empty()) {
    for (int c = 0; c < 4; ++c) {
      mesh.colors[out][c] = static_cast<std::uint8_t>(
          std::min(255.0, std::floor(static_cast<double>(a.color[c]) / divide + 0.5)));
    }
  }
  if (!cells.uv_sum.empty()) mesh.uvs[out] = (a.uv / divide).cast<float>();
}

// The weight to hand border_quadrics() for the border planes the output quadrics carry. It weighs a border
// crossing at w * cell^2; a border runs through a cell in about two crossings of one direction class, so
// its weight per unit length is about 4 w cell, which should be carried_border_weight times the mean edge
// length h, as a decimator's border edges would weigh.
double carried_border_scale(const FineCells& cells, const ClusterOptions& options) {
  // Each triangle adds its area-weighted plane to the cells of its three corners: the traces sum 3x the area.
  double trace = 0;
  for (const Quadric& q : cells.quadrics) trace += q.trace();
  const double triangles = static_cast<double>(std::max<std::uint64_t>(cells.input_triangles, 1));
  const double h = equilateral_edge(trace / 3.0 / triangles);
  const double scale = options.carried_border_weight * h / (4.0 * cells.grid.cell);
  return std::isfinite(scale) ? scale : 0.0;
}

// Leaves out the vertices whose `used` is 0, with their attributes and quadrics, keeping the others' order.
void drop_unused_vertices(const std::vector<std::uint8_t>& used, QuadricMesh& out) {
  IndexedMesh& mesh = out.mesh;
  std::vector<Index> id(used.size(), 0);
  Index kept = 0;
  for (std::size_t v = 0; v < used.size(); ++v) {
    if (!used[v]) continue;
    id[v] = kept;
    mesh.positions[kept] = mesh.positions[v];
    if (!mesh.normals.empty()) mesh.normals[kept] = mesh.normals[v];
    if (!mesh.colors.empty()) mesh.colors[kept] = mesh.colors[v];
    if (!mesh.uvs.empty()) mesh.uvs[kept] = mesh.uvs[v];
    if (!out.quadrics.empty()) out.quadrics[kept] = out.quadrics[v];
    if (!out.areas.empty()) out.areas[kept] = out.areas[v];
    ++kept;
  }
  mesh.positions.resize(kept);
  if (!mesh.normals.empty()) mesh.normals.resize(kept);
  if (!mesh.colors.empty()) mesh.colors.resize(kept);
  if (!mesh.uvs.empty()) mesh.uvs.resize(kept);
  if (!out.quadrics.empty()) out.quadrics.resize(kept);
  if (!out.areas.empty()) out.areas.resize(kept);
  for (Triangle& t : mesh.triangles)
    for (Index& v : t) v = id[v];
}

// Faces the input showed in both turns (the two sides of a thin part clustered onto one cell triple) take
// the turn of the faces around them, which the input did orient: each settled face votes, on every edge it
// shares with an open one, for the turn that crosses the edge the other way, and the open face with the
// clearest vote is settled next, so the choice spreads from the input's turns into runs of such faces. A
// run that no settled face touches is settled from its lowest face, in the turn of its cells' order. A
// closed 2 M-triangle scan clustered to 20 k faces had 287 such faces and, in the cells' order, 295 edges
// that two faces crossed the same way; now none (bunny, horse and igea at 2 %, octree and grid likewise).
void orient_ambiguous(std::vector<Triangle>& triangles, const std::vector<std::uint8_t>& ambiguous,
                      std::size_t vertices) {
  std::vector<Index> open;
  for (std::size_t f = 0; f < triangles.size(); ++f)
    if (ambiguous[f]) open.push_back(static_cast<Index>(f));
  if (open.empty()) return;
  // The edges between corners of ambiguous faces, with every face that uses them, sorted by their unordered
  // ends: faces sharing an edge are neighbours in the list. Only those, so that the list stays small beside
  // the output (all of its edges would be 36 bytes an output face).
  std::vector<std::uint8_t> corner(vertices, 0);
  for (Index f : open)
    for (Index v : triangles[f]) corner[v] = 1;
  struct EdgeUse {
    Index lo, hi, face;
    bool operator<(const EdgeUse& o) const {
      return lo != o.lo ? lo < o.lo : hi != o.hi ? hi < o.hi : face < o.face;
    }
  };
  std::vector<EdgeUse> uses;
  for (std::size_t f = 0; f < triangles.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const Index u = triangles[f][k], v = triangles[f][(k + 1) % 3];
      if (corner[u] && corner[v]) uses.push_back({std::min(u, v), std::max(u, v), static_cast<Index>(f)});
    }
  tbb::parallel_sort(uses.begin(), uses.end());
  // Whether face f goes from u to v.
  auto forward = [&](Index f, Index u, Index v) {
    const Triangle& t = triangles[f];
    for (int k = 0; k < 3; ++k)
      if (t[k] == u) return t[(k + 1) % 3] == v;
    return false;
  };
  // Calls fn(g, u, v) for each other face g on each edge u -> v of face f.
  auto for_each_neighbour = [&](Index f, const auto& fn) {
    for (int k = 0; k < 3; ++k) {
      const Index u = triangles[f][k], v = triangles[f][(k + 1) % 3];
      const EdgeUse key{std::min(u, v), std::max(u, v), 0};
      for (auto it = std::lower_bound(uses.begin(), uses.end(), key);
           it != uses.end() && it->lo == key.lo && it->hi == key.hi; ++it)
        if (it->face != f) fn(it->face, u, v);
    }
  };
  // An open face's votes: +1 for each edge a settled face crosses the other way, -1 for each it crosses the
  // same way. The face with the most votes either way is settled first (then the lowest index), and its
  // open neighbours are counted again. Settling one at a time, rather than every face with a vote at once,
  // matters where two open faces each have one settled neighbour that disagree (a fold): a wavy sheet at
  // a coarse grid kept 3 such edges.
  std::vector<std::uint8_t> settled(triangles.size());
  for (std::size_t f = 0; f < triangles.size(); ++f) settled[f] = !ambiguous[f];
  std::vector<int> votes(triangles.size(), 0);
  using Entry = std::pair<int, std::int64_t>;  // (|votes|, -face): the largest is the next to settle
  std::priority_queue<Entry> queue;
  auto count_votes = [&](Index f) {
    int sum = 0;
    for_each_neighbour(f, [&](Index g, Index u, Index v) {
      if (settled[g]) sum += forward(g, u, v) ? -1 : 1;
    });
    votes[f] = sum;
    if (sum != 0) queue.emplace(std::abs(sum), -static_cast<std::int64_t>(f));
  };
  for (Index f : open) count_votes(f);
  // Each open neighbour's count changes by this face's one vote on their shared edge. Recounting them
  // cost the square of an edge's faces for every face settled: a triangle soup on --grid 5 (290 k output
  // faces on 125 vertices) took 53 s, most of it here. The same counts, so the same order.
  auto settle = [&](Index f) {
    if (votes[f] < 0) std::swap(triangles[f][1], triangles[f][2]);
    settled[f] = 1;
    for_each_neighbour(f, [&](Index g, Index u, Index v) {
      if (settled[g]) return;
      votes[g] += forward(g, u, v) ? -1 : 1;
      if (votes[g] != 0) queue.emplace(std::abs(votes[g]), -static_cast<std::int64_t>(g));
    });
  };
  std::size_t next_open = 0;  // faces with no vote at all are settled in index order, as they are
  for (;;) {
    if (!queue.empty()) {
      const auto [weight, key] = queue.top();
      queue.pop();
      const auto f = static_cast<Index>(-key);
      if (!settled[f] && std::abs(votes[f]) == weight) settle(f);
      continue;
    }
    while (next_open < open.size() && settled[open[next_open]]) ++next_open;
    if (next_open == open.size()) break;
    settle(open[next_open]);
  }
}

// Builds the output: one vertex per cluster, the clusters' triangles, and the surface quadrics.
QuadricMesh assemble(FineCells& cells, const Clustering* clustering, const ClusterOptions& options,
                     ClusterStats& stats) {
  QuadricMesh out;
  IndexedMesh& mesh = out.mesh;
  const std::size_t n = cells.size();
  const std::size_t clusters = clustering ? clustering->count : n;
  mesh.positions.resize(clusters);
  if (!cells.normal_sum.empty()) mesh.normals.resize(clusters);
  if (!cells.color_sum.empty()) mesh.colors.resize(clusters);
  if (!cells.uv_sum.empty()) mesh.uvs.resize(clusters);

  std::vector<Triangle> triangles;
  std::vector<std::uint8_t> ambiguous;  // 1 where the input showed the face in both turns
  report(options.progress, "cluster: place", 0, clusters);
  const double carried_weight = options.border_in_quadrics ? carried_border_scale(cells, options) : 0.0;
  // With the border planes in the quadrics, each vertex says how much of its quadric is surface.
  if (options.border_in_quadrics) out.areas.resize(clusters);
  if (!clustering) {
    // Every fine cell is an output vertex.
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
      Quadric carried;
      const PlacementSums sums =
          cell_placement_sums(cells, i, options.boundary_weight, carried_weight, &carried);
      mesh.positions[i] = nearest_float(place(sums, options.representative).point);
      Attributes a;
      write_attributes(cells, i, a);
      store_attributes(cells, a, sums.points, i, mesh);
      if (options.border_in_quadrics) {
        out.areas[i] = cells.quadrics[i].trace();
        cells.quadrics[i] += carried;
      }
    });
    out.quadrics = std::move(cells.quadrics);
    triangles.reserve(cells.triangles.size());
    ambiguous.reserve(cells.triangles.size());
    for (const CellTriangle& t : cells.triangles) {
      triangles.push_back(t.oriented());
      ambiguous.push_back(t.seen_forward() && t.seen_reversed());
    }
  } else {
    // Members of each cluster, in fine-cell order so every sum runs in the same order.
    std::vector<std::uint32_t> first(clusters + 1, 0), member(n);
    for (std::uint32_t c : clustering->cluster_of) ++first[c + 1];
    for (std::size_t c = 0; c < clusters; ++c) first[c + 1] += first[c];
    {
      std::vector<std::uint32_t> fill(first.begin(), first.end() - 1);
      for (std::size_t i = 0; i < n; ++i)
        member[fill[clustering->cluster_of[i]]++] = static_cast<std::uint32_t>(i);
    }
    out.quadrics.resize(clusters);
    tbb::parallel_for(std::size_t{0}, clusters, [&](std::size_t c) {
      PlacementSums sums;
      Quadric surface;
      double area = 0;
      Attributes a;
      for (std::uint32_t k = first[c]; k < first[c + 1]; ++k) {
        const std::uint32_t i = member[k];
        Quadric carried;
        sums.add(cell_placement_sums(cells, i, options.boundary_weight, carried_weight, &carried));
        surface += cells.quadrics[i];
        if (options.border_in_quadrics) {
          area += cells.quadrics[i].trace();
          surface += carried;
        }
        write_attributes(cells, i, a);
      }
      mesh.positions[c] = nearest_float(place(sums, options.representative).point);
      out.quadrics[c] = surface;
      if (options.border_in_quadrics) out.areas[c] = area;
      store_attributes(cells, a, sums.points, c, mesh);
    });
    std::vector<CellTriangle> mapped;
    mapped.reserve(cells.triangles.size());
    for (const CellTriangle& t : cells.triangles) {
      const std::uint32_t a = clustering->cluster_of[t.first()], b = clustering->cluster_of[t.second()],
                          c = clustering->cluster_of[t.third()];
      if (a == b || b == c || c == a) continue;
      CellTriangle m = CellTriangle::of(a, b, c);
      if (!t.seen_forward()) m = CellTriangle::of(a, c, b);
      if (t.seen_forward() && t.seen_reversed()) m.merge_flags(CellTriangle::of(a, c, b));
      mapped.push_back(m);
    }
    tbb::parallel_sort(mapped.begin(), mapped.end());
    for (std::size_t i = 0; i < mapped.size();) {
      CellTriangle t = mapped[i];
      std::size_t j = i + 1;
      for (; j < mapped.size() && mapped[j].same_cells(t); ++j) t.merge_flags(mapped[j]);
      triangles.push_back(t.oriented());
      ambiguous.push_back(t.seen_forward() && t.seen_reversed());
      i = j;
    }
  }
  orient_ambiguous(triangles, ambiguous, clusters);
  mesh.triangles = std::move(triangles);
  report(options.progress, "cluster: place", clusters, clusters);

  std::vector<std::uint8_t> used(clusters, 0);
  for (const Triangle& t : mesh.triangles)
    for (Index v : t) used[v] = 1;
  stats.isolated_vertices = static_cast<std::uint64_t>(std::count(used.begin(), used.end(), 0));
  // A cluster whose every triangle collapsed (a grid cell at a corner of the surface, a part of the input
  // smaller than a cell) is a vertex no face uses: a point that shows nothing, and that readers flag as
  // unreferenced. It is left out, except where the octree's vertex target counts it (the octree joins such
  // a cluster to a neighbour wherever a collapsed triangle links them, and keeps the rest as points so that
  // --vertices N gives N), and where no face is left at all: the points are then all the output says of
  // the input.
  const bool keep_points = (options.octree && options.target_vertices > 0) || mesh.triangles.empty();
  if (stats.isolated_vertices > 0 && !keep_points) drop_unused_vertices(used, out);
  stats.output_vertices = mesh.positions.size();
  stats.output_faces = mesh.triangles.size();
  return out;
}

std::uint32_t spanned_cells(const std::vector<CellKey>& keys) {
  if (keys.empty()) return 0;
  std::array<std::uint32_t, 3> lo = key_coords(keys[0]), hi = lo;
  for (CellKey key : keys) {
    const std::array<std::uint32_t, 3> c = key_coords(key);
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], c[a]);
      hi[a] = std::max(hi[a], c[a]);
    }
  }
  std::uint32_t span = 0;
  for (int a = 0; a < 3; ++a) span = std::max(span, hi[a] - lo[a] + 1);
  return span;
}

int level_for(double cells) {
  // A surface spanning its box occupies about side^2 cells.
  const double side = std::sqrt(std::max(1.0, cells));
  return std::clamp(static_cast<int>(std::ceil(std::log2(side))), 0, kCoordBits);
}

QuadricMesh run(TriangleStream& stream, const ClusterOptions& options, unsigned threads,
                ClusterStats& stats) {
  const Box3 bounds = stream.bounds();
  PassOptions pass;
  pass.boundary = options.preserve_boundary;
  pass.threads = threads;
  pass.progress = options.progress;
  pass.accept_fine_cells = options.accept_fine_cells;
  const bool targeted = options.octree || options.target_faces > 0;
  if (targeted) {
    const double fine = static_cast<double>(planned_fine_cells(options));
    pass.target_cells = static_cast<std::uint64_t>(std::min(fine, 2e9));
    // A face target asks for as many fine cells as faces: a thin strip whose cross-section fit in one cell
    // had more cells than the target's vertices, yet every triangle collapsed within them, and the output
    // had no face at all.
    const bool by_faces = !(options.octree && options.target_vertices > 0);
    const double wanted = static_cast<double>(by_faces ? options.target_faces : options.target_vertices);
    const double needed =
        options.refine_until_cells > 0 ? static_cast<double>(options.refine_until_cells) : wanted;
    pass.needed_cells = static_cast<std::uint64_t>(std::min({needed, wanted, fine, 2e9}));
    pass.grid = Grid::power_of_two(bounds, level_for(fine));
  } else if (options.cell_size > 0) {
    pass.grid = Grid::sized(bounds, options.cell_size, stream.path());
  } else {
    pass.grid = Grid::uniform(bounds, options.grid);
  }

  FineCells cells = accumulate(stream, pass);
  if (cells.declined_cells > 0) {
    stats.declined = true;
    stats.fine_cells = cells.declined_cells;
    return {};
  }
  drop_untouched(cells);
  stats.input_vertices = cells.input_vertices;
  stats.input_triangles = cells.input_triangles;
  stats.fine_cells = cells.size();
  stats.fine_grid = cells.grid.along_longest;
  stats.spanned_cells = spanned_cells(cells.keys);
  stats.fine_cell_size = cells.grid.cell;
  stats.collapsed_triangles = cells.input_triangles - cells.surviving_instances;
  stats.duplicate_triangles = cells.surviving_instances - cells.triangles.size();

  if (!targeted) {
    stats.output_grid = cells.grid.along_longest;
    stats.output_cell_size = cells.grid.cell;
    return assemble(cells, nullptr, options, stats);
  }
  Clustering clustering;
  if (options.octree) {
    OctreeTarget target;
    target.vertices = options.target_vertices;
    target.faces = options.target_faces;
    clustering =
        octree_merge(cells, target, options.representative, options.boundary_weight, options.progress);
  } else {
    clustering = regrid_to_faces(cells, options.target_faces);
    stats.output_grid = static_cast<std::uint32_t>(std::ceil(clustering.along_longest));
    stats.output_cell_size = cells.grid.cell * cells.grid.along_longest / clustering.along_longest;
  }
  stats.target_met = clustering.target_met;
  // Both merges count a face target as met when they reach the largest count the fine grid allows; a fine
  // grid holding under half the faces asked for, from an input with more, is a miss whatever the merge does
  // (an input whose faces repeat, whose distinct faces are fewer than the target).
  if (options.target_faces > 0 && cells.input_triangles > options.target_faces &&
      cells.triangles.size() < options.target_faces / 2) {
    stats.target_met = false;
  }
  return assemble(cells, &clustering, options, stats);
}

}  // namespace
}  // namespace cluster_detail

QuadricMesh cluster(TriangleStream& stream, const ClusterOptions& options, ClusterStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  if (options.octree && (options.target_vertices > 0) == (options.target_faces > 0)) {
    throw Error("the octree needs exactly one target: a vertex count or a face count");
  }
  if (!options.octree && options.target_vertices > 0) {
    throw Error("an exact vertex count needs the octree");
  }
  // 0 means "use the grid resolution"; a negative or NaN size fell back to it without a word.
  if (!(options.cell_size >= 0.0))
    throw Error("the cell size must be positive (or 0 for the grid resolution)");
  if (!(options.fine_cells_per_target >= 1.0) || !std::isfinite(options.fine_cells_per_target)) {
    throw Error("fine_cells_per_target must be at least 1");
  }
  if (!(options.boundary_weight >= 0.0) || !std::isfinite(options.boundary_weight) ||
      !(options.carried_border_weight >= 0.0) || !std::isfinite(options.carried_border_weight)) {
    throw Error("the boundary weight must be a non-negative number");
  }
  if (options.representative != Representative::quadric && options.representative != Representative::mean &&
      options.representative != Representative::constrained) {
    throw Error("unknown representative " + std::to_string(static_cast<int>(options.representative)));
  }
  if (!stream.vertices().origin.allFinite())
    throw Error(stream.path(), {}, "the stream's origin is not a finite point");
  const unsigned threads = static_cast<unsigned>(
      worker_threads(static_cast<int>(std::min(options.threads, unsigned{std::numeric_limits<int>::max()}))));
  ClusterStats local;
  tbb::task_arena arena(static_cast<int>(threads));
  const Vec3d origin = stream.vertices().origin;  // the stream's positions and corners are relative to it
  QuadricMesh result = arena.execute([&] { return cluster_detail::run(stream, options, threads, local); });
  result.mesh.origin = origin;
  local.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  local.peak_rss_bytes = peak_rss_bytes();
  if (stats) *stats = local;
  return result;
}

}  // namespace ocsimp
