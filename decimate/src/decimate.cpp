// Garland-Heckbert edge collapse with an exact priority queue, on flat arrays of cache-line-sized records.
//
// Layout (per input triangle: 64 bytes of vertex, 28 of face, 12 of face lists, 18 of edges, 12 of heap; the
// `ocsimp decimate` command peaks at 142 bytes on a 10 M-triangle scan): a vertex is one 128-byte record
// (position, face-list segment, flags, scratch, then its double quadric relative to the bounding-box center),
// so looking at a neighbour costs two adjacent cache lines; a face holds its 3 corners, the ids of its 3
// edges and its input normal; an edge holds its endpoints and its slot in an 8-ary heap of float keys. A
// vertex's incident faces are a circular list of CSR segments (its own, then those of the vertices it
// absorbed); each gather packs the live ones into as few segments as hold them, so nothing is allocated per
// collapse and a vertex that absorbed many others still reads one or two lists. The large arrays ask for
// transparent huge pages, and each time half the vertices are gone the survivors are renumbered to the
// front of them, in order (see compact).
//
// The queue is in priority order, so consecutive collapses land anywhere in memory and the loop is bound by
// memory latency. Two things hide some of it: the next collapse is nearly always the cheapest child of the
// heap's root (99.7 % on a 1 M-triangle scan), so its records, lists, faces and then its neighbours' records
// are prefetched stage by stage while the current one computes (about 20 % of the CPU time of a 1 M-triangle
// decimation); and each collapse prefetches the records it is about to re-cost.
//
// Two phases. Phase 1 (meshes of 16 Ki faces or more, without virtual pairs; see run_pass) runs the same
// greedy loop in parallel over fixed spatial regions: the live vertices are cut into K ranges of a Morton
// order (K from the face count only: 4 to 64), and a vertex is interior to its region when every vertex it
// shares a face with is in it too. A collapse of two interior vertices reads and writes only faces, edges,
// vertex records, stamps and face lists of its own region's vertices, and merged neighbourhoods stay in the
// region, so each region keeps its own queue, blocked list, scratch and counters and needs no locks. Each
// region collapses, in rounds, the pairs at or below a key threshold taken from the keys then queued in all
// regions (so cheap pairs go first everywhere, as with one queue), and stops at its share of the targets. A
// second pass does the same over a shifted, turned partition, whose regions hold the first one's seams. The
// passes do most of the collapses a count target asks for (about 96 % on the shared scans; all those under
// the error bound when it is the only criterion), scaled to the part of the mesh off the seams so that the
// seams' share is left to phase 2; phase 2 is the global loop below, from one queue of everything left, to
// the exact target, with compaction, parity, deferral and the retry of blocked pairs as before. What a region
// does depends only on its own records and the thresholds, which are computed between rounds from every
// region's queue, so the output is the same for any thread count. On the generated 1 M-triangle mesh the
// passes also take about 10 % less CPU than the global loop did, as each region's queue stays small. Vertices
// are not renumbered by region: on a 10 M-triangle mesh a region's records lie all over the arrays, and it
// takes about 1.6 times the CPU per input triangle of the 1 M mesh.
//
// A candidate's key comes from its quadric cost (plus the attribute penalty). Guards and the shape penalty
// depend on the neighbourhood, which moves without the pair's quadric changing, so they are evaluated when
// the pair reaches the top: a guard failure takes the pair out of the queue until a collapse next to it, and
// a shape penalty raises its key in place, so the pair collapses only once it is the cheapest with its true
// cost.
#include "ocsimp/decimate/decimate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_sort.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <mutex>
#include <numeric>
#include <string>
#include <vector>

#include "edge_heap.h"
#include "ocsimp/core/big_vector.h"
#include "ocsimp/core/error.h"
#include "ocsimp/core/system.h"
#include "placement.h"
#include "seams.h"

namespace ocsimp {
namespace {

using decimate_detail::add_pair;
using decimate_detail::add_to;
using decimate_detail::EdgeHeap;
using decimate_detail::first_state;
using decimate_detail::HeapEntry;
using decimate_detail::place_pair;
using decimate_detail::Placement;

constexpr Index kNone = 0xFFFFFFFFu;

// Edge states (values of an edge's heap slot when it is not in the heap).
constexpr std::uint32_t kDead = 0xFFFFFFFFu;
constexpr std::uint32_t kIdleLocked = 0xFFFFFFFEu;  // both ends locked: never a candidate while that holds
constexpr std::uint32_t kIdleError = 0xFFFFFFFDu;   // its cost exceeds max_error
constexpr std::uint32_t kBlockedFlip = 0xFFFFFFFCu;
constexpr std::uint32_t kBlockedTopology = 0xFFFFFFFBu;
constexpr std::uint32_t kDeferred = 0xFFFFFFFAu;  // would overshoot a count target
constexpr std::uint32_t kPending = 0xFFFFFFF9u;   // first phase: not a candidate of any region yet
static_assert(kPending >= first_state);

constexpr std::uint32_t kLocked = 1;
constexpr std::uint32_t kHasBlocked =
    2;  // some incident edge is blocked: re-try it when the neighbourhood changes

// The QEM minimizer is taken only within this many edge lengths of the edge midpoint; farther solutions come
// from nearly parallel planes and would pull the surface away from where it was sampled.
constexpr double kReach = 2.0;
// Triangle quality 2 sqrt(3) |n| / sum(l^2) (1 equilateral, 0 degenerate) below which a collapse may not take
// a face. A face that starts below 1 / kDegenerateSlack times this (the long sides and fan caps of a CAD
// cylinder of thousands of segments, a fillet's strip) may not fall below kDegenerateSlack times its input
// quality instead. Requiring such a face never to get worse at all blocked every collapse on those meshes:
// moving a rim vertex changes its neighbours' quality by a relative 1e-7, and a 10,000-segment cylinder did
// not decimate at all. A slack of 0.5 still blocked a strip of 1 by 0.001 quads (quality 0.0017) at its first
// collapses along its length, each of which halves its triangles' quality: 113 faces for 10 with
// --preserve-topology. At 0.02 it reaches its target, and the shared meshes at 10, 1 and 0.3 % decimate to
// the same bytes; lowering kDegenerateQuality to 1e-5 instead did as much for the strip, but raised fandisk's
// Hausdorff distance by 65 % at 1 %. Without --preserve-topology such a strip still falls apart: a collapse
// across it moves its two vertices by half its width, which is all the quadrics see, and the faces between
// such collapses go. The floor costs 4 bytes a face (142.9 -> 146.9 bytes per input face at peak on a 10 M-
// triangle scan).
constexpr double kDegenerateQuality = 1e-3;
constexpr double kDegenerateSlack = 0.02;
// Quality below which a resulting triangle counts as a sliver for the shape penalty. Penalizing every
// collapse by its worst triangle (no threshold) made both RMS and Hausdorff distances worse on the shared
// scans and tripled the collapses re-queued; penalizing slivers only re-queues about 3 % and lowers the
// Hausdorff distance.
constexpr double kSliverQuality = 0.2;
// How far the shape penalty may put a pair back (see try_top's requeued): behind pairs of up to kNearTie
// times the larger of the level the collapses have reached (the largest key applied) and the key of a
// distance of kTieFloor times the square root of the pair's quadric area (its own size). Measured against
// the unbounded penalty over 8 shared meshes at 10, 3, 1 and 0.5 % (32 cases, `decimate --ratio` then
// `compare --samples 200000`), geometric means: RMS -0.8 %, Hausdorff -4.2 %, slivers (quality < 0.2)
// +0.4 %; the scans within 1 % RMS, fandisk from -25 % (1 %) to +14 % (0.5 %). Without the floor (the level
// alone, 0 in flat parts), early collapses at no cost made slivers that blocked later ones: a cube
// decimated from a clustered intermediate with its carried quadrics came out at 2.3 times the RMS. A floor
// of 0.003 let a 100 x 0.1 strip fall apart again.
constexpr float kNearTie = 3.0f;
constexpr double kTieFloor = 0.001;
// A face may not turn more than 60 degrees away from the input face it started as (cos^2 of the limit). At 90
// degrees single faces still ended up facing against the original surface at sharp creases (igea at 1 %);
// at 60 none did on the shared scans, with Hausdorff and RMS distances unchanged within noise.
constexpr double kRefCos2 = 0.25;
// Two faces on an edge whose normals are more than 120 degrees apart fold back onto each other.
constexpr double kFoldCos = -0.5;
// Where the only difference across a seam is the normal, and by less than this angle's cosine (30 degrees,
// Blender's auto-smooth angle, the common line between smooth and hard shading), the seam is flat shading's,
// not a crease, and holds no planes. A flat-shaded mesh has one along every edge, whose planes pinned every
// vertex: a torus with a normal per face, decimated to 20 %, came out 22 times as far from the original as
// the same torus without normals.
constexpr double kSoftNormalSeamCos = 0.8660254037844386;
constexpr std::size_t kMaxVirtualPairsPerVertex = 8;
constexpr std::size_t kMaxVirtualScanPerVertex = 512;
constexpr int kMaxVirtualRings = 8;
// The weight of a crack's border planes (a border that virtual pairs will close, see cracks_paired) relative
// to a border's. At full weight they stay after the crack closes, and the planes through the edges of a
// curved surface all pass near its centre of curvature, where they pulled the joined vertices: a triangle
// soup with its corners 1e-6 apart (every edge a border), joined at --pair-distance 1e-5 and decimated to
// 30 %, sank 0.25 into a unit sphere (its welded copy: 0.015). Without them, a soup's triangles vanish
// whole at no cost before their corners join. At 1e-3 they still keep each side until the pairs join it
// (nearly free), and leave the joined surface 0.017 off.
constexpr double kCrackWeight = 1e-3;

struct alignas(64) Vertex {
  float p[3];
  std::uint32_t flags : 8;
  std::uint32_t retry_asks : 24;  // retries of its blocked edges asked since the last one done (retry_due)
  Index seg_start, seg_count;     // this vertex's own segment of face ids in `vf`
  Index seg_next;                 // circular list of the segments the head vertex owns
  Index live_faces;               // 0: removed (or never used)
  std::uint32_t stamp, mark;      // scratch for neighbourhood maps
  Index seg_cap;                  // room in this vertex's own segment (its input valence)
  // The weight of q's surface planes alone (see QuadricMesh::areas), in units of Decimator::area_unit:
  // costs are distances over it, so the border planes' weight (boundary_weight) makes a border firmer
  // without loosening max_error along it.
  float area;
  Quadric q;  // relative to the local origin
};
static_assert(sizeof(Vertex) == 128);
}  // namespace

// build() writes every member of every vertex record (the face-list fields in build_face_lists).
template <>
inline constexpr bool filled_after_resize<Vertex> = true;

namespace {

struct Face {
  Index v[3];           // v[0] == kNone: dead
  Index e[3];           // e[i]: the edge from corner i to corner i+1
  std::int16_t ref[2];  // the input face's normal, octahedral-encoded; ref[0] == kNoNormal: degenerate
  float floor2;         // the squared quality no collapse may take it below (see kDegenerateQuality)
};

constexpr std::int16_t kNoNormal = -32768;

// Octahedral encoding of a direction in 4 bytes: enough to tell which side of a plane another normal is on.
inline void encode_normal(const Vec3d& n, std::int16_t out[2]) {
  const double l1 = std::abs(n.x()) + std::abs(n.y()) + std::abs(n.z());
  if (!(l1 > 0)) {
    out[0] = out[1] = kNoNormal;
    return;
  }
  double x = n.x() / l1, y = n.y() / l1;
  if (n.z() < 0) {
    const double fx = (1 - std::abs(y)) * (x < 0 ? -1 : 1), fy = (1 - std::abs(x)) * (y < 0 ? -1 : 1);
    x = fx;
    y = fy;
  }
  // Rounds half away from zero, as lround does, without its library call.
  out[0] = static_cast<std::int16_t>(x * 32767 + (x < 0 ? -0.5 : 0.5));
  out[1] = static_cast<std::int16_t>(y * 32767 + (y < 0 ? -0.5 : 0.5));
}

// The decoded direction is scaled by 32767 (no division): its only use is in tests that do not depend on
// its length.
inline Vec3d decode_normal(const std::int16_t in[2]) {
  double x = in[0], y = in[1];
  const double z = 32767 - std::abs(x) - std::abs(y);
  if (z < 0) {
    const double fx = (32767 - std::abs(y)) * (x < 0 ? -1 : 1), fy = (32767 - std::abs(x)) * (y < 0 ? -1 : 1);
    x = fx;
    y = fy;
  }
  return {x, y, z};
}

struct Edge {
  Index v[2];
  std::uint32_t slot;  // heap position, or a state
};

inline bool has_corner(const Face& f, Index v) {
  return f.v[0] == v || f.v[1] == v || f.v[2] == v;
}
inline int corner_of(const Face& f, Index v) {
  return f.v[0] == v ? 0 : f.v[1] == v ? 1 : 2;
}

// Calls body(begin, end) on the fixed chunks [k * grain, (k + 1) * grain) in parallel. Chunks are aligned to
// multiples of grain (tbb's own range splitting halves ranges and is not), so callers may index per-chunk
// results by begin / grain.
template <class Body>
void parallel_chunks(std::size_t n, std::size_t grain, const Body& body) {
  const std::size_t chunks = (n + grain - 1) / grain;
  tbb::parallel_for(std::size_t{0}, chunks,
                    [&](std::size_t k) { body(k * grain, std::min(n, (k + 1) * grain)); });
}

// Numbers the i in [0, n) for which keep(i) holds, in order: out[i] is i's rank among them, or kNone. Returns
// how many there are. Chunks count, then number from their prefix, so the numbering is the serial one.
template <class Keep>
Index number_kept(std::size_t n, Index* out, const Keep& keep) {
  constexpr std::size_t grain = 16384;
  const std::size_t chunks = (n + grain - 1) / grain;
  std::vector<Index> first(chunks + 1, 0);
  parallel_chunks(n, grain, [&](std::size_t begin, std::size_t end) {
    Index kept = 0;
    for (std::size_t i = begin; i < end; ++i) {
      const bool k = keep(i);
      out[i] = k;
      kept += k;
    }
    first[begin / grain + 1] = kept;
  });
  for (std::size_t c = 0; c < chunks; ++c) first[c + 1] += first[c];
  parallel_chunks(n, grain, [&](std::size_t begin, std::size_t end) {
    Index next = first[begin / grain];
    for (std::size_t i = begin; i < end; ++i) out[i] = out[i] ? next++ : kNone;
  });
  return first[chunks];
}

// For each vertex, the lowest index of a vertex at the same position (itself when there is none). Hashing
// rather than sorting: welding is on by default, so every decimation pays for it, and a sort of the positions
// took a fifth of a 1 M-triangle decimation. The vertices are first spread over buckets by hash, in index
// order (chunk counts, then a prefix), and each bucket then fills a small open-addressing table of its own in
// index order, so the first vertex to claim a position is its lowest one, whatever the thread count.
std::vector<Index> equal_position_targets(const std::vector<Vec3f>& positions) {
  const std::size_t n = positions.size();
  std::vector<Index> target(n);
  const int bucket_bits = std::clamp(static_cast<int>(std::bit_width(n / 4096)), 0, 12);
  const std::size_t buckets = std::size_t{1} << bucket_bits;
  auto bucket_of = [bucket_bits](std::uint64_t h) { return bucket_bits == 0 ? 0 : h >> (64 - bucket_bits); };
  constexpr std::size_t grain = 65536;
  const std::size_t chunks = (n + grain - 1) / grain;
  std::vector<std::uint32_t> count(chunks * buckets, 0);
  parallel_chunks(n, grain, [&](std::size_t begin, std::size_t end) {
    std::uint32_t* c = &count[begin / grain * buckets];
    for (std::size_t v = begin; v < end; ++v) ++c[bucket_of(PositionKey(positions[v]).hash())];
  });
  // Bucket-major offsets: bucket b's vertices, chunk by chunk, in index order.
  std::vector<std::size_t> bucket_begin(buckets + 1, 0);
  std::vector<std::size_t> at(chunks * buckets);
  std::size_t sum = 0;
  for (std::size_t b = 0; b < buckets; ++b) {
    bucket_begin[b] = sum;
    for (std::size_t k = 0; k < chunks; ++k) {
      at[k * buckets + b] = sum;
      sum += count[k * buckets + b];
    }
  }
  bucket_begin[buckets] = sum;
  std::vector<Index> by_bucket(n);
  parallel_chunks(n, grain, [&](std::size_t begin, std::size_t end) {
    std::size_t* next = &at[begin / grain * buckets];
    for (std::size_t v = begin; v < end; ++v)
      by_bucket[next[bucket_of(PositionKey(positions[v]).hash())]++] = static_cast<Index>(v);
  });
  tbb::parallel_for(std::size_t{0}, buckets, [&](std::size_t b) {
    const std::size_t first = bucket_begin[b], size = bucket_begin[b + 1] - first;
    if (size == 0) return;
    const std::size_t mask = std::bit_ceil(2 * size) - 1;
    std::vector<Index> table(mask + 1, kNone);
    for (std::size_t i = first; i < first + size; ++i) {
      const Index v = by_bucket[i];
      const PositionKey key(positions[v]);
      for (std::size_t slot = key.hash() & mask;; slot = (slot + 1) & mask) {
        const Index u = table[slot];
        if (u == kNone) {
          table[slot] = target[v] = v;
          break;
        }
        if (PositionKey(positions[u]) == key) {
          target[v] = u;
          break;
        }
      }
    }
  });
  return target;
}

// 1 at each face that repeats an earlier one: the same three corners in the same turn (any rotation), as a
// part exported twice or a soup written with repeats leaves after welding. A repeat's copies stack on every
// edge they share, which the collapses treat as a non-manifold sheet: a 10 x 10 grid with 50 of its faces
// repeated went to one triangle written twice, half the square gone. Faces are grouped by their lowest
// corner (a counting sort, 4 bytes a face and a vertex, freed before the decimator's own arrays grow), and
// each group, two faces on average, compared within itself. Copies in the opposite turn stay: they are the
// two sides of a sheet. Empty when there is no repeat. Faces with a repeated corner are grouped too (the
// caller drops them as degenerate first, so a repeat among them counts as that).
std::vector<std::uint8_t> repeated_faces(const std::vector<Triangle>& triangles, std::size_t vertices) {
  const std::size_t nf = triangles.size();
  auto lowest = [](const Triangle& t) { return std::min({t[0], t[1], t[2]}); };
  // The two corners after the lowest one, in the face's turn.
  auto rest = [](const Triangle& t, Index low) {
    return t[0] == low ? std::pair(t[1], t[2]) : t[1] == low ? std::pair(t[2], t[0]) : std::pair(t[0], t[1]);
  };
  // Counting sort of the faces by lowest corner: group v is by_low[first[v] .. first[v + 1]).
  std::vector<Index> first(vertices + 2, 0);
  for (const Triangle& t : triangles) ++first[lowest(t) + 2];
  for (std::size_t v = 0; v < vertices; ++v) first[v + 2] += first[v + 1];
  std::vector<Index> by_low(nf);
  for (std::size_t f = 0; f < nf; ++f) by_low[first[lowest(triangles[f]) + 1]++] = static_cast<Index>(f);
  std::vector<std::uint8_t> repeat;
  auto mark = [&](Index f) {
    if (repeat.empty()) repeat.assign(nf, 0);
    repeat[f] = 1;
  };
  std::vector<std::pair<std::pair<Index, Index>, Index>> large;
  for (std::size_t v = 0; v < vertices; ++v) {
    const Index begin = first[v], end = first[v + 1];
    const Index low = static_cast<Index>(v);
    if (end - begin <= 8) {
      // The faces of a group are in increasing index order, so the earliest of equal ones is kept.
      for (Index i = begin + 1; i < end; ++i) {
        const auto corners = rest(triangles[by_low[i]], low);
        for (Index k = begin; k < i; ++k) {
          if (rest(triangles[by_low[k]], low) == corners) {
            mark(by_low[i]);
            break;
          }
        }
      }
      continue;
    }
    large.clear();
    for (Index i = begin; i < end; ++i) large.push_back({rest(triangles[by_low[i]], low), by_low[i]});
    std::sort(large.begin(), large.end());
    for (std::size_t i = 1; i < large.size(); ++i) {
      if (large[i].first == large[i - 1].first) mark(large[i].second);
    }
  }
  return repeat;
}

// Sorts a short list in place (neighbour lists have a handful of entries).
inline void small_sort(Index* first, Index* last) {
  if (last - first > 32) {
    std::sort(first, last);
    return;
  }
  for (Index* i = first + 1; i < last; ++i) {
    const Index x = *i;
    Index* j = i;
    for (; j > first && *(j - 1) > x; --j) *j = *(j - 1);
    *j = x;
  }
}

struct Neighbour {
  Index x;      // the other endpoint
  Index edge;   // the surviving edge between the kept vertex and x
  Index cnt_k;  // faces of the kept vertex containing x, before the collapse
  Index cnt_r;  // faces of the removed vertex containing x, before the collapse
  Index cnt_d;  // dying faces containing x
};

// The mesh records, shared by the global loop and the region loops of the first phase.
struct Storage {
  BigVector<Vertex> verts;
  std::vector<Vec3f> normals;
  std::vector<Color> colors;
  std::vector<Vec2f> uvs;
  BigVector<Face> faces;
  BigVector<Index> vf;  // CSR face lists, one segment per input vertex
  BigVector<Edge> edges;
  std::vector<std::vector<Index>> virtual_pairs;  // per vertex; only with pair_distance
  // When the input has attributes (see seams.h): the input before welding, and the input face each face
  // record descends from (moved along by compact), which the output's attributes are interpolated from.
  bool keeps_source = false;
  bool seams = false;  // welding joined an attribute seam, whose sides the output splits again
  decimate_detail::SeamSource seam_source;
  std::vector<Index> face_origin;
  std::vector<std::uint8_t> welded_at;  // 1 at a vertex others were welded into (until the edges are built)
};

// Region ids of the first phase (see run_pass): a vertex's region, with kOutside set when a vertex it
// shares a face with lies in another region.
constexpr std::uint32_t kOutside = 0x80000000u;

struct Decimator {
  const DecimateOptions& opt;
  DecimateStats stats;

