// The single pass over the input.
//
// Parallel scheme: the cells are split among owners (indexed input: runs of the Morton-ordered cell numbers,
// a few owners per thread so that TBB can balance them; soups: blocks of cells hashed to one owner per
// thread). An owner adds contributions to its own cells only, in input order, so every cell's sums are
// taken in the same order whatever the thread count and the output is the same bytes for 1 or N threads -
// which the "chunks merged in chunk order" would also give, but at the price of one partial copy of
// the cells per chunk in flight. Here no per-thread copies exist: memory stays at one set of cells. A
// triangle whose corners belong to two owners is computed by both (identically); that is a few per cent.
//
// Indexed input: the vertex array is visited first. Each vertex's cell is resolved once (a hash lookup per
// vertex instead of per corner: the lookups are what this stage spends its time on) and written back into
// the vertex's own 12 bytes together with its position inside the cell, quantized to 2^-21 of a cell per
// axis - finer than the float input itself for any grid of 4 or more cells. The face loop then reaches a
// corner's cell by index, with no hashing, and rebuilds the corner's position from the cell and the offset.
// Each batch's corners are gathered once, in parallel, and its triangles listed per owner.
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_group.h>

#ifdef __linux__
#include <sys/mman.h>
#include <unistd.h>
#endif
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <optional>
#include <string>

#include "cells.h"
#include "ocsimp/core/error.h"

namespace ocsimp::cluster_detail {
namespace {

// ---- Packed vertices -------------------------------------------------------------------------------------

constexpr double kQuantum = static_cast<double>(1u << 21);
constexpr std::uint64_t kQuantumMax = (1u << 21) - 1;
static_assert(sizeof(Vec3f) == 12, "packed vertices reuse a position's 12 bytes");

std::uint64_t quantize(const Vec3d& local) {
  std::uint64_t q = 0;
  for (int a = 0; a < 3; ++a) {
    const double s = local[a] * kQuantum;
    std::uint64_t v = 0;
    if (s >= static_cast<double>(kQuantumMax)) {
      v = kQuantumMax;
    } else if (s > 0.0) {
      v = static_cast<std::uint64_t>(s + 0.5);
    }
    q |= v << (21 * a);
  }
  return q;
}
// (Through int32: converting an unsigned 64-bit integer to double costs a branch on x86-64 before AVX-512.)
Vec3d dequantize(std::uint64_t q) {
  return Vec3d(static_cast<double>(static_cast<std::int32_t>(q & kQuantumMax)),
               static_cast<double>(static_cast<std::int32_t>((q >> 21) & kQuantumMax)),
               static_cast<double>(static_cast<std::int32_t>((q >> 42) & kQuantumMax))) *
         (1.0 / kQuantum);
}
void pack(Vec3f& slot, std::uint32_t cell, std::uint64_t q) {
  const std::uint32_t words[3] = {cell, static_cast<std::uint32_t>(q), static_cast<std::uint32_t>(q >> 32)};
  std::memcpy(slot.data(), words, sizeof words);
}
void unpack(const Vec3f& slot, std::uint32_t& cell, std::uint64_t& q) {
  // Two direct loads: copying the 12 bytes to a temporary and reading it back stalls on store forwarding.
  const char* bytes = reinterpret_cast<const char*>(slot.data());
  std::memcpy(&cell, bytes, 4);
  std::memcpy(&q, bytes + 4, 8);
}

// Returns the whole pages inside [begin, end) to the system; their contents read as zeros afterwards. For
// arrays whose data is dead but whose owner frees them only later.
void release_pages(const void* begin, const void* end) {
#ifdef __linux__
  const std::uintptr_t page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
  const std::uintptr_t lo = (reinterpret_cast<std::uintptr_t>(begin) + page - 1) / page * page;
  const std::uintptr_t hi = reinterpret_cast<std::uintptr_t>(end) / page * page;
  if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED);
#else
  (void)begin;
  (void)end;
#endif
}

// ---- Cell sums ------------------------------------------------------------------------------------------

// What the face loop adds to per cell, in one record of two cache lines: a triangle that touches a cell
// updates its quadric and, if it crosses a cell face, its border planes, and separate arrays would cost
// separate cache misses.
struct alignas(64) CellRecord {
  Quadric quadric;
  BorderSums border;
};
static_assert(sizeof(CellRecord) == 128, "a cell record is two cache lines");

// The sums one owner adds to; indexed input has one shared store (owners touch disjoint cells), soups one
// store per owner.
struct CellStore {
  std::vector<CellRecord> records;
  ZeroedVector<std::uint32_t> points;
  ZeroedVector<Vec3f> point_sum;