  Vec3d origin = Vec3d::Zero();
  double key_scale = 1;  // keys are length^3 (see key_of): divided by diagonal^3 they fit float's range
  // Vertex::area is in units of diagonal^2, for the same reason: as a plain float, a mesh 1e20 across
  // overflowed it (every error distance 0, --max-error ignored) and one 1e-25 across underflowed it.
  double area_unit = 1;
  Vec3d box_low = Vec3d::Zero();
  double box_extent = 0;  // the bounding box's longest side

  Storage& storage;
  BigVector<Vertex>& verts;
  std::vector<Vec3f>& normals;
  std::vector<Color>& colors;
  std::vector<Vec2f>& uvs;
  BigVector<Face>& faces;
  BigVector<Index>& vf;
  BigVector<Edge>& edges;
  std::vector<std::vector<Index>>& virtual_pairs;
  EdgeHeap heap{nullptr, 3};

  // A region loop of the first phase: only pairs of vertices interior to `region` are candidates.
  const std::uint32_t* region_of = nullptr;
  std::uint32_t region = 0;
  std::vector<std::pair<Index, Index>> boundary_list;  // (edge, its one face), from build_edges
  std::vector<std::pair<Index, Index>> fold_list;      // (edge, each of its two faces), from build_edges

  // Scratch, reused across collapses.
  std::uint32_t stamp_now = 0;
  std::vector<Index> fa, fb, dying, scratch_faces, scratch_ids;
  std::vector<Index> opposites;  // of the dying faces, when there are many (see orphans_of_dying)
  BigVector<Neighbour> nbrs;     // grows without initialization (see collapse)
  Index staged_edge = kNone;     // the pair whose neighbourhood the last collapse prefetched (see try_top)
  std::vector<Index> deferred, blocked;
  bool fallbacks = false;  // blocked pairs may take fallback placements (see run)

  std::uint64_t faces_alive = 0, verts_alive = 0, boundary_edges = 0;
  bool kept_last_faces = false;  // a collapse was put off as it would have removed every face left
  // The fewest faces below the face target that a pair put off this round would have left (see run).
  static constexpr std::uint64_t kNoShort = ~std::uint64_t{0};
  std::uint64_t least_short = kNoShort;
  float applied_key = 0;  // the largest key (without shape penalty) of the collapses done
  std::uint64_t target_f = 0, target_v = 0;
  std::uint64_t compact_below = 0;  // renumber when this few vertices are left (see compact)

  Decimator(const DecimateOptions& options, Storage& s)
      : opt(options),
        storage(s),
        verts(s.verts),
        normals(s.normals),
        colors(s.colors),
        uvs(s.uvs),
        faces(s.faces),
        vf(s.vf),
        edges(s.edges),
        virtual_pairs(s.virtual_pairs) {}

  // A position relative to the local origin, in double.
  Vec3d rel(const float* p) const {
    return Vec3d(double(p[0]) - origin.x(), double(p[1]) - origin.y(), double(p[2]) - origin.z());
  }
  Vec3d rel(Index v) const { return rel(verts[v].p); }
  bool face_alive(Index f) const { return faces[f].v[0] != kNone; }
  bool in_heap(Index e) const { return edges[e].slot < first_state; }
  bool edge_dead(Index e) const { return edges[e].slot == kDead; }
  bool locked(Index v) const { return verts[v].flags & kLocked; }
  Vec3d face_normal(Index f) const {
    const Face& face = faces[f];
    const Vec3d p0 = rel(face.v[0]);
    return (rel(face.v[1]) - p0).cross(rel(face.v[2]) - p0);
  }

  std::uint32_t next_stamp() {
    if (++stamp_now == 0) {
      if (region_of == nullptr) {
        for (Vertex& v : verts) v.stamp = 0;
      } else {
        // Other regions' loops are running: only this region's vertices are this loop's to write.
        for (std::size_t v = 0; v < verts.size(); ++v) {
          if ((region_of[v] & ~kOutside) == region) verts[v].stamp = 0;
        }
      }
      stamp_now = 1;
    }
    return stamp_now;
  }

  // ---------------------------------------------------------------- setup

  void validate_and_clean(QuadricMesh& in) {
    IndexedMesh& m = in.mesh;
    const std::size_t n = m.positions.size();
    if (n >= first_state) throw Error("decimate: too many vertices (" + std::to_string(n) + ")");
    check_indices(m, "decimate: ");
    if (!in.quadrics.empty() && in.quadrics.size() != n) {
      throw Error("decimate: the quadric array has " + std::to_string(in.quadrics.size()) + " entries for " +
                  std::to_string(n) + " vertices");
    }
    if (!in.areas.empty() && in.areas.size() != in.quadrics.size()) {
      throw Error("decimate: the area array has " + std::to_string(in.areas.size()) + " entries for " +
                  std::to_string(in.quadrics.size()) + " quadrics");
    }
    for (std::size_t v = 0; v < in.areas.size(); ++v) {
      if (!(in.areas[v] >= 0 && in.areas[v] < std::numeric_limits<double>::infinity()))
        throw Error("decimate: vertex " + std::to_string(v) +
                    " has an area that is not a finite number >= 0");
    }
    // A NaN there made every cost it touched NaN, and the error bound and the reported error 0.
    for (std::size_t v = 0; v < in.quadrics.size(); ++v) {
      const Quadric& q = in.quadrics[v];
      for (double x : {q.a00, q.a01, q.a02, q.a11, q.a12, q.a22, q.b0, q.b1, q.b2, q.c}) {
        if (!std::isfinite(x))
          throw Error("decimate: vertex " + std::to_string(v) + " has a non-finite quadric");
      }
    }
    for (std::size_t v = 0; v < n; ++v) {
      if (!m.positions[v].allFinite())
        throw Error("decimate: vertex " + std::to_string(v) + " has a non-finite coordinate");
    }
    // The attribute penalty reads them: a NaN there made every such collapse cost NaN.
    for (std::size_t v = 0; v < m.normals.size(); ++v) {
      if (!m.normals[v].allFinite())
        throw Error("decimate: vertex " + std::to_string(v) + " has a non-finite normal");
    }
    for (std::size_t v = 0; v < m.uvs.size(); ++v) {
      if (!m.uvs[v].allFinite())
        throw Error("decimate: vertex " + std::to_string(v) + " has a non-finite texture coordinate");
    }
    if (opt.weld) weld(in);
    // Without a seam too: interpolated along each collapsed edge, the attributes of a vertex that ended where
    // one its collapse removed had been (a flat grid's corner, taken with its last face by a collapse beside
    // it) were its neighbours' blend, 0.2 off in uv on a linear field; from the input's surface at the
    // vertex's position they are that corner's. The faces kept below are that surface (build() moves them to
    // the source once it has read them).
    const bool cleaned_source = !storage.keeps_source && (m.has_normals() || m.has_colors() || m.has_uvs());
    const std::vector<std::uint8_t> repeat = repeated_faces(m.triangles, n);
    std::size_t kept = 0;
    for (std::size_t f = 0; f < m.triangles.size(); ++f) {
      const Triangle t = m.triangles[f];
      if (has_repeated_corner(t)) {
        ++stats.dropped_degenerate_faces;
        continue;
      }
      if (!repeat.empty() && repeat[f]) {
        ++stats.dropped_repeated_faces;
        continue;
      }
      if (storage.keeps_source) storage.face_origin.push_back(static_cast<Index>(f));
      m.triangles[kept++] = t;
    }
    m.triangles.resize(kept);
    if (kept >= first_state / 3) throw Error("decimate: too many faces (" + std::to_string(kept) + ")");
    if (cleaned_source) {
      storage.keeps_source = true;
      storage.face_origin.resize(kept);
      std::iota(storage.face_origin.begin(), storage.face_origin.end(), Index{0});
    }
  }

  // Merges vertices at equal positions into the lowest index among them.
  void weld(QuadricMesh& in) {
    IndexedMesh& m = in.mesh;
    const std::size_t n = m.positions.size();
    const std::vector<Index> target = equal_position_targets(m.positions);
    for (std::size_t v = 0; v < n; ++v) stats.welded_vertices += target[v] != v;
    if (stats.welded_vertices == 0) return;
    // A seam: copies of a position that differ in attributes (a vertex that is not its position's lowest
    // index and not a copy of an earlier one).
    const std::vector<Index> side = decimate_detail::same_attribute_targets(m, target);
    for (std::size_t v = 0; v < n && !storage.seams; ++v) storage.seams = target[v] != v && side[v] == v;
    if (storage.seams) {
      // The positions and attributes join the source in build(), once the decimator has what it needs.
      storage.keeps_source = true;
      storage.seam_source.triangles = m.triangles;
      for (Triangle& t : storage.seam_source.triangles) {
        for (Index& v : t) v = side[v];
      }
      storage.face_origin.reserve(m.triangles.size());
      storage.welded_at.assign(n, 0);
      for (std::size_t v = 0; v < n; ++v) storage.welded_at[target[v]] |= target[v] != v;
    }
    if (!in.quadrics.empty()) {
      for (std::size_t v = 0; v < n; ++v) {
        if (target[v] != v) in.quadrics[target[v]] += in.quadrics[v];
      }
    }
    for (std::size_t v = 0; v < in.areas.size(); ++v) {
      if (target[v] != v) in.areas[target[v]] += in.areas[v];
    }
    for (Triangle& t : m.triangles) {
      for (Index& v : t) v = target[v];
    }
  }

  // The setup's steps, reported as the "decimate: setup" phase: on a 4 M-face scan they and the first round
  // of regions took half the run before the "decimate" phase said anything.
  static constexpr std::uint64_t kSetupSteps = 5;

  void build(QuadricMesh& in) {
    report(opt.progress, "decimate: setup", 0, kSetupSteps);
    validate_and_clean(in);
    report(opt.progress, "decimate: setup", 1, kSetupSteps);
    IndexedMesh& m = in.mesh;
    const std::size_t nv = m.positions.size();
    const std::size_t nf = m.triangles.size();
    stats.input_faces = nf;
    faces_alive = nf;

    // Vertices: positions, then face counts; faces: corners. The input arrays go as soon as they are copied,
    // except the positions: the loops over the faces here and in face_quadrics read them, 12 bytes a vertex,
    // rather than the 128-byte records.
    // Chunks of a few thousand records: on a mesh of 35 k vertices and 70 k faces (bunny) larger ones left
    // one core with most of the work and of the first touches of the pages.
    verts.resize(nv);
    parallel_chunks(nv, 4096, [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v) {
        Vertex& x = verts[v];
        x.p[0] = m.positions[v].x();
        x.p[1] = m.positions[v].y();
        x.p[2] = m.positions[v].z();
        x.flags = 0;
        x.seg_next = static_cast<Index>(v);
        x.stamp = 0;
        x.mark = 0;
        x.retry_asks = 0;
        x.area = 0;
        x.q = Quadric{};
      }
    });
    if (storage.keeps_source) {
      // The output's attributes come from the input's (see seams.h): the decimator only needs its own to
      // weigh them (attribute_weight).
      decimate_detail::SeamSource& source = storage.seam_source;
      if (opt.attribute_weight > 0) {
        source.normals = m.normals;
        source.colors = m.colors;
        source.uvs = m.uvs;
      } else {
        source.normals = std::move(m.normals);
        source.colors = std::move(m.colors);
        source.uvs = std::move(m.uvs);
      }
    }
    normals = std::move(m.normals);
    colors = std::move(m.colors);
    uvs = std::move(m.uvs);
    faces.resize(nf);
    parallel_chunks(nf, 8192, [&](std::size_t begin, std::size_t end) {
      for (std::size_t f = begin; f < end; ++f) {
        const Triangle& t = m.triangles[f];
        Face& face = faces[f];
        auto at = [&](Index v) { return m.positions[v].cast<double>(); };
        const Vec3d p0 = at(t[0]), p1 = at(t[1]), p2 = at(t[2]);
        const Vec3d n = (p1 - p0).cross(p2 - p0);
        const double sum = (p1 - p0).squaredNorm() + (p2 - p0).squaredNorm() + (p2 - p1).squaredNorm();
        // Squared, q^2 = 12 |n|^2 / sum^2, as shapes_ok compares it.
        const double q2 = sum > 0 ? 12 * n.squaredNorm() / (sum * sum) : 0;
        const double floor2 =
            std::min(kDegenerateQuality * kDegenerateQuality, kDegenerateSlack * kDegenerateSlack * q2);
        face = {{t[0], t[1], t[2]}, {kNone, kNone, kNone}, {0, 0}, float(floor2)};
        encode_normal(n, face.ref);
      }
    });
    if (storage.keeps_source && !storage.seams) {
      storage.seam_source.triangles = std::move(m.triangles);  // the cleaned faces (see validate_and_clean)
    } else {
      std::vector<Triangle>().swap(m.triangles);
    }

    Box3 box;
    {
      std::vector<Index> scratch(nv);
      build_face_lists(scratch, nv, [&](Vertex& x) {
        x.live_faces = x.seg_count;
        if (x.seg_count > 0) {
          box.add(Vec3f(x.p[0], x.p[1], x.p[2]));
          ++verts_alive;
        }
        if (x.seg_count == 1) ++stats.single_face_vertices;
      });
    }
    stats.input_vertices = verts_alive;
    report(opt.progress, "decimate: setup", 2, kSetupSteps);

    origin = box.center();
    box_low = box.lo;
    box_extent = box.extent().maxCoeff();
    const double diagonal = box.diagonal();
    key_scale = diagonal > 0 ? 1.0 / (diagonal * diagonal * diagonal) : 1.0;
    area_unit = diagonal > 0 ? diagonal * diagonal : 1.0;

    build_edges();
    // The pairs first: the border planes leave out the cracks they will close.
    if (opt.pair_distance > 0 && !opt.preserve_topology) build_virtual_pairs();
    report(opt.progress, "decimate: setup", 3, kSetupSteps);
    build_quadrics(in, m.positions);
    report(opt.progress, "decimate: setup", 4, kSetupSteps);
    if (storage.keeps_source) {
      storage.seam_source.positions = std::move(m.positions);
      std::vector<std::uint8_t>().swap(storage.welded_at);
    }
    std::vector<Vec3f>().swap(m.positions);
  }

  // Of an edge's sides, the face of the one that has area when all the others have none; else kNone.
  template <class Side>
  Index only_face_with_area(const Side* sides, std::size_t n) const {
    Index sheet = kNone;
    for (std::size_t k = 0; k < n; ++k) {
      if (faces[sides[k].f].ref[0] == kNoNormal) continue;
      if (sheet != kNone) return kNone;
      sheet = sides[k].f;
    }
    return sheet;
  }

  // One side of a face seen from its lower endpoint v: the other endpoint w > v, the face, and which of the
  // face's edge slots it is.
  struct UpperSide {
    Index w, f;
    std::uint32_t slot;
  };

  // Whether the faces on edge (v, w) met there in the input only through the weld, as the two sides of a
  // seam: some face's input vertices at the edge's ends differ from the first face's, other than by a
  // normal within kSoftNormalSeamCos.
  bool on_seam(Index v, const UpperSide* sides, std::size_t n) const {
    const decimate_detail::SeamSource& source = storage.seam_source;
    // The side's input vertices at v and at w.
    auto ends = [&](const UpperSide& side) {
      const Triangle& t = source.triangles[storage.face_origin[side.f]];
      const int next = side.slot == 2 ? 0 : side.slot + 1;
      return faces[side.f].v[side.slot] == v ? std::pair(t[side.slot], t[next])
                                             : std::pair(t[next], t[side.slot]);
    };
    auto apart = [&](Index a, Index b) {
      if (a == b) return false;
      if (!source.uvs.empty() && source.uvs[a] != source.uvs[b]) return true;
      if (!source.colors.empty() && source.colors[a] != source.colors[b]) return true;
      if (source.normals.empty()) return true;
      // (A zero normal has no direction to be near: either one makes a seam.)
      const Vec3d na = source.normals[a].cast<double>(), nb = source.normals[b].cast<double>();
      const double la = na.norm(), lb = nb.norm();
      return !(la > 0 && lb > 0 && na.dot(nb) >= kSoftNormalSeamCos * la * lb);
    };
    const auto [first_v, first_w] = ends(sides[0]);
    for (std::size_t k = 1; k < n; ++k) {
      const auto [at_v, at_w] = ends(sides[k]);
      if (apart(first_v, at_v) || apart(first_w, at_w)) return true;
    }
    return false;
  }

  // Marks, in a face's edge slot between the two passes of build_edges, the one side that writes the edge's
  // record.
  static constexpr Index kFirstSide = 0x80000000u;