  Quadric& quadric(std::uint32_t i) { return records[i].quadric; }
  BorderSums& border(std::uint32_t i) { return records[i].border; }
  // Marks the cell as touched by a triangle, after its contribution is added. A touched cell's quadric has a
  // positive trace (every proper triangle adds its area to it); one touched only by zero-area triangles
  // carries the mark in the sign of its zero constant term instead of a byte of its own.
  void touch(std::uint32_t i) {
    Quadric& q = records[i].quadric;
    if (!(q.a00 + q.a11 + q.a22 > 0.0)) q.c = -0.0;
  }
  static bool touched(const Quadric& q) { return q.a00 + q.a11 + q.a22 > 0.0 || std::signbit(q.c); }

  void push_back() {
    records.emplace_back();
    points.push_back(0);
    point_sum.emplace_back(Vec3f::Zero());
  }
  // Hands the sums over to `cells` in its layout (arrays per field).
  void move_into(FineCells& cells, bool with_border) {
    const std::size_t n = records.size();
    cells.quadrics.resize(n);
    if (with_border) cells.border.resize(n);
    cells.touched.resize(n);
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
      Quadric& q = records[i].quadric;
      cells.touched[i] = touched(q) ? 1 : 0;
      if (q.c == 0.0) q.c = 0.0;  // drops the mark's sign
      cells.quadrics[i] = q;
      if (with_border) cells.border[i] = records[i].border;
    });
    records = {};
    cells.points = std::move(points);
    cells.point_sum = std::move(point_sum);
  }
};

// The area-weighted plane quadric of a triangle with unnormalized normal c (|c| = twice the area) and
// offset dc = -c . p0: every coefficient is a product of c and dc over 2|c|, so one square root and one
// division serve all ten. Kept as plain numbers so that adding it to a cell is ten adds.
struct TriangleQuadric {
  double v[10];
  // `s` = 1 / (2 |c|).
  TriangleQuadric(const Vec3d& c, double dc, double s) {
    const double x = c.x(), y = c.y(), z = c.z();
    const double sx = s * x, sy = s * y, sz = s * z, sd = s * dc;
    v[0] = sx * x;
    v[1] = sx * y;
    v[2] = sx * z;
    v[3] = sy * y;
    v[4] = sy * z;
    v[5] = sz * z;
    v[6] = sd * x;
    v[7] = sd * y;
    v[8] = sd * z;
    v[9] = sd * dc;
  }
  void add_to(Quadric& q, int multiplicity) const {
    if (multiplicity == 1) {
      q.a00 += v[0], q.a01 += v[1], q.a02 += v[2], q.a11 += v[3], q.a12 += v[4], q.a22 += v[5];
      q.b0 += v[6], q.b1 += v[7], q.b2 += v[8], q.c += v[9];
    } else {
      const double m = multiplicity;
      q.a00 += m * v[0], q.a01 += m * v[1], q.a02 += m * v[2], q.a11 += m * v[3], q.a12 += m * v[4],
          q.a22 += m * v[5];
      q.b0 += m * v[6], q.b1 += m * v[7], q.b2 += m * v[8], q.c += m * v[9];
    }
  }
};

int dominant_axis(const Vec3d& e) {
  const double x = std::abs(e.x()), y = std::abs(e.y()), z = std::abs(e.z());
  if (x >= y && x >= z) return 0;
  return y >= z ? 1 : 2;
}

// One triangle as the owners see it: corners, their cells, and the triangle's normal.
struct Facet {
  Vec3d p[3];      // corner positions
  Vec3d local[3];  // corner positions in their cells' frames (cell units from each cell's lower corner)
  CellKey key[3];
  std::uint32_t index[3];  // the corners' cells in the owner's store (valid where owned)
  unsigned own;            // bit k: this owner holds corner k's cell
  Vec3d cross;             // (p1 - p0) x (p2 - p0)
  double inverse_length;   // 1 / |cross|, 0 for a degenerate triangle

  void set_normal() { cross = (p[1] - p[0]).cross(p[2] - p[0]); }
};

// 1 / |cross| for a block of facets, apart from the rest of the work: the square roots and divisions
// pipeline back to back instead of each stalling a triangle's dependency chain.
void set_inverse_lengths(Facet* facets, int count) {
  for (int i = 0; i < count; ++i) {
    const double squared = facets[i].cross.squaredNorm();
    const bool proper = squared > 0.0 && squared <= std::numeric_limits<double>::max();
    facets[i].inverse_length = proper ? 1.0 / std::sqrt(squared) : 0.0;
  }
}

// Adds one triangle to the cells among its corners' that this owner holds.
void contribute(const Facet& f, CellStore& store, const Grid& grid, bool boundary) {
  // A zero-area triangle adds no quadric (and no border planes: it has no normal), but still touches.
  const bool proper = f.inverse_length > 0.0;
  const TriangleQuadric q(f.cross, -f.cross.dot(f.p[0]), 0.5 * f.inverse_length);
  for (int k = 0; k < 3; ++k) {
    if (!(f.own & (1u << k))) continue;
    // Each distinct cell once, with its corner count.
    if ((k >= 1 && f.key[k] == f.key[0]) || (k == 2 && f.key[2] == f.key[1])) continue;
    int multiplicity = 1;
    for (int j = k + 1; j < 3; ++j) multiplicity += f.key[j] == f.key[k];
    const std::uint32_t i = f.index[k];
    if (proper) q.add_to(store.quadric(i), multiplicity);
    store.touch(i);
  }
  if (!boundary || !proper) return;
  const Vec3d n = f.cross * f.inverse_length;
  for (int k = 0; k < 3; ++k) {
    const int a = k, b = k == 2 ? 0 : k + 1;
    if (f.key[a] == f.key[b] || !(f.own & ((1u << a) | (1u << b)))) continue;
    // The two half-edges of an interior edge compute e with exactly opposite bits and the midpoint in each
    // end's frame with exactly equal bits, so their planes cancel up to the difference of the two
    // triangles' normals.
    const Vec3d e = f.p[b] - f.p[a];
    const double e_squared = e.squaredNorm();
    if (!(e_squared > 0.0)) continue;
    const Vec3d m = e.cross(n) * (1.0 / std::sqrt(e_squared));
    const Vec3d half = (0.5 * grid.inverse_cell) * e;
    const int slot = dominant_axis(e);
    const Vec3f mf = m.cast<float>();
    if (f.own & (1u << a)) {
      std::array<float, 4>& s = store.border(f.index[a]).slot[slot];
      s[0] += mf.x(), s[1] += mf.y(), s[2] += mf.z();
      s[3] += static_cast<float>(-m.dot(f.local[a] + half));
    }
    if (f.own & (1u << b)) {
      std::array<float, 4>& s = store.border(f.index[b]).slot[slot];
      s[0] += mf.x(), s[1] += mf.y(), s[2] += mf.z();
      s[3] += static_cast<float>(-m.dot(f.local[b] - half));
    }
  }
}

constexpr unsigned kOwnersPerThread = 4;

// One owner's surviving triangles: appended as they come (a hash set would cost a cache miss per triangle
// in the face loop), sorted and merged whenever the log fills, so memory stays proportional to the distinct
// triangles however often they repeat.
class TriangleLog {
 public:
  explicit TriangleLog(std::size_t expected) : limit_(std::max<std::size_t>(4096, expected)) {}
  void add(const CellTriangle& t) {
    items_.push_back(t);
    if (items_.size() >= limit_) {
      merge_repeats(items_);
      limit_ = std::max(limit_, 2 * items_.size());
    }
  }
  CellTriangles& items() { return items_; }

  // Sorts and merges repeated triangles, joining their orientation flags.
  static void merge_repeats(CellTriangles& v) {
    std::sort(v.begin(), v.end());
    merge_sorted_repeats(v);
  }
  static void merge_sorted_repeats(CellTriangles& v) {
    std::size_t out = 0;
    for (std::size_t i = 0; i < v.size(); ++out) {
      CellTriangle t = v[i];
      for (++i; i < v.size() && v[i].same_cells(t); ++i) t.merge_flags(v[i]);
      v[out] = t;
    }
    v.resize(out);
  }

 private:
  CellTriangles items_;
  std::size_t limit_;
};

// Reads the next batch on one task while the current one is prepared (`prepare(batch)`, which may run its
// own parallel loop) and then processed by every owner (`process(batch, owner)`).
template <class Prepare, class Process>
std::uint64_t run_batches(TriangleStream& stream, unsigned owners, const ProgressFn& progress,
                          Prepare&& prepare, Process&& process) {
  TriangleBatch current, next;
  std::uint64_t triangles = 0;
  bool have = stream.next(current);
  while (have) {
    bool have_next = false;
    tbb::task_group reader;
    reader.run([&] { have_next = stream.next(next); });
    std::exception_ptr failure;
    try {
      prepare(current);
      tbb::parallel_for(0u, owners, [&](unsigned owner) { process(current, owner); });
    } catch (...) {
      failure = std::current_exception();
    }
    reader.wait();
    if (failure) std::rethrow_exception(failure);
    triangles += current.size();
    report(progress, "cluster: faces", stream.bytes_read(), stream.bytes_total());
    std::swap(current, next);
    have = have_next;
  }
  return triangles;
}

std::uint64_t demorton_bits(std::uint64_t v) {
  v &= 0x1249249249249249ull;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ull;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00full;
  v = (v ^ (v >> 8)) & 0x1f0000ff0000ffull;
  v = (v ^ (v >> 16)) & 0x1f00000000ffffull;
  v = (v ^ (v >> 32)) & 0x1fffff;
  return v;
}
CellKey key_of_morton(std::uint64_t code) {
  return make_key(demorton_bits(code), demorton_bits(code >> 1), demorton_bits(code >> 2));
}

void check_cell_count(std::size_t cells) {
  if (cells >= (std::size_t{1} << 31)) {
    throw Error("more than 2^31 occupied cells: use a coarser grid");
  }
}