  // Each undirected edge gets an id from its lower endpoint: vertex v numbers the distinct neighbours w > v
  // it sees in its faces, in increasing w. One sort per vertex: the first pass numbers each chunk's edges
  // from 0 in the faces' edge slots, and once a prefix sum has given each chunk its first id, a pass over
  // the faces adds it and writes the edge records. (Counting the edges in a pass of its own, to number them
  // globally at once, sorted every vertex's neighbours twice: about a quarter of the setup's instructions.)
  void build_edges() {
    const std::size_t nv = verts.size();
    constexpr std::size_t grain = 4096;
    std::vector<Index> first_edge(nv + 1, 0);

    // Boundary edges (one face) and folds (two faces turned back on each other) found per chunk, then ordered
    // by id so constraint planes add up identically.
    std::vector<std::vector<std::pair<Index, Index>>> chunk_boundaries((nv + grain - 1) / grain);
    std::vector<std::vector<std::pair<Index, Index>>> chunk_folds((nv + grain - 1) / grain);
    parallel_chunks(nv, grain, [&](std::size_t begin, std::size_t end) {
      std::vector<UpperSide> sides;
      auto& found = chunk_boundaries[begin / grain];
      auto& folds = chunk_folds[begin / grain];
      Index id = 0;  // within the chunk
      for (std::size_t vi = begin; vi < end; ++vi) {
        const Index v = static_cast<Index>(vi);
        const Vertex& x = verts[v];
        if (sides.size() < 2 * std::size_t{x.seg_count}) sides.resize(2 * std::size_t{x.seg_count});
        std::size_t n = 0;
        for (Index i = x.seg_start; i < x.seg_start + x.seg_count; ++i) {
          const Index f = vf[i];
          const Face& face = faces[f];
          const int c = corner_of(face, v);
          const Index next = face.v[(c + 1) % 3], prev = face.v[(c + 2) % 3];
          if (next > v) sides[n++] = {next, f, std::uint32_t(c)};
          if (prev > v) sides[n++] = {prev, f, std::uint32_t((c + 2) % 3)};
        }
        // Sorted by w, stably: the face list is in face order (no collapse has run yet), so the sides of one
        // edge stay in face order. Insertion sort for the handful of sides of nearly every vertex; a fan's
        // centre or a non-manifold spine of thousands of faces takes the library's, as insertion sort was
        // quadratic there (an OBJ polygon of 900,000 corners took minutes).
        if (n > 32) {
          std::stable_sort(sides.begin(), sides.begin() + n,
                           [](const UpperSide& l, const UpperSide& r) { return l.w < r.w; });
        } else {
          for (std::size_t i = 1; i < n; ++i) {
            const UpperSide moving = sides[i];
            std::size_t j = i;
            for (; j > 0 && moving.w < sides[j - 1].w; --j) sides[j] = sides[j - 1];
            sides[j] = moving;
          }
        }
        const Index first = id;
        for (std::size_t i = 0; i < n; ++id) {
          std::size_t j = i + 1;
          while (j < n && sides[j].w == sides[i].w) ++j;
          faces[sides[i].f].e[sides[i].slot] = id | kFirstSide;
          for (std::size_t k = i + 1; k < j; ++k) faces[sides[k].f].e[sides[k].slot] = id;
          if (j - i == 1) {
            found.emplace_back(id, sides[i].f);
          } else if (j - i == 2 && is_fold(sides[i].f, sides[i + 1].f,
                                           faces[sides[i].f].v[sides[i].slot] ==
                                               faces[sides[i + 1].f].v[sides[i + 1].slot])) {
            folds.emplace_back(id, sides[i].f);
            folds.emplace_back(id, sides[i + 1].f);
          } else if (storage.seams && (storage.welded_at[v] || storage.welded_at[sides[i].w]) &&
                     on_seam(v, sides.data() + i, j - i)) {
            // Each side of a seam keeps the planes it had as a border, so the seam stays where it was: a
            // seam vertex moved off it would leave the faces of one side reaching across it, their corners
            // clamped to the side's edge (see seams.h).
            for (std::size_t k = i; k < j; ++k) folds.emplace_back(id, sides[k].f);
          } else if (const Index sheet = only_face_with_area(sides.data() + i, j - i); sheet != kNone) {
            // Faces of zero area along a border (collinear corners, as CAD exports leave) make it look
            // interior, and it then had no planes to hold it: a flat grid with them along one side went to
            // a single face at cost 0. It gets its one sheet's planes, as a fold does (and stays interior
            // for parity, which is topology).
            folds.emplace_back(id, sheet);
          }
          i = j;
        }
        first_edge[v + 1] = id - first;
      }
      if (id >= kFirstSide) throw Error("decimate: too many edges");
    });
    for (std::size_t v = 0; v < nv; ++v) {
      if (std::uint64_t{first_edge[v]} + first_edge[v + 1] >= first_state)
        throw Error("decimate: too many edges");
      first_edge[v + 1] += first_edge[v];
    }
    edges.resize(first_edge[nv]);
    heap = EdgeHeap(edges.empty() ? nullptr : &edges[0].slot, 3);

    // A slot's edge belongs to the chunk of its lower endpoint, whose first id is first_edge[chunk start].
    parallel_chunks(faces.size(), 8192, [&](std::size_t begin, std::size_t end) {
      for (std::size_t f = begin; f < end; ++f) {
        Face& face = faces[f];
        for (int i = 0; i < 3; ++i) {
          const Index v = face.v[i], w = face.v[i == 2 ? 0 : i + 1];
          const Index low = std::min(v, w);
          const Index local = face.e[i];
          const Index id = (local & ~kFirstSide) + first_edge[low / grain * grain];
          face.e[i] = id;
          if (local & kFirstSide) edges[id] = {{low, std::max(v, w)}, kIdleError};
        }
      }
    });
    for (std::size_t c = 0; c < chunk_boundaries.size(); ++c) {
      const Index base = first_edge[c * grain];
      for (const auto& [id, f] : chunk_boundaries[c]) boundary_list.emplace_back(id + base, f);
      for (const auto& [id, f] : chunk_folds[c]) fold_list.emplace_back(id + base, f);
    }
    boundary_edges = boundary_list.size();
  }

  // Two faces turned back on each other by more than 120 degrees, judged by their encoded input normals
  // (already computed, and the 1e-4 precision of the encoding does not matter for this threshold). Faces
  // that run along their edge the same way (`same_way`: the mesh's orientation flips there) are compared
  // with one turned over: a sphere with every other face reversed read as folded along every edge, and
  // their planes pinned it (16 % Hausdorff at 10 % of its faces, against 1.1 % consistently oriented).
  bool is_fold(Index f0, Index f1, bool same_way) const {
    const Face& a = faces[f0];
    const Face& b = faces[f1];
    if (a.ref[0] == kNoNormal || b.ref[0] == kNoNormal) return false;
    // Decoded, each component has the sign of its code (x and y; z: whether |x| + |y| is within 32767, see
    // decode_normal). Two normals in the same octant have no negative product, so no negative dot product:
    // most neighbouring faces, told apart without decoding. The signs of x and y compare as sign bits (an XOR
    // is negative where they differ), about half the instructions of building both octants' codes.
    const int xa = a.ref[0], ya = a.ref[1], xb = b.ref[0], yb = b.ref[1];
    const bool lower_a = std::abs(xa) + std::abs(ya) > 32767, lower_b = std::abs(xb) + std::abs(yb) > 32767;
    if (!same_way && ((xa ^ xb) | (ya ^ yb)) >= 0 && lower_a == lower_b) return false;
    const Vec3d n0 = decode_normal(a.ref), n1 = decode_normal(b.ref);
    const double dot = same_way ? -n0.dot(n1) : n0.dot(n1);
    return dot < 0 && dot * dot > kFoldCos * kFoldCos * n0.squaredNorm() * n1.squaredNorm();
  }

  // A face's plane quadric in factored form: weight w, unnormalized normal n and offset d, so that the
  // quadric is w (n n^T, n d, d^2). Half the bytes of the ten coefficients, and expanded the same way
  // wherever it is added, so every vertex sums bit-identical terms. w == 0: a degenerate face, which adds
  // nothing.
  struct FacePlane {
    double w, nx, ny, nz, d;
  };

  static void add_plane(Quadric& sum, const FacePlane& t) {
    const double wx = t.w * t.nx, wy = t.w * t.ny, wz = t.w * t.nz;
    add_to(sum, decimate_detail::RawQuadric{wx * t.nx, wx * t.ny, wx * t.nz, wy * t.ny, wy * t.nz, wz * t.nz,
                                            wx * t.d, wy * t.d, wz * t.d, t.w * t.d * t.d});
  }

  // Sums the area-weighted plane quadric of every face into its corners. Each face's plane is computed once
  // (a vertex-by-vertex pass computes it at each of the three corners), in parallel; the sums are then added
  // up in face order, so each vertex adds its faces in the order of its face list, whatever the thread count.
  // `positions`: the input's, which build() keeps until here: 12 bytes a vertex against the 128-byte records,
  // whose reads (one cache miss per corner on a mesh of 35 k vertices) were most of this step's time.
  void face_quadrics(const std::vector<Vec3f>& positions) {
    const std::size_t nf = faces.size();
    constexpr std::size_t grain = 1024;
    // Up to 2^19 faces, every face's plane at once (40 bytes each, freed before the edges' costs are
    // computed), each vertex summing its own faces' planes through its face list. Above, blocks of 16 Ki
    // faces (640 KiB of planes, within a core's L2), each task adding the block's planes to the vertices of
    // its own range: the whole array would add 40 bytes per input face to the peak memory.
    constexpr std::size_t kAllPlanesFaces = std::size_t{1} << 19;
    const bool all_at_once = nf <= kAllPlanesFaces;
    const std::size_t block = all_at_once ? std::max<std::size_t>(nf, 1) : 16384;
    BigVector<FacePlane> planes(std::min(nf, block));
    const bool area = opt.area_weighting;
    auto at = [&](Index v) { return rel(positions[v].data()); };
    // Two vertex ranges per core: every task scans the whole block, so more would only repeat that scan.
    const std::size_t nv = verts.size();
    const std::size_t ranges = 2 * std::max(1, tbb::this_task_arena::max_concurrency());
    const std::size_t owned = std::max<std::size_t>(1, (nv + ranges - 1) / ranges);
    for (std::size_t first = 0; first < nf; first += block) {
      const std::size_t count = std::min(block, nf - first);
      parallel_chunks(count, grain, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
          const Face& f = faces[first + i];
          const Vec3d p0 = at(f.v[0]);
          const Vec3d n = (at(f.v[1]) - p0).cross(at(f.v[2]) - p0);
          const double length2 = n.squaredNorm();
          // The plane of unit normal n / |n| weighted by the area |n| / 2 (or by 1), written on the
          // unnormalized n: one square root and one division per face.
          const double w = !(length2 > 0) ? 0.0 : area ? 0.5 / std::sqrt(length2) : 1.0 / length2;
          planes[i] = {w, n.x(), n.y(), n.z(), -n.dot(p0)};
        }
      });
      if (all_at_once) {
        parallel_chunks(nv, 4096, [&](std::size_t begin, std::size_t end) {
          for (std::size_t v = begin; v < end; ++v) {
            Vertex& x = verts[v];
            Quadric sum = x.q;
            for (Index i = x.seg_start; i < x.seg_start + x.seg_count; ++i) {
              const FacePlane& t = planes[vf[i]];
              if (t.w != 0) add_plane(sum, t);
            }
            x.q = sum;
          }
        });
        continue;
      }
      // Each task owns a range of vertices and adds only to those, so no two write the same record.
      parallel_chunks(nv, owned, [&](std::size_t low, std::size_t high) {
        for (std::size_t i = 0; i < count; ++i) {
          const FacePlane& t = planes[i];
          if (t.w == 0) continue;
          for (Index v : faces[first + i].v) {
            if (v >= low && v < high) add_plane(verts[v].q, t);
          }
        }
      });
    }
  }

  void build_quadrics(QuadricMesh& in, const std::vector<Vec3f>& positions) {
    const std::size_t nv = verts.size();
    std::vector<Quadric>& carried = in.quadrics;
    if (!carried.empty()) {
      // Re-express around the local origin o: Q(o + y) has the same A, gradient A o + b and constant Q(o).
      const Vec3d o = origin;
      parallel_chunks(nv, 16384, [&](std::size_t begin, std::size_t end) {
        for (std::size_t v = begin; v < end; ++v) {
          Quadric q = carried[v];
          const double c = decimate_detail::evaluate(q, o);
          q.b0 += q.a00 * o.x() + q.a01 * o.y() + q.a02 * o.z();
          q.b1 += q.a01 * o.x() + q.a11 * o.y() + q.a12 * o.z();
          q.b2 += q.a02 * o.x() + q.a12 * o.y() + q.a22 * o.z();
          q.c = c;
          verts[v].q = q;
          verts[v].area = static_cast<float>(surface_area(in, v) / area_unit);
        }
      });
      std::vector<Quadric>().swap(carried);
      std::vector<double>().swap(in.areas);
    } else {
      face_quadrics(positions);
      parallel_chunks(nv, 16384, [&](std::size_t begin, std::size_t end) {
        for (std::size_t v = begin; v < end; ++v)
          verts[v].area = static_cast<float>(verts[v].q.trace() / area_unit);
      });
    }
    std::sort(boundary_list.begin(), boundary_list.end());
    if (opt.lock_boundary) {
      for (const auto& [e, f] : boundary_list) {
        verts[edges[e].v[0]].flags |= kLocked;
        verts[edges[e].v[1]].flags |= kLocked;
      }
    }
    const std::vector<std::uint8_t> crack = cracks_paired();
    // Faces all of whose edges are border edges: they share no edge with another face. A side that pairs
    // will close (a crack) does not count: such a face joins its neighbours (separate_faces_note).
    if (boundary_list.size() >= 3) {
      std::vector<std::uint8_t> open_sides(faces.size(), 0);
      for (std::size_t i = 0; i < boundary_list.size(); ++i) {
        const bool closes = i < crack.size() && crack[i];
        stats.separate_faces += !closes && ++open_sides[boundary_list[i].second] == 3;
      }
    }
    // A fold is a border of each of its two sheets: plane quadrics cannot see a flap move along the surface
    // it lies on (its planes are nearly parallel), so both get the border's perpendicular planes.
    std::sort(fold_list.begin(), fold_list.end());
    boundary_list.insert(boundary_list.end(), fold_list.begin(), fold_list.end());
    std::vector<std::pair<Index, Index>>().swap(fold_list);
    for (std::size_t i = 0; i < boundary_list.size(); ++i) {
      const auto [e, f] = boundary_list[i];
      const Index v = edges[e].v[0], w = edges[e].v[1];
      if (!(opt.boundary_weight > 0)) continue;
      const Vec3d normal = face_normal(f);
      const Vec3d d = rel(w) - rel(v);
      Vec3d side = d.cross(normal);
      const double length = side.norm();
      if (!(length > 0)) continue;
      side /= length;
      const double weight = opt.boundary_weight * (opt.area_weighting ? d.squaredNorm() : 1.0) *
                            (i < crack.size() && crack[i] ? kCrackWeight : 1.0);
      const Quadric q = Quadric::plane(side, -side.dot(rel(v)), weight);
      add_to(verts[v].q, q);
      add_to(verts[w].q, q);
    }
    std::vector<std::pair<Index, Index>>().swap(boundary_list);
  }

  // Which borders of boundary_list (sorted, before the folds join it) are one side of a crack that the pairs
  // will close: another border runs between the edge's ends or their pair partners. Such a border's planes
  // weigh kCrackWeight of a border's (see there). Empty without pairs.
  std::vector<std::uint8_t> cracks_paired() const {
    if (virtual_pairs.empty()) return {};
    std::vector<std::pair<Index, Index>> borders(boundary_list.size());
    for (std::size_t i = 0; i < boundary_list.size(); ++i) {
      const Edge& e = edges[boundary_list[i].first];
      borders[i] = {std::min(e.v[0], e.v[1]), std::max(e.v[0], e.v[1])};
    }
    std::vector<std::pair<Index, Index>> sorted = borders;
    std::sort(sorted.begin(), sorted.end());
    std::vector<std::uint8_t> crack(borders.size(), 0);
    std::vector<Index> near_v, near_w;
    auto with_partners = [&](Index v, std::vector<Index>& out) {
      out.assign(1, v);
      for (Index e : virtual_pairs[v]) out.push_back(edges[e].v[0] == v ? edges[e].v[1] : edges[e].v[0]);
    };
    for (std::size_t i = 0; i < borders.size(); ++i) {
      const auto [v, w] = borders[i];
      with_partners(v, near_v);
      with_partners(w, near_w);
      for (Index a : near_v) {
        for (Index b : near_w) {
          const std::pair<Index, Index> other{std::min(a, b), std::max(a, b)};
          if (a != b && other != borders[i] && std::binary_search(sorted.begin(), sorted.end(), other)) {
            crack[i] = 1;
          }
        }
      }
    }
    return crack;
  }

  // Pairs closer than pair_distance sharing no edge: each vertex's nearest few (kMaxVirtualPairsPerVertex),
  // found in a uniform grid ring by ring outward, so the nearest come first whatever the distance. The
  // cells are pair_distance wide, or the mean edge length where that is smaller: cells of a large
  // pair_distance held the whole mesh, whose first vertices in index order filled the scan's budget, and a
  // soup's copies 1e-6 apart went unpaired at --pair-distance 1 while paired at 0.1.
  void build_virtual_pairs() {
    const std::size_t nv = verts.size();
    double edge_sum = 0;
    std::size_t edge_count = 0;
    for (const Edge& e : edges) {
      const double length = (rel(e.v[1]) - rel(e.v[0])).norm();
      if (length > 0) {
        edge_sum += length;
        ++edge_count;
      }
    }
    const double limit = opt.pair_distance;
    const double cell = edge_count > 0 ? std::min(limit, edge_sum / double(edge_count)) : limit;
    // Rings wider than the limit hold nothing to pair; past kMaxVirtualRings (a ring of that radius has
    // about 1,400 cells) a vertex with fewer than its share of pairs keeps what it found.
    const int rings = static_cast<int>(std::min<double>(kMaxVirtualRings, std::ceil(limit / cell)));
    struct Cell {
      std::int64_t x, y, z;
      Index v;
      bool operator<(const Cell& o) const {
        if (x != o.x) return x < o.x;
        if (y != o.y) return y < o.y;
        if (z != o.z) return z < o.z;
        return v < o.v;
      }
    };
    std::vector<Cell> cells;
    cells.reserve(verts_alive);
    auto cell_of = [&](double c) {
      return static_cast<std::int64_t>(std::floor(std::clamp(c / cell, -4e18, 4e18)));
    };
    for (std::size_t v = 0; v < nv; ++v) {
      if (verts[v].live_faces == 0) continue;
      const Vec3d p = rel(static_cast<Index>(v));
      cells.push_back({cell_of(p.x()), cell_of(p.y()), cell_of(p.z()), static_cast<Index>(v)});
    }
    tbb::parallel_sort(cells.begin(), cells.end());
    constexpr std::size_t grain = 4096;
    std::vector<std::vector<std::pair<Index, Index>>> chunk_pairs((cells.size() + grain - 1) / grain);
    const double limit2 = limit * limit;
    parallel_chunks(cells.size(), grain, [&](std::size_t begin, std::size_t end) {
      std::vector<std::pair<double, Index>> near;
      std::vector<Index> linked;
      auto& out = chunk_pairs[begin / grain];
      for (std::size_t i = begin; i < end; ++i) {
        const Index v = cells[i].v;
        const Vec3d p = rel(v);
        linked.clear();
        const Vertex& x = verts[v];
        for (Index k = x.seg_start; k < x.seg_start + x.seg_count; ++k) {
          for (Index w : faces[vf[k]].v) linked.push_back(w);
        }
        std::sort(linked.begin(), linked.end());
        near.clear();
        std::size_t scanned = 0;
        for (int r = 0; r <= rings && scanned < kMaxVirtualScanPerVertex; ++r) {
          for (int dx = -r; dx <= r; ++dx) {
            for (int dy = -r; dy <= r; ++dy) {
              for (int dz = -r; dz <= r; ++dz) {
                if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;
                const Cell key{cells[i].x + dx, cells[i].y + dy, cells[i].z + dz, 0};
                for (auto it = std::lower_bound(cells.begin(), cells.end(), key);
                     it != cells.end() && it->x == key.x && it->y == key.y && it->z == key.z &&
                     scanned < kMaxVirtualScanPerVertex;
                     ++it, ++scanned) {
                  if (it->v == v || std::binary_search(linked.begin(), linked.end(), it->v)) continue;
                  const double d2 = (rel(it->v) - p).squaredNorm();
                  if (d2 < limit2) near.emplace_back(d2, it->v);
                }
              }
            }
          }
          // Whatever lies beyond ring r is at least r cells away: done once the nearest few are nearer.
          if (near.size() >= kMaxVirtualPairsPerVertex) {
            std::nth_element(near.begin(), near.begin() + (kMaxVirtualPairsPerVertex - 1), near.end());
            const double bound = r * cell;
            if (near[kMaxVirtualPairsPerVertex - 1].first <= bound * bound) break;
          }
        }
        std::sort(near.begin(), near.end());
        if (near.size() > kMaxVirtualPairsPerVertex) near.resize(kMaxVirtualPairsPerVertex);
        for (const auto& [d2, w] : near) out.emplace_back(std::min(v, w), std::max(v, w));
      }
    });
    std::vector<std::pair<Index, Index>> pairs;
    for (auto& chunk : chunk_pairs) pairs.insert(pairs.end(), chunk.begin(), chunk.end());
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());  // found from both ends
    if (edges.size() + pairs.size() >= first_state) throw Error("decimate: too many candidate pairs");
    virtual_pairs.assign(nv, {});
    const std::size_t base = edges.size();
    edges.resize(base + pairs.size());
    heap = EdgeHeap(edges.empty() ? nullptr : &edges[0].slot, 3);
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      const Index e = static_cast<Index>(base + i);
      edges[e] = {{pairs[i].first, pairs[i].second}, kIdleError};
      virtual_pairs[pairs[i].first].push_back(e);
      virtual_pairs[pairs[i].second].push_back(e);
    }
  }

  void build_heap() {
    const std::size_t ne = edges.size();
    BigVector<HeapEntry> entries(ne);
    parallel_chunks(ne, 16384, [&](std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e) {
        float key = 0;
        const std::uint32_t state = key_of_edge(static_cast<Index>(e), &key);
        entries[e] = {key, state == 0 ? static_cast<std::uint32_t>(e) : state};
      }
    });
    std::size_t kept = 0;
    for (std::size_t e = 0; e < ne; ++e) {
      if (entries[e].edge == e) {
        entries[kept++] = entries[e];
      } else {
        edges[e].slot = entries[e].edge;
      }
    }
    entries.resize(kept);
    heap.assign(std::move(entries));
  }

  // ---------------------------------------------------------------- costs

  double attribute_difference2(Index a, Index b) const {
    double d = 0;
    if (!normals.empty()) d += (normals[a] - normals[b]).cast<double>().squaredNorm();
    if (!uvs.empty()) d += (uvs[a] - uvs[b]).cast<double>().squaredNorm();
    if (!colors.empty()) {
      for (int c = 0; c < 4; ++c) {
        const double x = (double(colors[a][c]) - double(colors[b][c])) / 255.0;
        d += x * x;
      }
    }
    return d;
  }

  // Undoes build_quadrics' shift to the local origin o: Q(x) = Q_rel(x - o).
  Quadric absolute(const Quadric& rel_q) const {
    Quadric q = rel_q;
    const Vec3d o = origin;
    q.b0 -= q.a00 * o.x() + q.a01 * o.y() + q.a02 * o.z();
    q.b1 -= q.a01 * o.x() + q.a11 * o.y() + q.a12 * o.z();
    q.b2 -= q.a02 * o.x() + q.a12 * o.y() + q.a22 * o.z();
    q.c = decimate_detail::evaluate(rel_q, -o);
    return q;
  }

  static double trace(const decimate_detail::RawQuadric& q) { return q.a00 + q.a11 + q.a22; }

  // The queue's order. `cost` is a quadric error (plus penalties), area * distance^2 over `weight` =
  // trace(A), the area the pair stands for. Garland-Heckbert order by the cost itself, which favours removing
  // small regions first; ordering by the mean, cost / weight, favours large ones. Between the two, cost /
  // sqrt(weight) gave the lowest Hausdorff and RMS distances on the shared scans (bunny, horse, igea at 10 %
  // and 1 %): against the plain cost, Hausdorff -26 % on bunny 10 %, -26 % on horse 1 %, -15 % on igea 10 %,
  // RMS within 2 %.
  float key_of(double cost, double weight) const {
    const double k = (weight > 0 ? cost / std::sqrt(weight) : cost) * key_scale;
    return k < 3.0e38 ? static_cast<float>(k) : 3.0e38f;
  }

  // The key alone, for re-costs (about 7 per collapse) and setup: inlined with the quadric and placement in
  // locals, the compiler keeps them in registers instead of storing them for a caller that never reads them.
  // Always inlined: in `recost` the call's prologue and epilogue were about 0.7 % of a bunny decimation's
  // instructions (callgrind, 450.6 M -> 447.4 M).
  [[gnu::always_inline]] std::uint32_t key_of_edge(Index e, float* key) const {
    decimate_detail::RawQuadric q;
    Placement p;
    return evaluate_inline(e, &q, &p, key, nullptr);
  }

  // The pair's summed quadric, placement, cost (quadric error plus attribute penalty) and key. Returns 0 for
  // a candidate, else the idle state it is in. Inlined in try_top too (its one other caller), with the sum
  // in a RawQuadric: about 0.1 % of a bunny decimation's instructions went to the call and to zeroing a
  // Quadric.
  [[gnu::always_inline]] std::uint32_t evaluate_inline(Index e, decimate_detail::RawQuadric* q, Placement* p,
                                                       float* key, double* cost_out) const {
    const Index a = edges[e].v[0], b = edges[e].v[1];
    const Vertex& va = verts[a];
    const Vertex& vb = verts[b];
    const bool la = va.flags & kLocked, lb = vb.flags & kLocked;
    if (la && lb) return kIdleLocked;
    add_pair(*q, va.q, vb.q);
    const Vec3d pa = rel(a), pb = rel(b);
    if (la) {
      *p = {pa, std::max(0.0, decimate_detail::evaluate(*q, pa))};
    } else if (lb) {
      *p = {pb, std::max(0.0, decimate_detail::evaluate(*q, pb))};
    } else {
      *p = place_pair(*q, pa, pb, kReach);
    }
    const double weight = trace(*q);
    if (opt.max_error < std::numeric_limits<double>::infinity() &&
        error_distance(p->error, (double(va.area) + vb.area) * area_unit) > opt.max_error)
      return kIdleError;
    double cost = p->error;
    if (opt.attribute_weight > 0) {
      cost += opt.attribute_weight * weight * (pb - pa).squaredNorm() * attribute_difference2(a, b);
    }
    *key = key_of(cost, weight);
    if (cost_out) *cost_out = cost;
    return 0;
  }

  // In a region loop of the first phase, a pair is a candidate only when both its ends are interior to the
  // region; the others stay pending until the global phase costs them.
  bool outside_region(Index e) const {
    return region_of != nullptr && (region_of[edges[e].v[0]] != region || region_of[edges[e].v[1]] != region);
  }

  void recost(Index e) { recost_inline(e); }

  // Inlined in the collapse's loop over the new vertex's pairs (about 7 per collapse): out of line, the
  // call's register saves and restores cost about 0.3 % of a bunny decimation's instructions.
  [[gnu::always_inline]] void recost_inline(Index e) {
    if (outside_region(e)) return;
    float key = 0;
    const std::uint32_t state = key_of_edge(e, &key);
    if (state == 0) {
      if (in_heap(e)) {
        heap.update(e, key);
      } else {
        heap.push(e, key);
      }
    } else if (in_heap(e)) {
      heap.remove(e, state);
    } else {
      edges[e].slot = state;
    }
  }

  void kill(Index e) {
    if (in_heap(e)) {
      heap.remove(e, kDead);
    } else {
      edges[e].slot = kDead;
    }
  }

  void block(Index e, std::uint32_t state) {
    heap.remove(e, state);
    verts[edges[e].v[0]].flags |= kHasBlocked;
    verts[edges[e].v[1]].flags |= kHasBlocked;
    blocked.push_back(e);
  }

  // ---------------------------------------------------------------- adjacency

  // Calls body(face) for the live faces around head vertex v, in circle order, without packing its segments
  // (see gather_faces); stops at, and returns, the first false.
  template <class Body>
  bool all_live_faces(Index v, const Body& body) const {
    Index seg = v;
    do {
      const Vertex& s = verts[seg];
      const Index* list = vf.data() + s.seg_start;
      for (Index i = 0; i < s.seg_count; ++i) {
        if (face_alive(list[i]) && !body(list[i])) return false;
      }
      seg = s.seg_next;
    } while (seg != v);
    return true;
  }

  // The live faces around head vertex v. They are packed into as few of its segments as hold them (in
  // circle order, v's own first) and the emptied segments are unlinked: a vertex that absorbed many others
  // would otherwise keep a few live faces in each of their segments, and every gather would visit all of
  // those scattered vertex records and lists (about a fifth of the collapse loop's cache misses).
  void gather_faces(Index v, std::vector<Index>& out) {
    Vertex& head = verts[v];
    if (head.seg_next == v) {
      // One segment (most vertices): packed in place while copied out, with no per-face capacity check.
      Index* list = vf.data() + head.seg_start;
      const Index n = head.seg_count;
      if (out.size() < n) out.resize(n);
      Index* to = out.data();
      Index kept = 0;
      for (Index i = 0; i < n; ++i) {
        const Index f = list[i];
        if (!face_alive(f)) continue;
        list[kept] = f;
        to[kept++] = f;
      }
      head.seg_count = kept;
      out.resize(kept);
      return;
    }
    // Several segments: the live faces out first, in circle order.
    out.clear();
    all_live_faces(v, [&](Index f) {
      out.push_back(f);
      return true;
    });
    // Then back into the segments, from the head on.
    std::size_t written = 0;
    Index prev = v;
    Index seg = v;
    do {
      Vertex& s = verts[seg];
      const Index next = s.seg_next;
      const std::size_t n = std::min<std::size_t>(s.seg_cap, out.size() - written);
      std::copy(out.begin() + written, out.begin() + written + n, vf.begin() + s.seg_start);
      s.seg_count = static_cast<Index>(n);
      written += n;
      if (n == 0 && seg != v) {
        verts[prev].seg_next = next;
      } else {
        prev = seg;
      }
      seg = next;
    } while (seg != v);
  }

  // ---------------------------------------------------------------- guards

  // Link condition of the edge (a, b) with dying faces `dying`: the common neighbours of a and b are exactly
  // the opposite corners of the dying faces, an interior edge does not join two boundary vertices, and a
  // tetrahedron is not flattened.
  bool link_condition(Index a, Index b) {
    const std::size_t kf = dying.size();
    if (kf == 0 || kf > 2) return false;
    const std::uint32_t s = next_stamp();
    for (Index f : fa) {
      for (Index x : faces[f].v) {
        if (x == a) continue;
        Vertex& vx = verts[x];
        if (vx.stamp != s) {
          vx.stamp = s;
          vx.mark = 1;
        } else {
          ++vx.mark;
        }
      }
    }
    bool a_boundary = false;
    for (Index f : fa) {
      for (Index x : faces[f].v) {
        if (x != a && verts[x].mark == 1) a_boundary = true;
      }
    }
    Index opposite[2] = {kNone, kNone};
    for (std::size_t i = 0; i < kf; ++i) {
      for (Index x : faces[dying[i]].v) {
        if (x != a && x != b) opposite[i] = x;
      }
    }
    if (kf == 2 && opposite[0] == opposite[1]) return false;
    // b's neighbours, with repeats, are kept only for the boundary test below.
    const bool b_boundary_matters = kf == 2 && a_boundary;
    scratch_ids.clear();
    for (Index f : fb) {
      for (Index x : faces[f].v) {
        if (x == b) continue;
        if (b_boundary_matters) scratch_ids.push_back(x);
        if (x != a && verts[x].stamp == s && x != opposite[0] && x != opposite[1]) return false;
      }
    }
    if (kf == 2) {
      // b's boundary only matters when a is on one: sorting the neighbours of a vertex of thousands of faces
      // took three quarters of a 10,000-segment cylinder's decimation with --preserve-topology.
      if (b_boundary_matters) {
        small_sort(scratch_ids.data(), scratch_ids.data() + scratch_ids.size());
        for (std::size_t i = 0; i < scratch_ids.size();) {
          std::size_t j = i;
          while (j < scratch_ids.size() && scratch_ids[j] == scratch_ids[i]) ++j;
          if (j - i == 1) return false;  // b is on a boundary too
          i = j;
        }
      }
      const Index c = opposite[0], d = opposite[1];
      auto has_face = [&](const std::vector<Index>& list, Index v) {
        for (Index f : list) {
          const Face& face = faces[f];
          if (has_corner(face, v) && has_corner(face, c) && has_corner(face, d)) return true;
        }
        return false;
      };
      if (has_face(fa, a) && has_face(fb, b)) return false;
    }
    return true;
  }

  // Calls body(face, p0, p1, p2) for every face around a and b that survives their collapse, p0 its corner
  // at a or b (before the collapse) and p1, p2 the next corners; stops at, and returns, the first false.
  template <class Body>
  [[gnu::always_inline]] bool all_surviving_faces(Index a, Index b, const Body& body) const {
    for (int side = 0; side < 2; ++side) {
      const std::vector<Index>& list = side == 0 ? fa : fb;
      const Index moved = side == 0 ? a : b, other = side == 0 ? b : a;
      const Vec3d p0 = rel(moved);
      for (Index f : list) {
        const Face& face = faces[f];
        if (has_corner(face, other)) continue;  // dying
        const int c = corner_of(face, moved);
        if (!body(face, p0, rel(face.v[(c + 1) % 3]), rel(face.v[(c + 2) % 3]))) return false;
      }
    }
    return true;
  }

  // A surviving face whose corner p0 moves to p: its new normal's squared length, the sum of its squared edge
  // lengths and its longest squared edge, for the shape penalty.
  struct MovedShape {
    double new2, sum, longest2;
    double old2, old_sum;  // the same before the move (the shape penalty's sliver threshold)
  };
  // Whether that face keeps its shape: it does not turn by 90 degrees or more in this move (a face that was
  // already degenerate has no direction to keep), nor by more than 60 from the input face it started as
  // (small turns add up over many collapses), nor fall below its quality floor.
  [[gnu::always_inline]] static bool keeps_shape(const Face& face, const Vec3d& p0, const Vec3d& p1,
                                                 const Vec3d& p2, const Vec3d& p, MovedShape* out) {
    const Vec3d e12 = p2 - p1;
    const Vec3d n_old = (p1 - p0).cross(p2 - p0);
    const Vec3d n_new = (p1 - p).cross(p2 - p);
    const double old2 = n_old.squaredNorm(), new2 = n_new.squaredNorm();
    if (old2 > 0 && n_old.dot(n_new) <= 0) return false;
    if (face.ref[0] != kNoNormal) {
      const Vec3d ref = decode_normal(face.ref);
      const double dot = n_new.dot(ref);
      if (dot <= 0 || dot * dot <= kRefCos2 * new2 * ref.squaredNorm()) return false;
    }
    const double l01 = (p1 - p).squaredNorm(), l02 = (p2 - p).squaredNorm(), l12 = e12.squaredNorm();
    const double sum = l01 + l02 + l12;
    // Qualities are compared squared, q^2 = 12 |n|^2 / sum(l^2)^2, so the test needs no square root.
    if (12 * new2 < face.floor2 * sum * sum) return false;  // degenerate
    const double old_sum = (p1 - p0).squaredNorm() + (p2 - p0).squaredNorm() + l12;
    *out = {new2, sum, std::max(l01, std::max(l02, l12)), old2, old_sum};
    return true;
  }

  // The shapes of a set of moved faces, for the shape penalty: the worst quality after and before the move
  // (kept squared, |n|^2 / sum^2, 1/12 for an equilateral triangle, so no square root per face) and the
  // longest squared edge after it.
  struct MovedShapes {
    double worst2 = 1.0 / 12.0, before2 = 1.0 / 12.0, longest2 = 0;
    void add(const MovedShape& m) {
      if (m.sum > 0) worst2 = std::min(worst2, m.new2 / (m.sum * m.sum));
      if (m.old_sum > 0) before2 = std::min(before2, m.old2 / (m.old_sum * m.old_sum));
      longest2 = std::max(longest2, m.longest2);
    }
    double worst_quality() const { return std::sqrt(12 * worst2); }
    double before_quality() const { return std::sqrt(12 * before2); }
  };

  // Flip and degeneracy guard over every surviving face around a and b with the moved corner at p; also the
  // worst resulting triangle quality and longest squared edge, for the shape penalty.
  bool shapes_ok(Index a, Index b, const Vec3d& p, double* worst_quality, double* longest2) const {
    MovedShapes shapes;
    const bool ok =
        all_surviving_faces(a, b, [&](const Face& face, const Vec3d& p0, const Vec3d& p1, const Vec3d& p2) {
          MovedShape m;
          if (!keeps_shape(face, p0, p1, p2, p, &m)) return false;
          shapes.add(m);
          return true;
        });
    *worst_quality = shapes.worst_quality();
    *longest2 = shapes.longest2;
    return ok;
  }

  // The worst quality, before the collapse, of the faces around a and b that survive it (the old shapes that
  // shapes_ok compares with). Only for collapses that would leave a sliver, so not in shapes_ok's loop.
  double worst_quality_before(Index a, Index b) const {
    double worst2 = 1.0 / 12.0;  // squared, as in shapes_ok
    all_surviving_faces(a, b, [&](const Face&, const Vec3d& p0, const Vec3d& p1, const Vec3d& p2) {
      const double sum = (p1 - p0).squaredNorm() + (p2 - p0).squaredNorm() + (p2 - p1).squaredNorm();
      if (sum > 0) worst2 = std::min(worst2, (p1 - p0).cross(p2 - p0).squaredNorm() / (sum * sum));
      return true;
    });
    return std::sqrt(12 * worst2);
  }

  // ---------------------------------------------------------------- the loop

  bool reached() const {
    return (target_f > 0 && faces_alive <= target_f) || (target_v > 0 && verts_alive <= target_v);
  }

  // The collapses the count targets ask for of a mesh of `faces` and `vertices` (one removes about one
  // vertex and two faces); infinite when there is none.
  double collapses_to_targets(std::uint64_t faces, std::uint64_t vertices) const {
    double needed = std::numeric_limits<double>::infinity();
    if (target_f > 0) needed = std::min(needed, faces > target_f ? double(faces - target_f) / 2 : 0.0);
    if (target_v > 0) needed = std::min(needed, vertices > target_v ? double(vertices - target_v) : 0.0);
    return needed;
  }
  // Of the input, in all.
  double collapses_needed() const { return collapses_to_targets(stats.input_faces, stats.input_vertices); }
  // Of the live counts: what the targets still ask for (see run_pass: with a tenth of its faces doubled, a
  // scan lost a further sixth of its faces below the target when only the collapses done were counted).
  double collapses_still_needed() const { return collapses_to_targets(faces_alive, verts_alive); }
  std::uint64_t expected_collapses() const {
    const double needed = collapses_needed();
    return needed < std::numeric_limits<double>::infinity() ? static_cast<std::uint64_t>(needed) : 0;
  }

  void run() {
    std::uint64_t collapses_at_retry = ~std::uint64_t{0};
    // How far below the face target a collapse may land: none, until every other candidate is spent; then
    // one (a closed manifold's parity), then as few as the pairs left allow (on a non-manifold edge a
    // collapse removes more than two faces: a surface and its reversed copy, four), so that the count ends
    // as near the target as it can but never above it.
    std::uint64_t short_allowed = 0;
    const std::uint64_t expected = expected_collapses();
    std::uint64_t next_report = 0;
    while (!reached()) {
      if (verts_alive <= compact_below) {
        compact();
        compact_below = verts_alive / 2;
      }
      if (stats.collapses >= next_report) {
        report(opt.progress, "decimate", stats.collapses, expected);
        next_report = stats.collapses + 16384;
      }
      if (heap.empty()) {
        if (!blocked.empty() && stats.collapses != collapses_at_retry) {
          collapses_at_retry = stats.collapses;
          std::vector<Index> list;
          list.swap(blocked);
          for (Index e : list) {
            if (edges[e].slot == kBlockedFlip || edges[e].slot == kBlockedTopology) recost(e);
          }
          if (!heap.empty()) continue;
        }
        // Every candidate left was put off: allow one below, then the least any of them needed (each
        // round allows more, so this ends).
        if (!deferred.empty() && (short_allowed == 0 || least_short != kNoShort)) {
          short_allowed = short_allowed == 0 ? 1 : least_short;
          least_short = kNoShort;
          for (Index e : deferred) {
            if (edges[e].slot == kDeferred) recost(e);
          }
          deferred.clear();
          if (!heap.empty()) continue;
        }
        // Every pair left is blocked where its quadric puts it: a last round lets each go to an end or its
        // midpoint where that keeps every face's shape. Not sooner: as a first resort those placements made
        // fandisk at 1 % 12 % worse (Hausdorff), where retrying a blocked pair once its neighbourhood changes
        // does better; as the last, a 1,280-face gear to 100 faces stopped at 170.
        if (!fallbacks && !blocked.empty()) {
          fallbacks = true;
          collapses_at_retry = ~std::uint64_t{0};
          continue;
        }
        break;
      }
      try_top(short_allowed);
    }
    // Done, whether at the target or stopped short of it (an error bound, guards): the bar ends full.
    report(opt.progress, "decimate", stats.collapses, stats.collapses);
  }

  // Survivors are scattered over arrays sized for the input: past 10 % of the input, collapses cost about
  // 1.5 times as much on a 1 M-triangle scan, as each touches cache lines and pages that hold mostly dead
  // records. Renumbering the live vertices, faces and edges to the front, in index order (so the output
  // order is unchanged), and rebuilding the face lists as one segment per vertex, packs them together. Done
  // in place (plus 4 bytes per live vertex, for the new ids) each time half the vertices of the last
  // renumbering remain: about 6 % less CPU time on 1 M and 10 M-triangle scans decimated to 1 % (against a
  // quarter: about 3 %); the heap keeps its order, so the output is byte-identical. Not with virtual pairs
  // (their per-vertex lists would need renumbering too).
  void compact() {
    const std::size_t nv = verts.size(), nf = faces.size(), ne = edges.size();
    // New vertex ids in a dense array rather than in the vertex records: the edge and face passes look up
    // both ends of every edge and all corners of every face, and with one 128-byte record per lookup those
    // reads were about two thirds of this function's time. New edge ids go in `vf` (rebuilt below; it has
    // room, as every edge was found in a face).
    std::vector<Index> id(nv);
    const Index nv_new = number_kept(nv, id.data(), [&](std::size_t v) { return verts[v].live_faces > 0; });
    // An edge lives only while a face holds both its ends; be safe anyway about ends left without faces.
    constexpr std::size_t grain = 65536;
    std::vector<std::vector<Index>> stray((ne + grain - 1) / grain);
    parallel_chunks(ne, grain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e) {
        const Edge& edge = edges[e];
        if (edge.slot != kDead && (id[edge.v[0]] == kNone || id[edge.v[1]] == kNone))
          stray[begin / grain].push_back(static_cast<Index>(e));
      }
    });
    for (const std::vector<Index>& chunk : stray) {
      for (Index e : chunk) kill(e);
    }
    if (vf.size() < ne) vf.resize(ne);
    const Index ne_new = number_kept(ne, vf.data(), [&](std::size_t e) { return edges[e].slot != kDead; });
    Index nf_new = 0;
    // Each array moves down in place, in order (a record's new place is never after its old one), so each
    // move is one serial loop; the three arrays move side by side. On a 1 M-triangle scan the first
    // compaction took 21 ms serially, about 5 % of the decimation's time.
    tbb::parallel_invoke(
        [&] {
          for (std::size_t e = 0; e < ne; ++e) {
            const Index to = vf[e];
            if (to == kNone) continue;
            const Edge edge = edges[e];
            edges[to] = {{id[edge.v[0]], id[edge.v[1]]}, edge.slot};
            if (edge.slot < first_state) heap.rename(edge.slot, to);
          }
          for (std::vector<Index>* list : {&blocked, &deferred}) {
            std::size_t kept = 0;
            for (Index e : *list) {
              if (vf[e] != kNone) (*list)[kept++] = vf[e];
            }
            list->resize(kept);
          }
        },
        [&] {
          std::vector<Index>& origin_of = storage.face_origin;
          for (std::size_t f = 0; f < nf; ++f) {
            const Face& t = faces[f];
            if (t.v[0] == kNone) continue;
            if (storage.keeps_source) origin_of[nf_new] = origin_of[f];
            faces[nf_new++] = {{id[t.v[0]], id[t.v[1]], id[t.v[2]]},
                               {vf[t.e[0]], vf[t.e[1]], vf[t.e[2]]},
                               {t.ref[0], t.ref[1]},
                               t.floor2};
          }
        },
        [&] {
          for (std::size_t v = 0; v < nv; ++v) {
            const Index to = id[v];
            if (to == kNone) continue;
            verts[to] = verts[v];
            Vertex& x = verts[to];
            x.stamp = 0;
            x.seg_next = to;
            if (!normals.empty()) normals[to] = normals[v];
            if (!colors.empty()) colors[to] = colors[v];
            if (!uvs.empty()) uvs[to] = uvs[v];
          }
        });
    stamp_now = 0;
    staged_edge = kNone;
    verts.resize(nv_new);
    faces.resize(nf_new);
    if (storage.keeps_source) storage.face_origin.resize(nf_new);
    edges.resize(ne_new);
    if (!normals.empty()) normals.resize(nv_new);
    if (!colors.empty()) colors.resize(nv_new);
    if (!uvs.empty()) uvs.resize(nv_new);

    build_face_lists(id, nv_new, [](Vertex&) {});
  }

  // Vertex -> faces in CSR form, each vertex's list one segment in face order. Counts and fill cursors go
  // through `scratch` (one entry per vertex, overwritten) rather than through the 128-byte vertex records,
  // which the two passes over the faces would otherwise visit three times each. `each` sees every vertex
  // once its segment is set.
  template <class Each>
  void build_face_lists(std::vector<Index>& scratch, std::size_t nv, Each&& each) {
    std::fill(scratch.begin(), scratch.begin() + static_cast<std::ptrdiff_t>(nv), Index{0});
    for (const Face& f : faces) {
      for (Index v : f.v) ++scratch[v];
    }
    Index running = 0;
    for (std::size_t v = 0; v < nv; ++v) {
      Vertex& x = verts[v];
      x.seg_start = running;
      x.seg_count = scratch[v];
      x.seg_cap = scratch[v];
      scratch[v] = running;  // fill cursor
      running += x.seg_count;
      each(x);
    }
    vf.resize(running);
    for (std::size_t f = 0; f < faces.size(); ++f) {
      for (Index v : faces[f].v) vf[scratch[v]++] = static_cast<Index>(f);
    }
  }

  // The next pair to collapse is nearly always the cheapest child of the heap's root (the current top). Its
  // data is loaded ahead, one dependent level per stage, while the current collapse computes.
  Index predicted_next() const {
    const std::size_t n = heap.size();
    if (n < 2) return kNone;
    std::size_t best = 1;
    float best_key = heap.entry(1).key;
    const std::size_t last = std::min<std::size_t>(n, 1 + EdgeHeap::arity);
    for (std::size_t i = 2; i < last; ++i) {
      const float k = heap.entry(i).key;
      const bool less = k < best_key;  // selects, not branches (as in EdgeHeap::sift_down)
      best = less ? i : best;
      best_key = less ? k : best_key;
    }
    return heap.entry(best).edge;
  }

  // Stage 1: the predicted pair's vertex records. Stage 2 (those records have arrived): their face-list
  // heads. Stage 3 (the lists have arrived; issued before the current collapse's re-costs): their faces.
  // Stage 4 (after the collapse): the faces' corners and edges. Reads of stale data are harmless: every index
  // stays in range. Stages 3 and 4 leave out a list longer than kLargeFan: a large fan's pair is mostly
  // settled from its small end (see refused_beside_small_end), and loading the whole fan at every prediction
  // of one of its pairs made each collapse beside the fan cost as much as the fan (a disk fanned from one
  // centre to 80,000 rim vertices: 4.0 s at 10 %, against 0.6 s without those loads).
  //
  // Always inlined: GCC finds a function that only reads memory and prefetches to be pure, and then deletes
  // its calls (their result is void), so out of line these prefetches were never issued.
  [[gnu::always_inline]] void prefetch_stage(Index e, int stage) const {
    if (e == kNone) return;
    for (Index v : edges[e].v) {
      const Vertex& x = verts[v];
      if (stage == 1) {
        __builtin_prefetch(&x);
        __builtin_prefetch(reinterpret_cast<const char*>(&x) + 64);
      } else if (stage == 2) {
        __builtin_prefetch(vf.data() + x.seg_start);
      } else if (x.seg_count > kLargeFan) {
        continue;
      } else if (stage == 3) {
        const Index* list = vf.data() + x.seg_start;
        for (Index i = 0; i < x.seg_count; ++i) __builtin_prefetch(&faces[list[i]]);
      } else {
        // Stage 4 (the faces have arrived): their corners, both cache lines (positions for the guards,
        // quadrics for the re-costs), and their edges.
        const Index* list = vf.data() + x.seg_start;
        for (Index i = 0; i < x.seg_count; ++i) {
          const Face& face = faces[list[i]];
          if (face.v[0] == kNone) continue;
          // The corner after v in each face: around an interior vertex, every neighbour once.
          const int c = corner_of(face, v);
          const char* next_corner = reinterpret_cast<const char*>(&verts[face.v[(c + 1) % 3]]);
          __builtin_prefetch(next_corner);
          __builtin_prefetch(next_corner + 64);
          __builtin_prefetch(&edges[face.e[c]]);
        }
      }
    }
  }

  // After gathering: the corners (for the shape guards) and the edges (merged or re-costed) around a and b.
  [[gnu::always_inline]] void prefetch_neighbourhood(const std::vector<Index>& list, Index v) const {
    for (Index f : list) {
      const Face& face = faces[f];
      const int c = corner_of(face, v);
      __builtin_prefetch(&verts[face.v[(c + 1) % 3]]);
      __builtin_prefetch(&verts[face.v[(c + 2) % 3]]);
      __builtin_prefetch(&edges[face.e[c]]);
      __builtin_prefetch(&edges[face.e[(c + 2) % 3]]);
    }
  }

  // The vertices the collapse of (a, b) leaves without faces: opposite corners of the dying faces whose every
  // live face dies. Each dying face has one opposite corner, so a corner's dying faces are the dying faces
  // naming it. Up to a few faces (every manifold edge) they are counted pairwise; beyond, from a sorted copy:
  // pairwise on an edge of 300,000 duplicate faces took minutes.
  std::uint64_t orphans_of_dying(Index a, Index b) {
    auto opposite = [&](Index f) {
      const Face& t = faces[f];
      return t.v[0] != a && t.v[0] != b ? t.v[0] : t.v[1] != a && t.v[1] != b ? t.v[1] : t.v[2];
    };
    std::uint64_t orphans = 0;
    if (dying.size() <= 8) {
      for (std::size_t i = 0; i < dying.size(); ++i) {
        const Index c = opposite(dying[i]);
        Index count = 0;
        bool first = true;
        for (std::size_t j = 0; j < dying.size(); ++j) {
          if (opposite(dying[j]) == c) {
            ++count;
            if (j < i) first = false;
          }
        }
        if (first && verts[c].live_faces == count) ++orphans;
      }
      return orphans;
    }
    opposites.resize(dying.size());
    std::transform(dying.begin(), dying.end(), opposites.begin(), opposite);
    std::sort(opposites.begin(), opposites.end());
    for (std::size_t i = 0; i < opposites.size();) {
      std::size_t j = i;
      while (j < opposites.size() && opposites[j] == opposites[i]) ++j;
      if (verts[opposites[i]].live_faces == j - i) ++orphans;
      i = j;
    }
    return orphans;
  }

  // Whether collapsing (a, b) would put two faces on the same three vertices: a face (a, x, y) and a face
  // (b, x, y), neither on the edge, become one face twice. Where the surface folds back (a tetrahedron's
  // edge, a thin part closing up) that is a two-sided sliver with opposite windings, which encloses nothing
  // and z-fights when drawn: horse.ply to 5,000 faces kept 3 such pairs. --preserve-topology's link condition
  // excludes them too; this guard holds without it, where collapses may still join parts and close holes.
  // Reads fa and fb (try_top's gather): the smaller side's far vertices are stamped, so only faces of the
  // larger side with both far vertices stamped (rare: both are common neighbours of a and b) are compared.
  bool doubles_a_face(Index a, Index b) {
    const bool a_small = fa.size() <= fb.size();
    const std::vector<Index>& small = a_small ? fa : fb;
    const std::vector<Index>& large = a_small ? fb : fa;
    const Index s_end = a_small ? a : b, l_end = a_small ? b : a;
    const std::uint32_t s = next_stamp();
    for (Index f : small) {
      const Face& t = faces[f];
      if (has_corner(t, l_end)) continue;  // dies with the edge
      for (Index x : t.v) verts[x].stamp = s;
    }
    for (Index f : large) {
      const Face& t = faces[f];
      if (has_corner(t, s_end)) continue;
      const int c = corner_of(t, l_end);
      const Index x = t.v[(c + 1) % 3], y = t.v[(c + 2) % 3];
      if (verts[x].stamp != s || verts[y].stamp != s) continue;
      for (Index g : small) {
        const Face& u = faces[g];
        if (!has_corner(u, l_end) && has_corner(u, x) && has_corner(u, y)) return true;
      }
    }
    return false;
  }

  // Whether a and b are two corners of a tetrahedron that is a whole component: four faces on four vertices,
  // each in three faces (dying: the two on the edge); its corners go to `corners`, a and b first. What a
  // small closed part (a scan's floating debris, a bolt's head) decimates down to, and where it stuck: any
  // collapse doubles its two other faces (doubles_a_face). 2,000 tiny tetrahedra beside a sphere, decimated
  // to 2,000 faces, kept their 8,000 faces and left the sphere 4 faces, at 6.95 % Hausdorff.
  bool lone_tetrahedron(Index a, Index b, Index corners[4]) const {
    if (dying.size() != 2 || fa.size() != 3 || fb.size() != 3) return false;
    corners[0] = a;
    corners[1] = b;
    for (int i = 0; i < 2; ++i) {
      const Face& t = faces[dying[i]];
      corners[2 + i] = t.v[0] != a && t.v[0] != b ? t.v[0] : t.v[1] != a && t.v[1] != b ? t.v[1] : t.v[2];
    }
    if (corners[2] == corners[3]) return false;
    for (int i = 0; i < 4; ++i) {
      if (verts[corners[i]].live_faces != 3 || locked(corners[i])) return false;
    }
    // a's and b's third faces must be (a, c, d) and (b, c, d): then c's and d's three faces are all here.
    for (const std::vector<Index>* list : {&fa, &fb}) {
      for (Index f : *list) {
        for (Index x : faces[f].v) {
          if (x != a && x != b && x != corners[2] && x != corners[3]) return false;
        }
      }
    }
    return true;
  }

  // Removes a lone tetrahedron (see lone_tetrahedron) found at the top pair e, whose queue key is `queued`,
  // charged as the collapse of all four corners to the centroid of its surface: the larger of their summed
  // quadric there and the area they stand for times the mean squared distance from the tetrahedron's
  // surface to that point. The quadric alone measures distance to planes, which a small closed part is
  // close to everywhere inside it: charged by it, 2,000 small tetrahedra beside a sphere of 47,600 faces
  // went at 9,000 faces, at ten times the RMS distance of keeping them. When the charge is above the pair's
  // key, the pair first goes back to the queue at it. A part far from the rest leaves a gap of that
  // distance, which no local charge sees; --preserve-topology keeps every part.
  void remove_tetrahedron(Index e, const Index corners[4], float queued, std::uint64_t short_allowed) {
    if (!fits_targets(4, 4, short_allowed)) {
      heap.remove(e, kDeferred);
      deferred.push_back(e);
      return;
    }
    Quadric q;
    double area = 0;
    Vec3d at[4];
    for (int i = 0; i < 4; ++i) {
      const Vertex& v = verts[corners[i]];
      decimate_detail::add_to(q, v.q);
      area += v.area;
      at[i] = rel(corners[i]);
    }
    // The surface's centroid and its second moment about it, face by face: over a triangle with corners
    // x, y, z (relative to the point), the integral of |p|^2 is its area / 6 times (|x|^2 + |y|^2 + |z|^2 +
    // x.y + y.z + z.x).
    static constexpr int kFaces[4][3] = {{0, 1, 2}, {0, 1, 3}, {0, 2, 3}, {1, 2, 3}};
    double face_area[4], surface = 0;
    Vec3d centroid = Vec3d::Zero();
    for (int k = 0; k < 4; ++k) {
      const int* f = kFaces[k];
      face_area[k] = 0.5 * (at[f[1]] - at[f[0]]).cross(at[f[2]] - at[f[0]]).norm();
      surface += face_area[k];
      centroid += face_area[k] / 3 * (at[f[0]] + at[f[1]] + at[f[2]]);
    }
    if (surface > 0) centroid /= surface;
    double moment = 0;
    for (int k = 0; k < 4; ++k) {
      const int* f = kFaces[k];
      const Vec3d x = at[f[0]] - centroid, y = at[f[1]] - centroid, z = at[f[2]] - centroid;
      moment += face_area[k] / 6 *
                (x.squaredNorm() + y.squaredNorm() + z.squaredNorm() + x.dot(y) + y.dot(z) + z.dot(x));
    }
    const double mean_square = surface > 0 ? moment / surface : 0.0;
    const double weight = area * area_unit;
    const double cost = std::max(decimate_detail::evaluate(q, centroid), weight * mean_square);
    const double error = error_distance(cost, weight);
    if (error > opt.max_error) {
      heap.remove(e, kIdleError);
      return;
    }
    const float key = key_of(cost, q.trace());
    if (sent_back(e, key, &queued)) return;
    for (const std::vector<Index>* list : {&fa, &fb}) {
      for (Index f : *list) {
        Face& t = faces[f];
        if (t.v[0] == kNone) continue;  // one of the dying faces, met again in b's list
        for (Index id : t.e) {
          if (!edge_dead(id)) kill(id);
        }
        t.v[0] = kNone;
      }
    }
    for (int i = 0; i < 4; ++i) {
      verts[corners[i]].live_faces = 0;
      if (!virtual_pairs.empty()) drop_virtual_pairs(corners[i]);
    }
    faces_alive -= 4;
    verts_alive -= 4;
    stats.max_error = std::max(stats.max_error, error);
    applied_key = std::max(applied_key, key);
    ++stats.collapses;
  }

  // Whether a collapse removing kf faces and kv vertices stays within the count targets. The last faces are
  // never removed, whatever the targets: an error bound alone (a flat square at --max-error 1, a single
  // triangle at cost 0 without border planes) or a vertex target below 3 took every face, and an empty mesh
  // is no approximation of a surface.
  bool fits_targets(std::uint64_t kf, std::uint64_t kv, std::uint64_t short_allowed) {
    if (kf >= faces_alive) {
      kept_last_faces = true;
      return false;
    }
    if (target_f > 0 && faces_alive - kf < target_f) {
      // One below is the best a closed manifold allows when one face is left to remove: every collapse
      // removes two unless it is on a boundary edge, and none is left. Beyond that, what run() allows.
      const std::uint64_t short_by = target_f - (faces_alive - kf);
      const bool parity = short_by == 1 && kf == 2 && boundary_edges == 0;
      if (!parity && short_by > short_allowed) {
        least_short = std::min(least_short, short_by);
        return false;
      }
    }
    return !(target_v > 0 && verts_alive - kv < target_v);
  }

  // A pair with one end on a large fan (a cone's apex, the centre of a CAD cylinder's cap of thousands of
  // segments) is refused, when it is, mostly at faces beside the small end: its own, and the fan's faces at
  // its neighbours, which moving the apex to the rim squeezes into slivers. Those are read first, found from
  // the small end, then a sample of the rest of the fan in list order, all within a budget of an eighth of
  // the fan's faces. Before, each refusal read the whole fan three times (gather, prefetch, shapes_ok): a
  // double cone of two 50,000-face apexes took 47 s at 10 %, now 9.5 s. The refusals taken here are the very
  // ones shapes_ok would make; a pair that passes, or that the count targets would defer, goes on through
  // try_top's whole check. (With --preserve-topology, a refusal here counts as a flip even where the link
  // condition, checked first in try_top, would also refuse it.)
  //
  // The faces it reads also give a first shape penalty (see try_top), from them alone: `near` gets their
  // shapes (none read: no penalty). Around a fan's centre, the worst slivers a move to the rim makes are
  // beside the small end (its neighbours on the rim), so this penalty is what sends such a pair back into the
  // queue; the full check, when the pair comes up again, may raise it. Each collapse on the rim re-costs the
  // centre's pair to it, and when every return trip read the whole fan (the full penalty's faces), a disk
  // fanned from one centre to 20,000 rim vertices took 4.5 s at 10 %.
  static constexpr Index kLargeFan = 64;
  bool refused_beside_small_end(Index a, Index b, const Vec3d& p, std::uint64_t short_allowed,
                                MovedShapes* near, bool* shapes_checked) {
    const bool a_small = verts[a].live_faces <= verts[b].live_faces;
    const Index small = a_small ? a : b, big = a_small ? b : a;
    // The budget keeps the pairs this does not refuse (where both ends are large, as in a soup of coincident
    // points, or where the link condition refuses them) at little more than their cost before: reading the
    // whole fan here too made such runs up to 50 % slower.
    std::uint64_t budget = verts[big].live_faces / 8;
    if (verts[small].live_faces > budget) return false;
    budget -= verts[small].live_faces;
    gather_faces(small, scratch_faces);  // try_top gathers it next anyway
    dying.clear();
    for (Index f : scratch_faces) {
      if (has_corner(faces[f], big)) dying.push_back(f);
    }
    // More than two faces on the pair's edge (a soup, a non-manifold fan): left to try_top's whole check.
    if (dying.size() > 2) return false;
    const std::uint64_t kf = dying.size(), orphans = orphans_of_dying(a, b);
    const bool pair_orphaned = std::uint64_t{verts[a].live_faces} + verts[b].live_faces == 2 * kf;
    if (!fits_targets(kf, 1 + orphans + (pair_orphaned ? 1 : 0), short_allowed)) return false;
    if (opt.preserve_topology && (orphans > 0 || pair_orphaned)) return false;
    *shapes_checked = true;
    auto kept = [&](const Face& face, Index moved) {
      const int c = corner_of(face, moved);
      MovedShape m;
      if (!keeps_shape(face, rel(moved), rel(face.v[(c + 1) % 3]), rel(face.v[(c + 2) % 3]), p, &m))
        return false;
      near->add(m);
      return true;
    };
    for (Index f : scratch_faces) {
      if (!has_corner(faces[f], big) && !kept(faces[f], small)) return true;
    }
    // Each neighbour once, within the budget.
    const std::uint32_t s = next_stamp();
    for (Index f : scratch_faces) {
      for (Index x : faces[f].v) {
        Vertex& vx = verts[x];
        if (x == small || x == big || vx.stamp == s) continue;
        vx.stamp = s;
        if (vx.live_faces > budget) continue;  // another fan, as the other apex of a double cone
        budget -= vx.live_faces;
        const bool all_kept = all_live_faces(x, [&](Index g) {
          const Face& face = faces[g];
          return !has_corner(face, big) || has_corner(face, small) || kept(face, big);
        });
        if (!all_kept) return true;
      }
    }
    // Then up to kLargeFan more of the fan's faces, in its list's order, within the budget: a sample of the
    // far side, where a cone's apex moved to the rim turns faces over. Up to the whole budget (an eighth of
    // the fan), the pairs of a fanned disk's centre, refused or sent back at every change of the rim, each
    // read thousands of faces here (40,000 rim vertices: 1.3 s at 10 %, against 0.3 s).
    budget = std::min<std::uint64_t>(budget, kLargeFan);
    bool refused = false;
    all_live_faces(big, [&](Index g) {
      const Face& face = faces[g];
      if (budget-- == 0) return false;
      refused = !has_corner(face, small) && !kept(face, big);
      return !refused;
    });
    return refused;
  }

  // Faces of the large fan a few rings out from the small end, read before try_top reads the whole fan for
  // its full check. On a finely fanned disk (float positions, a million rim vertices) rounding turns faces
  // over for about a hundred rim steps either side of where the centre would move, beyond the first ring
  // that refused_beside_small_end reads, and each full check read the whole fan: 1 M rim vertices took
  // 7.3 s at 10 %, 2 M 47 s. Called only for pairs that refused_beside_small_end checked and did not
  // refuse or send back, so its refusals are again ones shapes_ok would make.
  static constexpr std::size_t kFartherFaces = 1024;
  bool refused_farther_out(Index a, Index b, const Vec3d& p) {
    const Index small = verts[a].live_faces <= verts[b].live_faces ? a : b, big = small == a ? b : a;
    const std::uint32_t s = next_stamp();
    verts[small].stamp = s;
    verts[big].stamp = s;
    scratch_ids.assign(1, small);
    std::size_t checks = 0;
    bool refused = false;
    for (std::size_t i = 0; i < scratch_ids.size() && !refused && checks < kFartherFaces; ++i) {
      const Index x = scratch_ids[i];
      if (verts[x].live_faces > kLargeFan) continue;  // another fan, as the other apex of a double cone
      all_live_faces(x, [&](Index g) {
        const Face& face = faces[g];
        // Along the fan's rim only: a walk into the rest of the mesh (a cone's base) would find no fan faces.
        if (!has_corner(face, big)) return true;
        for (Index y : face.v) {
          if (verts[y].stamp != s) {
            verts[y].stamp = s;
            scratch_ids.push_back(y);
          }
        }
        if (x != small && !has_corner(face, small)) {
          ++checks;
          const int c = corner_of(face, big);
          MovedShape m;
          refused = !keeps_shape(face, rel(big), rel(face.v[(c + 1) % 3]), rel(face.v[(c + 2) % 3]), p, &m);
        }
        return !refused && checks < kFartherFaces;
      });
    }
    return refused;
  }

  // Raises the top pair e's key to `key` where that is above `*queued` (its key in the queue, updated):
  // returns whether another pair is then at the top, which goes first.
  bool sent_back(Index e, float key, float* queued) {
    if (!(key > *queued)) return false;
    heap.update(e, key);
    *queued = key;
    return heap.top().edge != e;
  }

  void try_top(std::uint64_t short_allowed) {
    const HeapEntry top = heap.top();
    const Index e = top.edge;
    const Index next = predicted_next();
    prefetch_stage(next, 1);
    const Index a = edges[e].v[0], b = edges[e].v[1];
    // Stage 4 of the last collapse loaded this pair's neighbourhood when it predicted this pair and both
    // lists were one segment (those it read), so they are loaded again only otherwise: on the shared scans,
    // about 1 % of the instructions for prefetches of lines already requested.
    const bool staged = e == staged_edge && verts[a].seg_next == a && verts[b].seg_next == b;
    staged_edge = kNone;
    decimate_detail::RawQuadric q;
    Placement pl;
    float key = 0;
    double cost = 0;
    evaluate_inline(e, &q, &pl, &key, &cost);
    float queued = top.key;  // the key it has in the queue
    // Sends the pair back to the queue with its cost plus a shape penalty, when that puts it behind another
    // pair: returns whether it went.
    auto requeued = [&](double penalty, bool whole_fan) {
      if (!(penalty > 0)) return false;
      float penalized = key_of(cost + penalty, trace(q));
      // The penalty only tips near-ties: it may put a pair behind others of about the level the collapses
      // have reached (see kNearTie), never behind every pair that costs geometry. Unbounded, it grows with
      // the squared length of the longest resulting edge, and on a long strip (100 x 0.1) every collapse
      // along it, all of cost 0, came out dearer than the ones across it: the strip fell into pieces at
      // 91 % Hausdorff. A vertex of more than kLargeFan faces keeps the whole penalty: moving it would turn
      // its whole fan into slivers (a disk fanned from its centre lost the centre to the rim, at no
      // geometric cost).
      if (!whole_fan) {
        const double w = trace(q);
        const float floor_key = key_of(kTieFloor * kTieFloor * w * w, w);
        penalized = std::min(penalized, key + kNearTie * std::max(applied_key, floor_key));
      }
      return sent_back(e, penalized, &queued);
    };
    const bool large_fan = std::max(verts[a].live_faces, verts[b].live_faces) > kLargeFan;
    if (large_fan) {
      MovedShapes near;
      bool shapes_checked = false;
      if (refused_beside_small_end(a, b, pl.point, short_allowed, &near, &shapes_checked)) {
        ++stats.rejected_flip;
        block(e, kBlockedFlip);
        return;
      }
      if (requeued(sliver_penalty(trace(q), near.worst_quality(), near.before_quality(), near.longest2),
                   true))
        return;
      if (shapes_checked && refused_farther_out(a, b, pl.point)) {
        ++stats.rejected_flip;
        block(e, kBlockedFlip);
        return;
      }
    }
    gather_faces(a, fa);
    gather_faces(b, fb);
    if (!staged) {
      prefetch_neighbourhood(fa, a);
      prefetch_neighbourhood(fb, b);
    }
    dying.clear();
    for (Index f : fa) {
      if (has_corner(faces[f], b)) dying.push_back(f);
    }
    const std::uint64_t kf = dying.size();
    const std::uint64_t orphans = orphans_of_dying(a, b);
    const bool pair_orphaned = fa.size() + fb.size() == 2 * kf;  // the pair itself loses every face
    if (!fits_targets(kf, 1 + orphans + (pair_orphaned ? 1 : 0), short_allowed)) {
      heap.remove(e, kDeferred);
      deferred.push_back(e);
      return;
    }
    if (opt.preserve_topology && (orphans > 0 || pair_orphaned || !link_condition(a, b))) {
      ++stats.rejected_topology;
      block(e, kBlockedTopology);
      return;
    }
    double worst_quality = 1, longest2 = 0;
    if (doubles_a_face(a, b)) {
      Index corners[4];
      if (!opt.preserve_topology && lone_tetrahedron(a, b, corners)) {
        remove_tetrahedron(e, corners, queued, short_allowed);
        return;
      }
      ++stats.rejected_flip;
      block(e, kBlockedFlip);
      return;
    }
    if (!shapes_ok(a, b, pl.point, &worst_quality, &longest2)) {
      const double attribute_cost = cost - pl.error;  // the same wherever the pair goes
      if (!(fallbacks && fallback_placement(a, b, q, &pl, &worst_quality, &longest2))) {
        ++stats.rejected_flip;
        block(e, kBlockedFlip);
        return;
      }
      cost = pl.error + attribute_cost;
      const float fallback_key = key_of(cost, trace(q));
      if (sent_back(e, fallback_key, &queued)) return;
      key = std::max(key, fallback_key);
    }
    // A sliver counts against a collapse only where it is worse than the faces were before: CAD tessellations
    // are made of slivers, and penalizing every collapse among them put shape before geometry (teapot.obj at
    // 10 %: RMS distance 0.229 % of the diagonal with the fixed threshold, 0.161 with this one; bunny, horse
    // and igea at 10, 3 and 1 % within 1.2 %).
    if (opt.shape_weight > 0 && worst_quality < kSliverQuality &&
        requeued(sliver_penalty(trace(q), worst_quality, worst_quality_before(a, b), longest2), large_fan))
      return;
    prefetch_stage(next, 2);
    applied_key = std::max(applied_key, key);
    collapse(e, a, b, q, pl, orphans, next);
    prefetch_stage(next, 4);
    staged_edge = next;
  }

  // Where the quadric's best point would turn or degenerate a face around the pair, the cheaper of the
  // pair's ends and its midpoint that keeps every shape (Garland and Heckbert's fallbacks), in `pl`; false
  // when none does within max_error, or when an end is locked (its placement is the only one).
  bool fallback_placement(Index a, Index b, const decimate_detail::RawQuadric& q, Placement* pl,
                          double* worst_quality, double* longest2) const {
    if (locked(a) || locked(b)) return false;
    const Vec3d pa = rel(a), pb = rel(b);
    Placement options[3] = {{pa, decimate_detail::evaluate(q, pa)},
                            {pb, decimate_detail::evaluate(q, pb)},
                            {0.5 * (pa + pb), decimate_detail::evaluate(q, Vec3d(0.5 * (pa + pb)))}};
    std::sort(std::begin(options), std::end(options),
              [](const Placement& x, const Placement& y) { return x.error < y.error; });
    const double area = (double(verts[a].area) + verts[b].area) * area_unit;
    for (Placement& option : options) {
      option.error = std::max(0.0, option.error);
      if (error_distance(option.error, area) > opt.max_error) break;  // sorted: the rest cost more
      if (shapes_ok(a, b, option.point, worst_quality, longest2)) {
        *pl = option;
        return true;
      }
    }
    return false;
  }

  // The shape penalty of a collapse whose worst resulting triangle quality is `worst` (`before`: the worst of
  // the same faces before it; `longest2`: their longest squared edge after it), for a pair of quadric weight
  // `weight`.
  double sliver_penalty(double weight, double worst, double before, double longest2) const {
    const double sliver = std::min(kSliverQuality, before);
    return worst < sliver ? opt.shape_weight * weight * longest2 * (1 - worst / sliver) : 0.0;
  }

  void interpolate_attributes(Index a, Index b, Index k, const Vec3d& p) {
    if (normals.empty() && colors.empty() && uvs.empty()) return;
    const Vec3d pa = rel(a), d = rel(b) - pa;
    const double length2 = d.squaredNorm();
    const double t = length2 > 0 ? std::clamp((p - pa).dot(d) / length2, 0.0, 1.0) : 0.5;
    const float tf = static_cast<float>(t);
    if (!normals.empty()) {
      const Vec3f n = (1 - tf) * normals[a] + tf * normals[b];
      const float length = n.norm();
      normals[k] = length > 0 ? Vec3f(n / length) : normals[a];
    }
    if (!uvs.empty()) uvs[k] = (1 - tf) * uvs[a] + tf * uvs[b];
    if (!colors.empty()) {
      Color c;
      for (int i = 0; i < 4; ++i) {
        c[i] = static_cast<std::uint8_t>(std::lround((1 - t) * colors[a][i] + t * colors[b][i]));
      }
      colors[k] = c;
    }
  }

  void collapse(Index e, Index a, Index b, const decimate_detail::RawQuadric& q, const Placement& pl,
                std::uint64_t orphans, Index next) {
    // Keep the locked end if there is one (it does not move), else the one with more faces (fewer rewrites).
    const bool la = locked(a), lb = locked(b);
    const bool keep_b = lb && !la ? true : la && !lb ? false : fb.size() > fa.size();
    const Index k = keep_b ? b : a, r = keep_b ? a : b;
    const std::vector<Index>& fk = keep_b ? fb : fa;
    const std::vector<Index>& fr = keep_b ? fa : fb;
    // The arrays' data in locals: through the members, each access reloaded the vector's address and then
    // its data pointer after every store and call in these loops.
    Vertex* const vtx = verts.data();
    Face* const fcs = faces.data();
    Edge* const egs = edges.data();
    Vertex& vk = vtx[k];
    Vertex& vr = vtx[r];

    stats.max_error =
        std::max(stats.max_error, error_distance(pl.error, (double(vk.area) + vr.area) * area_unit));
    interpolate_attributes(a, b, k, pl.point);
    const Vec3f placed = nearest_float(origin + pl.point);
    for (int a = 0; a < 3; ++a) vk.p[a] = placed[a];
    vk.q = {q.a00, q.a01, q.a02, q.a11, q.a12, q.a22, q.b0, q.b1, q.b2, q.c};
    vk.flags = (vk.flags | vr.flags) & kLocked;
    vk.area += vr.area;

    // The kept vertex's edges, keyed by the other end.
    const std::uint32_t s = next_stamp();
    // Room for every side of k's and r's faces up front, so the loops below add neighbours without a capacity
    // check each.
    const std::size_t most = 2 * (fk.size() + fr.size());
    if (nbrs.size() < most) nbrs.resize(most);
    Neighbour* const nb = nbrs.data();
    Index count = 0;
    for (Index f : fk) {
      const Face& t = fcs[f];
      const int c = corner_of(t, k);
      for (int side = 1; side <= 2; ++side) {
        const Index x = t.v[(c + side) % 3];
        if (x == r) continue;
        Vertex& vx = vtx[x];
        if (vx.stamp != s) {
          vx.stamp = s;
          vx.mark = count;
          nb[count++] = {x, t.e[side == 1 ? c : (c + 2) % 3], 1, 0, 0};
        } else {
          ++nb[vx.mark].cnt_k;
        }
      }
    }
    for (Index f : dying) {
      for (Index x : fcs[f].v) {
        if (x != k && x != r) ++nb[vtx[x].mark].cnt_d;
      }
    }
    // Every edge around k is re-costed below: start loading the quadrics and heap slots it will read.
    for (Index i = 0; i < count; ++i) {
      const Neighbour& n = nb[i];
      __builtin_prefetch(reinterpret_cast<const char*>(&vtx[n.x]) + 64);
      const std::uint32_t slot = egs[n.edge].slot;
      if (slot < first_state) heap.prefetch(slot);
    }
    // The removed vertex's faces move to k; its edges are renamed, or merged into k's edge to the same
    // vertex.
    for (Index f : fr) {
      Face& t = fcs[f];
      const bool is_dying = has_corner(t, k);
      const int c = corner_of(t, r);
      for (int side = 1; side <= 2; ++side) {
        const Index x = t.v[(c + side) % 3];
        if (x == k) continue;
        const int edge_slot = side == 1 ? c : (c + 2) % 3;
        const Index id = t.e[edge_slot];
        Vertex& vx = vtx[x];
        if (vx.stamp == s) {
          Neighbour& n = nb[vx.mark];
          ++n.cnt_r;
          if (n.edge != id) {
            if (!is_dying) t.e[edge_slot] = n.edge;
            if (!edge_dead(id)) kill(id);
          }
        } else {
          vx.stamp = s;
          vx.mark = count;
          nb[count++] = {x, id, 0, 1, 0};
          Edge& edge = egs[id];
          edge.v[edge.v[0] == r ? 0 : 1] = k;
        }
      }
      if (!is_dying) t.v[c] = k;
    }
    nbrs.resize(count);  // shrinking: no reallocation, so `nb` stays valid
    kill(e);

    // Boundary edges before (around k and r, the collapsed edge once) and after (around k).
    std::uint64_t before = dying.size() == 1 ? 1 : 0, after = 0;
    for (Neighbour& n : nbrs) {
      before += (n.cnt_k == 1) + (n.cnt_r == 1);
      const Index count = n.cnt_k + n.cnt_r - 2 * n.cnt_d;
      after += count == 1;
      if (count == 0 && !edge_dead(n.edge)) kill(n.edge);
    }
    boundary_edges = boundary_edges + after - before;

    for (Index f : dying) {
      Face& t = fcs[f];
      for (Index x : t.v) {
        if (x != k && x != r) --vtx[x].live_faces;
      }
      t.v[0] = kNone;
    }
    faces_alive -= dying.size();
    vk.live_faces = static_cast<Index>(fk.size() + fr.size() - 2 * dying.size());
    vr.live_faces = 0;
    verts_alive -= 1 + orphans + (vk.live_faces == 0 ? 1 : 0);

    // r's face segments join k's circular list.
    std::swap(vk.seg_next, vr.seg_next);

    if (!virtual_pairs.empty()) merge_virtual_pairs(k, r, s);

    // The next pair's face lists arrived during the work above; its faces load during the re-costs.
    prefetch_stage(next, 3);
    // Every pair of k is re-costed; its blocked ones only when a retry around k is due (see retry_due).
    const bool retry_k = retry_due(vk);
    bool kept_blocked = false;
    for (const Neighbour& n : nbrs) {
      const std::uint32_t slot = egs[n.edge].slot;
      if (slot == kDead) continue;
      if (!retry_k && (slot == kBlockedFlip || slot == kBlockedTopology)) {
        kept_blocked = true;
        continue;
      }
      recost_inline(n.edge);
    }
    if (!virtual_pairs.empty()) {
      for (Index id : virtual_pairs[k]) recost(id);
    }
    vk.flags = kept_blocked ? vk.flags | kHasBlocked : vk.flags & ~kHasBlocked;
    // The neighbours' blocked edges, too, when due: around k (k's many neighbours each retrying its blocked
    // edge into k's fan cost as much as k's own retry) and around each neighbour.
    if (retry_k) {
      for (const Neighbour& n : nbrs) {
        if (vtx[n.x].flags & kHasBlocked) retry_around(n.x);
      }
    }
    ++stats.collapses;
  }

  void merge_virtual_pairs(Index k, Index r, std::uint32_t s) {
    std::vector<Index>& lk = virtual_pairs[k];
    std::vector<Index>& lr = virtual_pairs[r];
    scratch_ids.clear();
    for (int side = 0; side < 2; ++side) {
      for (Index id : side == 0 ? lk : lr) {
        if (edge_dead(id)) continue;
        Edge& edge = edges[id];
        const Index x = edge.v[0] == k || edge.v[0] == r ? edge.v[1] : edge.v[0];
        if (x == k || x == r || verts[x].stamp == s) {
          kill(id);
          continue;
        }
        verts[x].stamp = s;
        edge.v[edge.v[0] == x ? 1 : 0] = k;
        scratch_ids.push_back(id);
      }
    }
    lk.assign(scratch_ids.begin(), scratch_ids.end());
    std::vector<Index>().swap(lr);
    // Vertices left without faces leave the candidate set altogether.
    for (const Neighbour& n : nbrs) {
      if (verts[n.x].live_faces == 0) drop_virtual_pairs(n.x);
    }
    if (verts[k].live_faces == 0) drop_virtual_pairs(k);
  }

  void drop_virtual_pairs(Index v) {
    for (Index id : virtual_pairs[v]) {
      if (!edge_dead(id)) kill(id);
    }
    std::vector<Index>().swap(virtual_pairs[v]);
  }

  // Whether the blocked edges around v get another chance at this change of its neighbourhood. Around a
  // vertex of many faces, only at every (faces / kRetryFaces)-th change: each retry re-costs every blocked
  // edge of its fan, and each of those that comes up is checked against the whole fan again, so a fan of
  // thousands (a cone's apex, an edge shared by thousands of faces) made every collapse next to it cost
  // millions of steps and ran for minutes. Small fans, nearly all of them, retry at every change. (The run's
  // last resort, retrying every blocked edge when the queue runs dry, still covers them all.)
  static constexpr std::uint32_t kRetryFaces = 16;
  static constexpr std::uint32_t kMostRetryAsks = (1u << 24) - 1;  // retry_asks' range
  static bool retry_due(Vertex& v) {
    if (v.retry_asks < kMostRetryAsks) ++v.retry_asks;
    if (v.retry_asks * std::uint64_t{kRetryFaces} < v.live_faces && v.retry_asks < kMostRetryAsks)
      return false;
    v.retry_asks = 0;
    return true;
  }

  // Blocked edges around x get another chance now that x's neighbourhood changed (see retry_due).
  void retry_around(Index x) {
    Vertex& v = verts[x];
    if (!retry_due(v)) return;
    v.flags &= ~kHasBlocked;
    gather_faces(x, scratch_faces);
    for (Index f : scratch_faces) {
      const Face& face = faces[f];
      const int c = corner_of(face, x);
      for (Index id : {face.e[c], face.e[(c + 2) % 3]}) {
        if (edges[id].slot == kBlockedFlip || edges[id].slot == kBlockedTopology) recost(id);
      }
    }
    if (!virtual_pairs.empty()) {
      for (Index id : virtual_pairs[x]) {
        if (edges[id].slot == kBlockedFlip || edges[id].slot == kBlockedTopology) recost(id);
      }
    }
  }

  // ---------------------------------------------------------------- the first phase

  // Below this many faces the first phase does not pay: its setup and the seams it leaves cost about what a
  // second core saves.
  static constexpr std::uint64_t kFirstPhaseMinFaces = 16384;
  // Input faces per region, and bounds on the region count: enough regions to keep two cores busy through
  // the threshold rounds' uneven work, few enough that the seams stay a small part of the mesh.
  static constexpr std::uint64_t kFacesPerRegion = 32768;
  static constexpr std::size_t kMinRegions = 4, kMaxRegions = 64;
  // Passes of the first phase, each over its own partition (the second one's seams cross the first one's),
  // and the share of the collapses still to do that each does (see run_pass).
  static constexpr int kPasses = 2;
  static constexpr double kPassShare[kPasses] = {0.7, 0.97};
  // Rounds per pass, and the part of the pass's remaining collapses each round's key threshold aims at.
  static constexpr int kRounds = 6;
  static constexpr double kRoundPart = 0.6;

  // Regions are cut from a Morton order of a 2^kRegionBits-cells-a-side grid (see assign_regions).
  static constexpr int kRegionBits = 6;
  static constexpr std::uint32_t kRegionCells = 1u << (3 * kRegionBits);
  struct RegionScratch {
    std::vector<std::uint32_t> ids;    // per vertex: its cell, then its region (see kOutside)
    std::vector<std::uint32_t> cells;  // per cell: its vertex count, then its region
  };

  static std::size_t region_count(std::uint64_t faces) {
    std::size_t k = kMinRegions;
    while (k < kMaxRegions && (k + k / 2) * kFacesPerRegion < faces) k *= 2;
    return k;
  }

  // Decided by the mesh and the options, never by the thread count, so the output does not depend on it.
  bool use_first_phase() const {
    if (!virtual_pairs.empty() || stats.input_faces < kFirstPhaseMinFaces) return false;
    if (target_f > 0 && target_f >= faces_alive) return false;
    if (target_v > 0 && target_v >= verts_alive) return false;
    return true;
  }

  // Called once the targets are set: the global queue, after the first phase when it runs.
  void start() {
    compact_below = virtual_pairs.empty() ? stats.input_vertices / 2 : 0;
    if (!use_first_phase()) {
      build_heap();
      report(opt.progress, "decimate: setup", kSetupSteps, kSetupSteps);
      return;
    }
    parallel_chunks(edges.size(), 65536, [&](std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e) edges[e].slot = kPending;
    });
    // The region arrays serve both passes (vertices are only ever renumbered downwards): allocated once,
    // their pages are faulted in once.
    RegionScratch scratch;
    scratch.ids.resize(verts.size());
    for (int pass = 0; pass < kPasses; ++pass) run_pass(pass, scratch);
  }

  // Regions are ranges of a Morton order of the live vertices over a 64^3 grid of the bounding box, cut at
  // equal vertex counts; each pass shifts the grid and turns its axes, so the next pass's regions hold the
  // last one's seams. Returns the vertices per region.
  std::vector<std::uint64_t> assign_regions(int pass, std::size_t regions, RegionScratch& scratch) const {
    const std::size_t nv = verts.size();
    constexpr int kBits = kRegionBits;
    constexpr std::uint32_t kCells = kRegionCells, kSide = 1u << kBits;
    std::vector<std::uint32_t>& ids = scratch.ids;
    // Half a region's width, in cells, for a surface: a region covers about kSide^2 / regions cells of it.
    const double shift = pass == 0 ? 0.0 : 0.5 * kSide / std::sqrt(double(regions));
    const double scale = box_extent > 0 ? (kSide - shift) / box_extent : 0.0;
    std::uint32_t spread[kSide];  // bit i to bit 3i
    for (std::uint32_t x = 0; x < kSide; ++x) {
      spread[x] = 0;
      for (int i = 0; i < kBits; ++i) spread[x] |= ((x >> i) & 1u) << (3 * i);
    }
    const int turn[3] = {pass % 3, (1 + pass) % 3, (2 + pass) % 3};  // axis a's bit offset
    parallel_chunks(nv, 16384, [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v) {
        const Vertex& x = verts[v];
        if (x.live_faces == 0) {
          ids[v] = kCells;
          continue;
        }
        std::uint32_t code = 0;
        for (int a = 0; a < 3; ++a) {
          const double c = std::clamp((double(x.p[a]) - box_low[a]) * scale + shift, 0.0, double(kSide - 1));
          code |= spread[static_cast<std::uint32_t>(c)] << turn[a];
        }
        ids[v] = code;
      }
    });
    // Vertices per cell, then, in place, each cell's region. Most cells of a surface are empty and no vertex
    // reads them: a bit per cell marks the others, so the serial walk in cell order skips 64 empty cells at a
    // time (walking all 2^18 cells was about 1 % of a 70 k-triangle decimation's instructions).
    std::vector<std::uint32_t>& cells = scratch.cells;
    cells.assign(kCells + 1, 0u);
    // One word more than the walk reads: the vertices without faces (id kCells) set a bit in word
    // kCells / 64, which the walk leaves alone (their entry is set after it).
    std::vector<std::uint64_t> occupied(kCells / 64 + 1, 0);
    for (std::size_t v = 0; v < nv; ++v) {
      const std::uint32_t c = ids[v];
      ++cells[c];
      occupied[c / 64] |= std::uint64_t{1} << (c % 64);
    }
    std::vector<std::uint64_t> per_region(regions, 0);
    const std::uint64_t total = std::max<std::uint64_t>(1, verts_alive);
    std::uint64_t before = 0;
    for (std::uint32_t word = 0; word < kCells / 64; ++word) {
      for (std::uint64_t bits = occupied[word]; bits != 0; bits &= bits - 1) {
        const std::uint32_t c = word * 64 + static_cast<std::uint32_t>(std::countr_zero(bits));
        const std::uint32_t count = cells[c];
        // A cell goes to the region its middle vertex falls in.
        const std::uint64_t middle = before + count / 2;
        const auto r =
            static_cast<std::uint32_t>(std::min<std::uint64_t>(regions - 1, middle * regions / total));
        cells[c] = r;
        per_region[r] += count;
        before += count;
      }
    }
    cells[kCells] = kOutside;  // the vertices without faces
    parallel_chunks(nv, 16384, [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v) ids[v] = cells[ids[v]];
    });
    // Interior: every vertex it shares a live face with is in its region. A live face whose corners lie in
    // more than one region marks all three outside, in a second array, as the first is read meanwhile. One
    // pass over the faces: going through each vertex's face list read every face three times and was most of
    // this function's instructions. Threads may mark one vertex at once, all with the same value: relaxed
    // atomic stores (plain byte stores on x86).
    std::vector<std::uint8_t> outside(nv, 0);
    parallel_chunks(faces.size(), 16384, [&](std::size_t begin, std::size_t end) {
      for (std::size_t f = begin; f < end; ++f) {
        const Face& face = faces[f];
        if (face.v[0] == kNone) continue;
        const std::uint32_t r = ids[face.v[0]];
        if (ids[face.v[1]] == r && ids[face.v[2]] == r) continue;
        for (Index v : face.v) std::atomic_ref<std::uint8_t>(outside[v]).store(1, std::memory_order_relaxed);
      }
    });
    parallel_chunks(nv, 16384, [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v) ids[v] |= outside[v] ? kOutside : 0;
    });
    return per_region;
  }

  // The key a live pair has now: its entry's in the global queue, else costed now. Returns the state when it
  // is no candidate (dead, blocked, idle). Always inlined in build_region_heaps' loop over every edge: called
  // out of line, its register saves and restores were about 1 % of a bunny decimation's instructions.
  [[gnu::always_inline]] std::uint32_t current_key(Index e, float* key) {
    const std::uint32_t slot = edges[e].slot;
    if (slot < first_state) {
      *key = heap.entry(slot).key;
      return 0;
    }
    if (slot == kPending || slot == kDeferred) return key_of_edge(e, key);
    return slot;
  }

  // Each region's queue holds the pairs interior to it, in edge order, with their current keys (from the
  // global queue, which is then dropped); every other live pair is kPending.
  void build_region_heaps(std::vector<std::unique_ptr<Decimator>>& workers, const std::uint32_t* ids) {
    const std::size_t ne = edges.size(), regions = workers.size();
    constexpr std::size_t grain = 16384;
    const std::size_t chunks = (ne + grain - 1) / grain;
    std::vector<Index> count(chunks * regions, 0);
    // Pass 1: each candidate's key, kept in its slot as the float's bits until the entries are written (a
    // float that is not a NaN has bits below first_state), and the candidates per chunk and region.
    parallel_chunks(ne, grain, [&](std::size_t begin, std::size_t end) {
      Index* counts = count.data() + begin / grain * regions;
      for (std::size_t e = begin; e < end; ++e) {
        Edge& edge = edges[e];
        if (edge.slot == kDead) continue;
        const std::uint32_t r = ids[edge.v[0]];
        if (r != ids[edge.v[1]] || (r & kOutside)) {
          // Whatever its state: a collapse next to it may change it, and the region loops do not re-cost
          // it.
          edge.slot = kPending;
          continue;
        }
        float key = 0;
        const std::uint32_t state = current_key(static_cast<Index>(e), &key);
        if (state != 0) {
          edge.slot = state;
        } else {
          std::uint32_t bits;
          std::memcpy(&bits, &key, sizeof bits);
          edge.slot = bits;
          ++counts[r];
        }
      }
    });
    heap = EdgeHeap(nullptr, 3);
    std::vector<BigVector<HeapEntry>> entries(regions);
    for (std::size_t r = 0; r < regions; ++r) {
      Index running = 0;
      for (std::size_t c = 0; c < chunks; ++c) {
        const Index n = count[c * regions + r];
        count[c * regions + r] = running;
        running += n;
      }
      entries[r].resize(running);
    }
    parallel_chunks(ne, grain, [&](std::size_t begin, std::size_t end) {
      Index* cursor = count.data() + begin / grain * regions;
      for (std::size_t e = begin; e < end; ++e) {
        const Edge& edge = edges[e];
        if (edge.slot >= first_state) continue;
        const std::uint32_t r = ids[edge.v[0]];
        float key;
        std::memcpy(&key, &edge.slot, sizeof key);
        entries[r][cursor[r]++] = {key, static_cast<std::uint32_t>(e)};
      }
    });
    tbb::parallel_for(std::size_t{0}, regions, [&](std::size_t r) {
      workers[r]->heap = EdgeHeap(&edges[0].slot, 3);
      workers[r]->heap.assign(std::move(entries[r]));
    });
  }

  // One pass of phase 1: the live vertices are split into fixed spatial regions, and each region runs the
  // greedy loop over the pairs interior to it (both ends, and every vertex they share a face with, in the
  // region), all regions in parallel. Such a collapse writes only records of its own region's vertices. The
  // pass runs in rounds: each round collapses, in every region, the pairs whose key is at most a threshold
  // taken from the keys then queued, so cheap pairs go first everywhere as in one global queue; a region
  // also stops at its share of the pass's collapses. The pass ends with the global queue rebuilt.
  void run_pass(int pass, RegionScratch& scratch) {
    const std::size_t regions = region_count(stats.input_faces);
    const std::vector<std::uint64_t> per_region = assign_regions(pass, regions, scratch);
    const std::vector<std::uint32_t>& ids = scratch.ids;

    // The collapses the targets ask for in all, and this pass's part of those still to do. A pair with an end
    // on a seam waits for a later pass, so the part is taken of the share of the mesh the regions may change
    // (their interior vertices): taken of the whole mesh, it came out of the interiors alone, which on a
    // small mesh decimated far (seams about as large as the target) left them much coarser than the seams. On
    // a 20 k-triangle CAD part at 3 % that doubled the RMS distance and quadrupled the Hausdorff distance
    // against the single global queue; now both are within a few percent of it.
    // What is still to do is the smaller of two counts: the collapses asked for less those done, and what
    // the live counts still ask for. The first is the larger where collapses removed more than two faces
    // each (doubled faces), the second where they removed fewer (borders), and either way the smaller one
    // never takes the pass past the target.
    const double needed = collapses_needed();
    const double still = std::min(needed - double(stats.collapses), collapses_still_needed());
    std::uint64_t interior = 0;
    for (std::size_t v = 0; v < verts.size(); ++v) interior += (ids[v] & kOutside) == 0;
    const double budget = kPassShare[pass] * std::max(0.0, still) * double(interior) /
                          double(std::max<std::uint64_t>(1, verts_alive));
    const std::uint64_t faces0 = faces_alive, verts0 = verts_alive, boundary0 = boundary_edges;
    std::vector<std::unique_ptr<Decimator>> workers;
    for (std::size_t r = 0; r < regions; ++r) {
      auto w = std::make_unique<Decimator>(opt, storage);
      w->origin = origin;
      w->key_scale = key_scale;
      w->area_unit = area_unit;
      w->region_of = ids.data();
      w->region = static_cast<std::uint32_t>(r);
      w->faces_alive = faces0;
      w->verts_alive = verts0;
      w->boundary_edges = boundary0;
      w->stamp_now = stamp_now;
      w->applied_key = applied_key;
      // A region's share of the pass's removals, by its vertices; the shares add up to the pass's part.
      const double part = needed < std::numeric_limits<double>::infinity()
                              ? budget / needed * double(per_region[r]) / double(verts0)
                              : 0.0;
      // (Never 0, which would mean no target.)
      if (target_f > 0) {
        w->target_f = std::max<std::uint64_t>(
            1, faces0 - static_cast<std::uint64_t>(part * double(stats.input_faces - target_f)));
      }
      if (target_v > 0) {
        w->target_v = std::max<std::uint64_t>(
            1, verts0 - static_cast<std::uint64_t>(part * double(stats.input_vertices - target_v)));
      }
      workers.push_back(std::move(w));
    }
    build_region_heaps(workers, ids.data());
    if (pass == 0) report(opt.progress, "decimate: setup", kSetupSteps, kSetupSteps);

    const std::uint64_t expected = expected_collapses();
    std::uint64_t done = 0;
    RoundProgress progress(opt.progress, stats.collapses, expected);
    std::vector<float> sample;
    std::vector<std::pair<std::size_t, std::size_t>> order;  // (expected work, region)
    for (int round = 0; round < kRounds; ++round) {
      float threshold = std::numeric_limits<float>::infinity();
      if (needed < std::numeric_limits<double>::infinity()) {
        const double left = budget - double(done);
        if (left < 0.01 * needed) break;
        // About three queued pairs per collapse go at or below the threshold: the pair, and the two edges
        // merged into others.
        sample.clear();
        std::size_t queued = 0;
        for (const auto& w : workers) {
          if (w->region_done()) continue;
          queued += w->heap.size();
          for (std::size_t i = 0; i < w->heap.size(); i += 8) sample.push_back(w->heap.entry(i).key);
        }
        if (sample.empty()) break;
        // Regions that hold fewer queued pairs than three a collapse still to do have spent their cheap
        // pairs: the pairs left pending across their seams (uncosted until the global queue takes them)
        // may then be cheaper than any they hold, and their median key no longer stands for the mesh's.
        // Ten separate thin boxes of 17,600 faces, at 500 faces, had their corners cut at 2 % Hausdorff
        // (zero-cost pairs on the seams left for later); the global queue keeps them exact. On the shared
        // scans and generated ones the rounds never get there: the same bytes.
        if (double(queued) < 3 * left) break;
        // Never above the median queued key: without a threshold the regions would decimate evenly up to
        // their shares, wherever the detail is.
        const double rank = std::min(0.5, 3 * kRoundPart * left / double(queued)) * double(sample.size() - 1);
        const auto at = sample.begin() + static_cast<std::ptrdiff_t>(rank);
        std::nth_element(sample.begin(), at, sample.end());
        threshold = *at;
      }
      // The regions in order of their expected work this round (sampled queued pairs at or below the
      // threshold), largest first, taken by the threads as they free up: a long region then never starts
      // last while the other threads idle. The order only schedules; each region's work is its own.
      order.clear();
      for (std::size_t r = 0; r < regions; ++r) {
        const Decimator& w = *workers[r];
        if (w.region_done()) continue;
        // The sample starts at the top, so a region with nothing at or below the threshold counts 0.
        std::size_t expected_work = 0;
        for (std::size_t i = 0; i < w.heap.size(); i += 8) expected_work += w.heap.entry(i).key <= threshold;
        if (expected_work > 0) order.emplace_back(expected_work, r);
      }
      std::sort(order.begin(), order.end(), [](const auto& x, const auto& y) {
        return x.first != y.first ? x.first > y.first : x.second < y.second;
      });
      std::atomic<std::size_t> next{0};
      const int lanes = static_cast<int>(
          std::min<std::size_t>(order.size(), std::max(1, tbb::this_task_arena::max_concurrency())));
      tbb::parallel_for(0, lanes, [&](int) {
        for (std::size_t i = next++; i < order.size(); i = next++)
          workers[order[i].second]->run_region(threshold, progress);
      });
      done = 0;
      for (const auto& w : workers) done += w->stats.collapses;
      report(opt.progress, "decimate", stats.collapses + done,
             progress_total(expected, stats.collapses + done));
      if (threshold == std::numeric_limits<float>::infinity()) break;
    }

    for (const auto& w : workers) {
      stats.collapses += w->stats.collapses;
      stats.rejected_flip += w->stats.rejected_flip;
      stats.rejected_topology += w->stats.rejected_topology;
      stats.max_error = std::max(stats.max_error, w->stats.max_error);
      applied_key = std::max(applied_key, w->applied_key);
      faces_alive -= faces0 - w->faces_alive;
      verts_alive -= verts0 - w->verts_alive;
      boundary_edges += w->boundary_edges - boundary0;
      stamp_now = std::max(stamp_now, w->stamp_now);
      blocked.insert(blocked.end(), w->blocked.begin(), w->blocked.end());
    }
    build_global_heap(workers, ids.data());
    if (verts_alive <= compact_below) {
      compact();
      compact_below = verts_alive / 2;
    }
  }

  bool region_done() const {
    return (target_f > 0 && faces_alive <= target_f + 2) || (target_v > 0 && verts_alive <= target_v + 2);
  }

  // The total a progress report gives once `done` collapses are done of `expected`: never below what is
  // done, and 0 without a count target (only max_error), where a total of what is done read as finished.
  static std::uint64_t progress_total(std::uint64_t expected, std::uint64_t done) {
    return expected == 0 ? 0 : std::max(expected, done);
  }

  // The collapses of a round's regions, added up across threads as they go and reported by whichever
  // thread finds no other reporting: a round of a large mesh's regions can take seconds.
  struct RoundProgress {
    RoundProgress(const ProgressFn& f, std::uint64_t b, std::uint64_t e) : fn(f), before(b), expected(e) {}
    const ProgressFn& fn;
    std::uint64_t before, expected;  // collapses before the pass; expected in all
    std::atomic<std::uint64_t> done{0};
    std::mutex reporting;

    void add(std::uint64_t collapses) {
      const std::uint64_t now = done += collapses;
      if (!fn || !reporting.try_lock()) return;
      report(fn, "decimate", before + now, progress_total(expected, before + now));
      reporting.unlock();
    }
  };

  void run_region(float threshold, RoundProgress& progress) {
    constexpr std::uint64_t kReportEvery = 1024;
    std::uint64_t reported = stats.collapses;
    while (!heap.empty() && !region_done() && heap.top().key <= threshold) {
      try_top(false);
      if (stats.collapses - reported >= kReportEvery) {
        progress.add(stats.collapses - reported);
        reported = stats.collapses;
      }
    }
    progress.done += stats.collapses - reported;
  }

  // The global queue: the pairs still queued in the regions keep their keys; pending and deferred pairs are
  // costed now. In edge order, as build_heap. Keys wait in the slots as float bits (see build_region_heaps)
  // so the regions' queues are freed before the global one is allocated: both at once would add about 9
  // bytes per input triangle to the peak on a 10 M-triangle scan.
  void build_global_heap(std::vector<std::unique_ptr<Decimator>>& workers, const std::uint32_t* ids) {
    const std::size_t ne = edges.size();
    constexpr std::size_t grain = 16384;
    const std::size_t chunks = (ne + grain - 1) / grain;
    std::vector<Index> count(chunks, 0);
    parallel_chunks(ne, grain, [&](std::size_t begin, std::size_t end) {
      Index n = 0;
      for (std::size_t e = begin; e < end; ++e) {
        Edge& edge = edges[e];
        float key = 0;
        if (edge.slot < first_state) {
          key = workers[ids[edge.v[0]]]->heap.entry(edge.slot).key;
        } else if (edge.slot == kPending || edge.slot == kDeferred) {
          const std::uint32_t state = key_of_edge(static_cast<Index>(e), &key);
          if (state != 0) {
            edge.slot = state;
            continue;
          }
        } else {
          continue;
        }
        std::memcpy(&edge.slot, &key, sizeof key);
        ++n;
      }
      count[begin / grain] = n;
    });
    for (auto& w : workers) w->heap = EdgeHeap(nullptr, 3);
    Index total = 0;
    for (Index& n : count) {
      const Index c = n;
      n = total;
      total += c;
    }
    BigVector<HeapEntry> entries(total);
    parallel_chunks(ne, grain, [&](std::size_t begin, std::size_t end) {
      Index at = count[begin / grain];
      for (std::size_t e = begin; e < end; ++e) {
        const Edge& edge = edges[e];
        if (edge.slot >= first_state) continue;
        float key;
        std::memcpy(&key, &edge.slot, sizeof key);
        entries[at++] = {key, static_cast<std::uint32_t>(e)};
      }
    });
    heap = EdgeHeap(edges.empty() ? nullptr : &edges[0].slot, 3);
    heap.assign(std::move(entries));
  }

  // ---------------------------------------------------------------- result

  void explain() {
    stats.faces = faces_alive;
    stats.vertices = verts_alive;
    stats.target_faces = target_f;
    stats.target_vertices = target_v;
    const std::string reached_text =
        std::to_string(faces_alive) + " faces, " + std::to_string(verts_alive) + " vertices";
    if (reached()) {
      stats.target_reached = true;
      const bool below = target_f > 0 && faces_alive < target_f && stats.input_faces > target_f &&
                         !(target_v > 0 && verts_alive <= target_v);
      stats.stop = below ? DecimateStop::parity : DecimateStop::target_reached;
      // An input already within its target is left as it is, and says so.
      const bool already = stats.collapses == 0 && ((target_f > 0 && stats.input_faces <= target_f) ||
                                                    (target_v > 0 && stats.input_vertices <= target_v));
      stats.reason = "reached " + reached_text +
                     (below ? " (the face target " + std::to_string(target_f) +
                                  " is unreachable: no remaining collapse removes a single face)"
                      : already ? " (the input is already within the target: nothing was collapsed)"
                                : "");
      // With both count targets, whichever is met first stops the run: say which, as the other is not met.
      const bool faces_met = faces_alive <= target_f, vertices_met = verts_alive <= target_v;
      if (target_f > 0 && target_v > 0 && faces_met != vertices_met) {
        const std::string faces = "the face target " + std::to_string(target_f),
                          vertices = "the vertex target " + std::to_string(target_v);
        stats.reason += faces_met ? " (" + faces + " was met first; " + vertices + " was not)"
                                  : " (" + vertices + " was met first; " + faces + " was not)";
      }
      return;
    }
    // A blocked pair whose cost exceeds the error bound would not be collapsed without its guard either: it
    // counts as over the bound, so that a run stopped by the bound says so even where guards blocked others.
    const bool bounded = opt.max_error < std::numeric_limits<double>::infinity();
    auto over_bound = [&](Index e) {
      decimate_detail::RawQuadric q;
      Placement p;
      float key = 0;
      return bounded && evaluate_inline(e, &q, &p, &key, nullptr) == kIdleError;
    };
    std::uint64_t flip = 0, topology = 0, locked_pairs = 0, over = 0, deferred_left = 0;
    for (std::size_t e = 0; e < edges.size(); ++e) {
      const Edge& edge = edges[e];
      switch (edge.slot) {
        case kBlockedFlip:
          ++(over_bound(static_cast<Index>(e)) ? over : flip);
          break;
        case kBlockedTopology:
          ++(over_bound(static_cast<Index>(e)) ? over : topology);
          break;
        case kIdleLocked:
          ++locked_pairs;
          break;
        case kIdleError:
          ++over;
          break;
        case kDeferred:
          ++deferred_left;
          break;
        default:
          break;
      }
    }
    const bool count_target = target_f > 0 || target_v > 0;
    std::string target_text;
    if (target_f > 0) target_text += std::to_string(target_f) + " faces";
    if (target_v > 0)
      target_text += (target_text.empty() ? "" : " or ") + std::to_string(target_v) + " vertices";
    const std::string prefix =
        "stopped at " + reached_text + (count_target ? " (target " + target_text + ")" : "") + ": ";
    if (!count_target) {
      // The error bound is the only criterion, and it always holds: decimation went as far as it allows.
      stats.stop = DecimateStop::max_error;
      stats.target_reached = true;
      stats.reason = prefix + std::to_string(over) + " remaining candidates exceed the maximum error" +
                     (flip + topology + locked_pairs > 0
                          ? ", " + std::to_string(flip + topology + locked_pairs) + " are blocked by guards"
                          : "") +
                     (kept_last_faces ? ", and the last faces are kept" : "");
      return;
    }
    // With both criteria, the error bound is what stopped the run when candidates exceed it, as with the
    // bound alone: guards blocking a few others within it do not make it a guard's stop.
    if (over > 0) {
      stats.stop = DecimateStop::max_error;
      stats.target_reached = false;
      const std::uint64_t guarded = flip + topology + locked_pairs + deferred_left;
      stats.reason =
          prefix + (guarded == 0
                        ? "every remaining candidate (" + std::to_string(over) + ") exceeds the maximum error"
                        : std::to_string(over) + " remaining candidates exceed the maximum error, " +
                              std::to_string(guarded) + " are blocked by guards");
      return;
    }
    if (flip + topology + locked_pairs + deferred_left + over == 0) {
      stats.stop = DecimateStop::exhausted;
      stats.target_reached = false;
      stats.reason = prefix + "no candidate pair is left";
      return;
    }
    stats.stop = DecimateStop::blocked;
    stats.target_reached = false;
    std::string why;
    auto add = [&why](std::uint64_t n, const char* text) {
      if (n == 0) return;
      why += (why.empty() ? "" : ", ") + std::to_string(n) + " " + text;
    };
    add(flip, "would flip, degenerate or double a triangle");
    add(topology, "would break the link condition (--preserve-topology)");
    add(locked_pairs, "join two locked boundary vertices (--lock-boundary)");
    add(over, "exceed the maximum error");
    add(deferred_left, kept_last_faces ? "would remove the last faces or overshoot the target"
                                       : "would overshoot the target");
    stats.reason = prefix + "every remaining candidate is blocked: " + why;
  }

  // With `quadrics`, also each output vertex's quadric and its surface area (see QuadricMesh::areas).
  IndexedMesh output(std::vector<Quadric>* quadrics, std::vector<double>* areas) {
    IndexedMesh out;
    const std::size_t nv = verts.size();
    std::vector<Index> remap(nv);
    Index next = 0;
    for (std::size_t v = 0; v < nv; ++v) remap[v] = verts[v].live_faces > 0 ? next++ : kNone;
    out.positions.reserve(next);
    if (!normals.empty()) out.normals.reserve(next);
    if (!colors.empty()) out.colors.reserve(next);
    if (!uvs.empty()) out.uvs.reserve(next);
    for (std::size_t v = 0; v < nv; ++v) {
      if (remap[v] == kNone) continue;
      out.positions.emplace_back(verts[v].p[0], verts[v].p[1], verts[v].p[2]);
      if (!normals.empty()) out.normals.push_back(normals[v]);
      if (!colors.empty()) out.colors.push_back(colors[v]);
      if (!uvs.empty()) out.uvs.push_back(uvs[v]);
      if (quadrics) {
        quadrics->push_back(absolute(verts[v].q));
        areas->push_back(double(verts[v].area) * area_unit);
      }
    }
    out.triangles.reserve(faces_alive);
    std::vector<Index> origin_of;
    for (std::size_t f = 0; f < faces.size(); ++f) {
      const Face& t = faces[f];
      if (t.v[0] == kNone) continue;
      out.triangles.push_back({remap[t.v[0]], remap[t.v[1]], remap[t.v[2]]});
      if (storage.keeps_source) origin_of.push_back(storage.face_origin[f]);
    }
    if (storage.keeps_source) {
      // The run's records are done with: freed before the walks' own tables come on top of them (a 1 M-face
      // scan with normals and colors to 10 %: 188 MB at peak with them, 177 without).
      BigVector<Vertex>().swap(verts);
      BigVector<Face>().swap(faces);
      BigVector<Index>().swap(vf);
      BigVector<Edge>().swap(edges);
      std::vector<Index>().swap(storage.face_origin);
      stats.seam_copies = decimate_detail::restore_attributes(storage.seam_source, origin_of, out, quadrics,
                                                              areas, storage.seams);
    }
    return out;
  }
};

}  // namespace