// ---- Indexed input ---------------------------------------------------------------------------------------

// A small direct-mapped cache of cell lookups. Vertices come in runs along the surface, so most of them land
// in a cell one of the last few hundred did; the cache answers those from L1/L2 instead of a hash table of
// every cell (a cache miss each).
class RecentCells {
 public:
  RecentCells() { slots_.fill({kNoKey, 0}); }
  std::uint32_t find(CellKey key) const {
    const Slot& s = slots_[slot(key)];
    return s.key == key ? s.value : CellMap::kMissing;
  }
  void remember(CellKey key, std::uint32_t value) { slots_[slot(key)] = {key, value}; }

 private:
  struct Slot {
    CellKey key;
    std::uint32_t value;
  };
  static std::size_t slot(CellKey key) { return (key * 0x9E3779B97F4A7C15ull) >> 52; }
  std::array<Slot, 4096> slots_;
};

// Morton codes of the distinct cells of `positions`, ascending. False when more than `cap` (0: no cap) turn
// up in one thread's share, which stops the count early.
bool distinct_cells(const std::string& path, const std::vector<Vec3f>& positions, const Grid& grid,
                    std::size_t cap, std::vector<std::uint64_t>& codes) {
  // Each task dedupes its range of vertices in a small set that stays in cache, then hands the range's
  // Morton codes to its thread's list; a thread sorts and dedupes its list whenever it doubles. One big set
  // instead would cost a cache miss per new run of vertices.
  struct Found {
    std::vector<std::uint64_t> codes;
    std::size_t compact_at = std::size_t{1} << 20;
  };
  tbb::enumerable_thread_specific<Found> found;
  std::atomic<bool> over{false};
  std::atomic<std::size_t> first_bad{positions.size()};
  auto compact = [](std::vector<std::uint64_t>& v) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, positions.size(), 1 << 18),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      if (over.load(std::memory_order_relaxed)) return;
                      KeySet set(std::size_t{1} << 13);
                      RecentCells recent;
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const Vec3d p = positions[i].cast<double>();
                        if (!p.allFinite()) {
                          std::size_t seen = first_bad.load();
                          while (i < seen && !first_bad.compare_exchange_weak(seen, i)) {
                          }
                          continue;
                        }
                        const CellKey key = grid.locate(p);
                        if (recent.find(key) == CellMap::kMissing) {
                          set.insert(key);
                          recent.remember(key, 0);
                        }
                      }
                      Found& mine = found.local();
                      set.for_each([&](CellKey key) { mine.codes.push_back(morton(key)); });
                      if (mine.codes.size() >= mine.compact_at) {
                        compact(mine.codes);
                        mine.compact_at = std::max(mine.compact_at, 2 * mine.codes.size());
                        if (cap && mine.codes.size() > cap) over = true;
                      }
                    });
  if (first_bad.load() < positions.size()) {
    throw Error(path, {}, "vertex " + std::to_string(first_bad.load()) + " has a non-finite coordinate");
  }
  if (over) return false;
  std::size_t total = 0;
  for (const Found& f : found) total += f.codes.size();
  codes.clear();
  codes.reserve(total);
  for (Found& f : found) {
    codes.insert(codes.end(), f.codes.begin(), f.codes.end());
    f.codes = {};
  }
  tbb::parallel_sort(codes.begin(), codes.end());
  codes.erase(std::unique(codes.begin(), codes.end()), codes.end());
  return !(cap && codes.size() > cap);
}

// Picks the grid (for target-driven modes, the power-of-two level) and returns its cells' Morton codes.
std::vector<std::uint64_t> choose_cells(const std::string& path, const std::vector<Vec3f>& positions,
                                        const Box3& bounds, const PassOptions& options, Grid& grid) {
  std::vector<std::uint64_t> codes;
  if (options.target_cells == 0 || grid.level < 0) {
    distinct_cells(path, positions, grid, 0, codes);
    return codes;
  }
  const double target = static_cast<double>(options.target_cells);
  int level = grid.level;
  for (int attempt = 0;; ++attempt) {
    grid = Grid::power_of_two(bounds, level);
    const std::size_t cap = static_cast<std::size_t>(std::min(8 * target + 1024, 4e9));
    if (!distinct_cells(path, positions, grid, cap, codes)) {
      if (level == 0) break;  // cannot happen: one cell
      level = std::max(0, level - 2);
      continue;
    }
    // Halving the grid merges each group of up to 8 siblings, which are contiguous in Morton order.
    while (codes.size() > 2 * target && grid.level > 0) {
      for (std::uint64_t& c : codes) c >>= 3;
      codes.erase(std::unique(codes.begin(), codes.end()), codes.end());
      grid = grid.coarser();
    }
    level = grid.level;
    const double count = static_cast<double>(codes.size());
    // Far too few cells: refine once or twice if the input has the vertices to fill them. A surface's
    // occupied cells grow about 4x per level.
    if (attempt < 2 && count < target / 8 && count < positions.size() / 4.0 && level < kCoordBits) {
      level = std::min(
          kCoordBits,
          level + std::max(1, static_cast<int>(std::lround(std::log(target / count) / std::log(4.0)))));
      continue;
    }
    break;
  }
  return codes;
}