namespace {

// Throws Error unless ratio is in (0, 1], naming it in full (1.0000001 printed as 1).
void check_ratio(double ratio) {
  if (ratio > 0 && ratio <= 1) return;
  char text[64];
  std::snprintf(text, sizeof text, "%.17g", ratio);
  throw Error(std::string("the ratio must be in (0, 1], not ") + text);
}

}  // namespace

std::uint64_t ratio_target(double ratio, std::uint64_t faces) {
  // A cast of a NaN, a negative or an out-of-range product to an integer is undefined.
  check_ratio(ratio);
  // In doubles, not through llround's signed 64 bits: a count past 2^63 came back as 2^63.
  const double target = std::round(ratio * static_cast<double>(faces));
  if (target >= static_cast<double>(faces)) return faces;
  return std::max<std::uint64_t>(1, static_cast<std::uint64_t>(target));
}

std::string separate_faces_note(const DecimateStats& stats, bool welded) {
  // Below a few faces, a mesh of separate triangles is likely meant (a test, a marker).
  // Both counts: a book's pages (faces on one shared edge) leave their tips on a single face each, but they
  // are not separate.
  if (stats.input_faces < 4 || 2 * stats.single_face_vertices <= stats.input_vertices ||
      2 * stats.separate_faces <= stats.input_faces)
    return "";
  return std::to_string(stats.single_face_vertices) + " of the " + std::to_string(stats.input_vertices) +
         " vertices each belong to a single face, as in a triangle soup: such faces decimate as separate "
         "pieces, each removed whole, so the surface falls apart" +
         (welded ? "" : "; without --no-weld, vertices at equal positions are joined first");
}

std::string nothing_to_decimate_reason(const DecimateStats& stats, bool welded) {
  if (stats.input_faces > 0 || stats.dropped_degenerate_faces == 0) return "";
  const std::uint64_t n = stats.dropped_degenerate_faces;
  return (n == 1 ? std::string("its one face has") : "all " + std::to_string(n) + " faces have") +
         " a repeated corner" +
         (welded && stats.welded_vertices > 0 ? " once vertices at equal positions are joined" : "") +
         ": nothing is left to simplify";
}

std::string dropped_faces_note(const DecimateStats& stats) {
  const std::uint64_t degenerate = stats.dropped_degenerate_faces, repeated = stats.dropped_repeated_faces;
  if (degenerate + repeated == 0 || stats.input_faces == 0) return "";  // none, or all (an error then)
  std::string note;
  if (degenerate > 0) {
    note = counted(degenerate, "face") + " with a repeated corner" +
           (stats.welded_vertices > 0 ? " (once vertices at equal positions are joined)" : "");
  }
  if (repeated > 0) {
    note += (note.empty() ? counted(repeated, "face") : " and " + std::to_string(repeated)) +
            " repeating another face's corners in the same order";
  }
  return note + (degenerate + repeated == 1 ? " was" : " were") + " left out";
}

const char* stop_name(DecimateStop stop) {
  switch (stop) {
    case DecimateStop::target_reached:
      return "target_reached";
    case DecimateStop::parity:
      return "parity";
    case DecimateStop::max_error:
      return "max_error";
    case DecimateStop::blocked:
      return "blocked";
    case DecimateStop::exhausted:
      return "exhausted";
  }
  return "unknown";
}