// Surviving triangles of all owners in one array sized up front: each owner claims blocks of it, so the
// face loop appends without hashing (a hash set costs a cache miss per triangle) and without per-owner
// vectors that would have to be concatenated (a second copy at the memory peak). An owner that finds the
// array full keeps a private log instead, compacted whenever it fills.
class TriangleBuffer {
 public:
  static constexpr std::size_t kBlock = 4096;
  static constexpr CellTriangle kUnused{~std::uint32_t{0}, ~std::uint32_t{0}, ~std::uint32_t{0}};

  TriangleBuffer(std::size_t expected, unsigned owners) : items_(expected + kBlock * owners) {
    for (unsigned t = 0; t < owners; ++t) overflow_.emplace_back(kBlock);
  }

  struct Cursor {
    std::size_t next = 0, end = 0;
  };
  void add(Cursor& cursor, unsigned owner, const CellTriangle& t) {
    if (cursor.next == cursor.end) {
      const std::size_t start = claimed_.fetch_add(kBlock, std::memory_order_relaxed);
      if (start + kBlock <= items_.size()) {
        cursor.next = start;
        cursor.end = start + kBlock;
      }
    }
    if (cursor.next < cursor.end) {
      items_[cursor.next++] = t;
    } else {
      overflow_[owner].add(t);
    }
  }
  // The distinct triangles, sorted, their orientation flags merged. `cursors`: each owner's last one.
  CellTriangles finish(const std::vector<Cursor>& cursors) {
    for (const Cursor& c : cursors) std::fill(items_.begin() + c.next, items_.begin() + c.end, kUnused);
    items_.resize(std::min(items_.size(), claimed_.load()));
    for (TriangleLog& log : overflow_) {
      items_.insert(items_.end(), log.items().begin(), log.items().end());
      log.items() = {};
    }
    tbb::parallel_sort(items_.begin(), items_.end());
    while (!items_.empty() && items_.back().a == kUnused.a) items_.pop_back();
    TriangleLog::merge_sorted_repeats(items_);
    return std::move(items_);
  }

 private:
  CellTriangles items_;
  std::atomic<std::size_t> claimed_{0};
  std::vector<TriangleLog> overflow_;
};

FineCells accumulate_indexed(TriangleStream& stream, const PassOptions& options) {
  IndexedMesh& vertices = stream.scratch_vertices();
  std::vector<Vec3f>& positions = vertices.positions;
  const std::size_t vertex_count = positions.size();
  // More owners than threads: TBB then balances the owners' uneven shares (and the reader's task) over the
  // threads. Any number of owners gives the same sums, each cell's taken in input order.
  const unsigned owners = std::max(1u, options.threads) * kOwnersPerThread;
  const Box3 bounds = stream.bounds();

  FineCells cells;
  cells.grid = options.grid;
  cells.input_vertices = vertex_count;
  std::vector<std::uint64_t> codes = choose_cells(stream.path(), positions, bounds, options, cells.grid);
  const Grid grid = cells.grid;
  check_cell_count(codes.size());
  const std::size_t count = codes.size();
  cells.keys.resize(count);
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t i) { cells.keys[i] = key_of_morton(codes[i]); });
  codes = {};

  // Vertex pass: resolve each vertex's cell once and pack it, with the vertex's offset inside the cell, into
  // the vertex's own 12 bytes. Each vertex is read and written by the same task.
  {
    CellMap map(count);
    bool inserted;
    for (std::size_t i = 0; i < count; ++i)
      map.insert(cells.keys[i], static_cast<std::uint32_t>(i), inserted);
    constexpr std::size_t kChunk = 1 << 20;
    for (std::size_t start = 0; start < vertex_count; start += kChunk) {
      const std::size_t end = std::min(vertex_count, start + kChunk);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(start, end, 1 << 18),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          RecentCells recent;
                          for (std::size_t v = r.begin(); v != r.end(); ++v) {
                            Vec3d local;
                            const CellKey key = grid.locate(positions[v].cast<double>(), local);
                            std::uint32_t cell = recent.find(key);
                            if (cell == CellMap::kMissing) {
                              cell = map.find(key);
                              recent.remember(key, cell);
                            }
                            pack(positions[v], cell, quantize(local));
                          }
                        });
      report(options.progress, "cluster: vertices", end, vertex_count);
    }
  }

#ifdef __GLIBC__
  // The temporaries above (per-thread key sets, the key -> cell map) were freed into the heap; give their
  // pages back before the face pass, the memory peak, allocates its own.
  malloc_trim(0);
#endif
  // Face pass. Owners hold equal runs of the Morton-ordered cells: about equal shares of the surface.
  CellStore store;
  store.records.resize(count);
  std::vector<std::uint32_t> owner_bounds(owners + 1);
  for (unsigned t = 0; t <= owners; ++t) owner_bounds[t] = static_cast<std::uint32_t>(count * t / owners);
  // About two distinct triangles per cell on a closed surface; repeats are few when cells are much larger
  // than triangles.
  TriangleBuffer triangles(count * 23 / 10, owners);
  std::vector<TriangleBuffer::Cursor> cursors(owners);
  std::vector<std::uint64_t> survivors(owners, 0);
  const Vec3f* packed = positions.data();
  const std::string& path = stream.path();
  // Each batch's corners are gathered once, in parallel, into a flat array the owners then scan in order:
  // otherwise every owner would chase the same random vertex reads.
  struct Gathered {
    std::uint64_t q[3];
    std::uint32_t cell[3];
  };
  std::vector<Gathered> gathered;
  // Each gathered triangle is listed for the owners of its corners' cells, per fixed slice of the batch, so
  // an owner visits only its own triangles, in input order.
  constexpr std::size_t kSlices = 32;
  std::vector<std::vector<std::uint32_t>> listed(kSlices * owners);
  auto owner_of = [&](std::uint32_t cell) {
    return static_cast<unsigned>(std::upper_bound(owner_bounds.begin() + 1, owner_bounds.end() - 1, cell) -
                                 (owner_bounds.begin() + 1));
  };
  auto gather = [&](const TriangleBatch& batch) {
    if (!batch.corners.empty()) throw Error(path, {}, "an indexed stream delivered a triangle soup batch");
    const std::size_t n = batch.triangles.size();
    gathered.resize(n);
    const std::size_t slice = (n + kSlices - 1) / kSlices;
    tbb::parallel_for(std::size_t{0}, kSlices, [&](std::size_t s) {
      for (unsigned t = 0; t < owners; ++t) listed[s * owners + t].clear();
      for (std::size_t i = s * slice; i < std::min(n, (s + 1) * slice); ++i) {
        const Triangle& t = batch.triangles[i];
        Gathered& g = gathered[i];
        for (int k = 0; k < 3; ++k) {
          if (t[k] >= vertex_count) {
            throw Error(path, {},
                        "a triangle refers to vertex " + std::to_string(t[k]) + " of " +
                            std::to_string(vertex_count));
          }
          unpack(packed[t[k]], g.cell[k], g.q[k]);
        }
        const unsigned o0 = owner_of(g.cell[0]), o1 = owner_of(g.cell[1]), o2 = owner_of(g.cell[2]);
        const auto index = static_cast<std::uint32_t>(i);
        listed[s * owners + o0].push_back(index);
        if (o1 != o0) listed[s * owners + o1].push_back(index);
        if (o2 != o0 && o2 != o1) listed[s * owners + o2].push_back(index);
      }
    });
  };
  cells.input_triangles =
      run_batches(stream, owners, options.progress, gather, [&](const TriangleBatch&, unsigned owner) {
        const std::uint32_t lo = owner_bounds[owner], span = owner_bounds[owner + 1] - lo;
        TriangleBuffer::Cursor& cursor = cursors[owner];
        std::uint64_t survived = 0;
        // Each triangle's contributions are added before the next triangle's: a cell's sums then run in
        // input order whatever the owners are.
        for (std::size_t s = 0; s < kSlices; ++s) {
          for (const std::uint32_t i : listed[s * owners + owner]) {
            const Gathered& g = gathered[i];
            const std::uint32_t(&cell)[3] = g.cell;
            if (cell[0] == cell[1] && cell[1] == cell[2]) {
              // Most triangles lie inside one cell: one key, no border crossing, no survivor. In cell units
              // the corners are small numbers: the cross product loses nothing to cancellation.
              const Vec3d l0 = dequantize(g.q[0]);
              const Vec3d cross =
                  (grid.cell * grid.cell) * (dequantize(g.q[1]) - l0).cross(dequantize(g.q[2]) - l0);
              const double squared = cross.squaredNorm();
              if (squared > 0.0 && squared <= std::numeric_limits<double>::max()) {
                const double offset = -cross.dot(grid.cell_origin(cells.keys[cell[0]]) + grid.cell * l0);
                TriangleQuadric(cross, offset, 0.5 / std::sqrt(squared)).add_to(store.quadric(cell[0]), 3);
              }
              store.touch(cell[0]);
              continue;
            }
            Facet f;
            f.own = static_cast<unsigned>(cell[0] - lo < span) |
                    static_cast<unsigned>(cell[1] - lo < span) << 1 |
                    static_cast<unsigned>(cell[2] - lo < span) << 2;
            for (int k = 0; k < 3; ++k) {
              f.index[k] = cell[k];
              f.key[k] = cells.keys[cell[k]];
              f.local[k] = dequantize(g.q[k]);
              f.p[k] = grid.cell_origin(f.key[k]) + grid.cell * f.local[k];
            }
            f.set_normal();
            set_inverse_lengths(&f, 1);
            contribute(f, store, grid, options.boundary);
            if (cell[0] != cell[1] && cell[1] != cell[2] && cell[2] != cell[0]) {
              const std::uint32_t first = std::min(cell[0], std::min(cell[1], cell[2]));
              if (first - lo < span) {
                triangles.add(cursor, owner, CellTriangle::of(cell[0], cell[1], cell[2]));
                ++survived;
              }
            }
          }
        }
        survivors[owner] += survived;
      });
  gathered = {};
  for (unsigned t = 0; t < owners; ++t) cells.surviving_instances += survivors[t];
  cells.triangles = triangles.finish(cursors);

  // What is averaged per vertex, from the packed vertices: deferred to here so that these sums do not sit
  // in memory through the face pass. Each owner scans all vertices in order and adds its own cells'.
  CellStore& sums = store;
  sums.points.resize(count);  // zeros that take memory only as they are written
  sums.point_sum.resize(count);
  const bool normals = vertices.normals.size() == vertex_count;
  const bool colors = vertices.colors.size() == vertex_count;
  const bool uvs = vertices.uvs.size() == vertex_count;
  if (normals) cells.normal_sum.assign(count, Vec3f::Zero());
  if (colors) cells.color_sum.assign(count, {0, 0, 0, 0});
  if (uvs) cells.uv_sum.assign(count, Vec2d::Zero());
  const unsigned threads = std::max(1u, options.threads);
  std::vector<std::uint32_t> vertex_bounds(threads + 1);
  for (unsigned t = 0; t <= threads; ++t) vertex_bounds[t] = static_cast<std::uint32_t>(count * t / threads);
  constexpr std::size_t kChunk = 1 << 20;
  for (std::size_t start = 0; start < vertex_count; start += kChunk) {
    const std::size_t end = std::min(vertex_count, start + kChunk);
    // One owner per thread here: every owner reads every vertex of the chunk.
    tbb::parallel_for(0u, threads, [&](unsigned owner) {
      const std::uint32_t lo = vertex_bounds[owner], span = vertex_bounds[owner + 1] - lo;
      for (std::size_t v = start; v < end; ++v) {
        std::uint32_t cell;
        std::uint64_t q;
        unpack(packed[v], cell, q);
        if (cell - lo >= span) continue;
        if (sums.points[cell] != std::numeric_limits<std::uint32_t>::max()) {
          ++sums.points[cell];
          sums.point_sum[cell] += dequantize(q).cast<float>();
        }
        if (normals) cells.normal_sum[cell] += vertices.normals[v];
        if (colors) {
          for (int c = 0; c < 4; ++c) cells.color_sum[cell][c] += vertices.colors[v][c];
        }
        if (uvs) cells.uv_sum[cell] += vertices.uvs[v].cast<double>();
      }
    });
    // These vertices are done with: hand their pages back now rather than when the whole array goes, so that
    // the sums above never sit in memory beside all of it.
    release_pages(positions.data() + start, positions.data() + end);
    if (normals) release_pages(vertices.normals.data() + start, vertices.normals.data() + end);
    if (colors) release_pages(vertices.colors.data() + start, vertices.colors.data() + end);
    if (uvs) release_pages(vertices.uvs.data() + start, vertices.uvs.data() + end);
  }
  // The stream is exhausted: its vertex array (the largest block of memory in play) is no longer needed.
  vertices = IndexedMesh();

  store.move_into(cells, options.boundary);
  return cells;
}