DecimateResult decimate(QuadricMesh input, const DecimateOptions& options) {
  // The values first, then whether they stop anything: a ratio of -0.5 or a NaN bound read as "no stopping
  // criterion".
  if (options.target_ratio != 0) check_ratio(options.target_ratio);
  if (!(options.max_error >= 0)) throw Error("decimate: the maximum error must be a distance >= 0");
  // Finite too: an infinite border weight made every border quadric infinite, the reported error smaller
  // than the real one, and the output quadrics unusable for a next level; an infinite attribute weight times
  // a zero difference is NaN.
  auto finite = [](double x) { return x >= 0 && x < std::numeric_limits<double>::infinity(); };
  if (!finite(options.pair_distance) || !finite(options.boundary_weight) || !finite(options.shape_weight) ||
      !finite(options.attribute_weight)) {
    throw Error("decimate: the pair distance and the weights must be finite and >= 0");
  }
  if (!input.mesh.origin.allFinite()) throw Error("decimate: the mesh's origin is not a finite point");
  const bool has_count = options.target_faces > 0 || options.target_vertices > 0 || options.target_ratio > 0;
  if (!has_count && !(options.max_error < std::numeric_limits<double>::infinity())) {
    throw Error("decimate: no stopping criterion (give a face, vertex or ratio target, or a maximum error)");
  }
  Storage storage;
  Decimator d(options, storage);
  tbb::task_arena arena(worker_threads(options.threads));
  arena.execute([&] { d.build(input); });
  d.target_f = options.target_faces;
  if (options.target_ratio > 0) {
    const std::uint64_t by_ratio = ratio_target(options.target_ratio, d.stats.input_faces);
    d.target_f = d.target_f > 0 ? std::min(d.target_f, by_ratio) : by_ratio;
  }
  d.target_v = options.target_vertices;
  arena.execute([&] { d.start(); });
  arena.execute([&] { d.run(); });  // its compactions run in parallel
  d.explain();
  DecimateResult result;
  result.mesh =
      options.output_quadrics ? d.output(&result.quadrics, &result.areas) : d.output(nullptr, nullptr);
  result.mesh.origin = input.mesh.origin;  // build() took the arrays, not the frame they are in
  result.stats = d.stats;
  return result;
}

}  // namespace ocsimp