// ---- Triangle soups --------------------------------------------------------------------------------------

struct SoupOwner {
  CellMap map;
  std::vector<CellKey> keys;
  CellStore store;
  TripleSet<CellKey> triangles;
  std::uint64_t survived = 0;
};

FineCells accumulate_soup(TriangleStream& stream, const PassOptions& options) {
  const unsigned owners = std::max(1u, options.threads);
  FineCells cells;
  cells.grid = options.grid;
  if (options.target_cells > 0 && cells.grid.level >= 0) {
    // No vertex array to count cells on: size the grid so a surface spanning the box occupies about the
    // target (a closed surface in its box occupies 1-5 x cells^2 cells).
    const double side = std::sqrt(static_cast<double>(options.target_cells) / 2.0);
    const int level = std::clamp(static_cast<int>(std::ceil(std::log2(std::max(1.0, side)))), 0, kCoordBits);
    cells.grid = Grid::power_of_two(stream.bounds(), level);
  }
  const Grid grid = cells.grid;
  // Owners hold blocks of cells (up to 16 blocks along an axis) so that most triangles have one owner.
  int shift = 0;
  while ((grid.along_longest >> shift) > 16) ++shift;
  auto owner_of = [&](CellKey key) -> unsigned {
    if (owners == 1) return 0;
    const auto c = key_coords(key);
    return static_cast<unsigned>(mix64(make_key(c[0] >> shift, c[1] >> shift, c[2] >> shift)) % owners);
  };
  std::vector<SoupOwner> state(owners);
  cells.input_triangles = run_batches(
      stream, owners, options.progress, [](const TriangleBatch&) {},
      [&](const TriangleBatch& batch, unsigned owner) {
        if (!batch.triangles.empty()) {
          throw Error(stream.path(), {}, "a triangle soup stream delivered indexed triangles");
        }
        SoupOwner& me = state[owner];
        for (const auto& corners : batch.corners) {
          Facet f;
          f.own = 0;
          for (int k = 0; k < 3; ++k) {
            f.p[k] = corners[k].cast<double>();
            if (!f.p[k].allFinite()) throw Error(stream.path(), {}, "a triangle has a non-finite corner");
            f.key[k] = grid.locate(f.p[k], f.local[k]);
            f.index[k] = 0;
            f.own |= static_cast<unsigned>(owner_of(f.key[k]) == owner) << k;
          }
          if (!f.own) continue;
          for (int k = 0; k < 3; ++k) {
            if (!(f.own & (1u << k))) continue;
            bool inserted;
            const std::uint32_t i =
                me.map.insert(f.key[k], static_cast<std::uint32_t>(me.keys.size()), inserted);
            f.index[k] = i;
            if (inserted) {
              check_cell_count(me.keys.size() + 1);
              me.keys.push_back(f.key[k]);
              me.store.push_back();
            }
            if (me.store.points[i] != std::numeric_limits<std::uint32_t>::max()) {
              ++me.store.points[i];
              me.store.point_sum[i] += f.local[k].cast<float>();
            }
          }
          f.set_normal();
          set_inverse_lengths(&f, 1);
          contribute(f, me.store, grid, options.boundary);
          const CellKey(&key)[3] = f.key;
          if (key[0] != key[1] && key[1] != key[2] && key[2] != key[0]) {
            const CellKey first = std::min(key[0], std::min(key[1], key[2]));
            if (owner_of(first) == owner) {
              me.triangles.add(CellTriple<CellKey>::of(key[0], key[1], key[2]));
              ++me.survived;
            }
          }
        }
      });

  // Number the cells of all owners in Morton order.
  struct Entry {
    std::uint64_t code;
    std::uint32_t owner, index;
  };
  std::vector<Entry> entries;
  for (unsigned t = 0; t < owners; ++t) {
    for (std::uint32_t i = 0; i < state[t].keys.size(); ++i)
      entries.push_back({morton(state[t].keys[i]), t, i});
    cells.surviving_instances += state[t].survived;
  }
  check_cell_count(entries.size());
  tbb::parallel_sort(entries.begin(), entries.end(),
                     [](const Entry& a, const Entry& b) { return a.code < b.code; });
  const std::size_t count = entries.size();
  cells.keys.resize(count);
  CellStore store;
  store.records.resize(count);
  store.points.resize(count);
  store.point_sum.resize(count);
  CellMap numbering(count);
  for (std::size_t i = 0; i < count; ++i) {
    const Entry& e = entries[i];
    CellStore& from = state[e.owner].store;
    cells.keys[i] = state[e.owner].keys[e.index];
    store.records[i] = from.records[e.index];
    store.points[i] = from.points[e.index];
    store.point_sum[i] = from.point_sum[e.index];
    bool inserted;
    numbering.insert(cells.keys[i], static_cast<std::uint32_t>(i), inserted);
  }
  entries = {};
  for (unsigned t = 0; t < owners; ++t) {
    state[t].store = {};
    state[t].map = CellMap();
    std::vector<CellTriple<CellKey>> triples;
    state[t].triangles.drain_into(triples);
    for (const CellTriple<CellKey>& k : triples) {
      const std::uint32_t a = numbering.find(k.first()), b = numbering.find(k.second()),
                          c = numbering.find(k.third());
      CellTriangle t3 = CellTriangle::of(a, b, c);
      if (!k.seen_forward()) t3 = CellTriangle::of(a, c, b);
      if (k.seen_forward() && k.seen_reversed()) t3.merge_flags(CellTriangle::of(a, c, b));
      cells.triangles.push_back(t3);
    }
  }
  tbb::parallel_sort(cells.triangles.begin(), cells.triangles.end());
  store.move_into(cells, options.boundary);
  return cells;
}

}  // namespace

FineCells accumulate(TriangleStream& stream, const PassOptions& options) {
  if (stream.indexed()) return accumulate_indexed(stream, options);
  return accumulate_soup(stream, options);
}

}  // namespace ocsimp::cluster_detail
