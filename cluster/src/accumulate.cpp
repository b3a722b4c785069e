// The single pass over the input.
//
// Parallel scheme (DESIGN.md, Threads): each batch is cut into fixed-size chunks of triangles, counted from
// the batch's start, so the cuts do not depend on the thread count. Chunks run in parallel, each adding into
// partial sums of its own (a few hundred cells for a coherent input, so they stay in cache); the partials are
// then added to the cells' totals in chunk order. Every cell's totals are therefore the same floating-point
// sums for 1 or N threads, and the output is the same bytes. Indexed input merges the partials in parallel
// over ranges of cells, each range walking the chunks in order; soups merge on one thread, since their cells
// are numbered as they first appear.
//
// Indexed input: the vertex array is visited first. Each vertex's cell is resolved once (a hash lookup per
// vertex instead of per corner: the lookups are what this stage spends its time on) and written back into
// the vertex's own 12 bytes together with its position inside the cell, quantized to 2^-21 of a cell per
// axis - finer than the float input itself for any grid of 4 or more cells. The face loop then reaches a
// corner's cell by index, with no hashing, and rebuilds the corner's position from the cell and the offset.
// What is averaged per vertex is summed last, in fixed chunks of the vertex array, merged the same way.
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
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <type_traits>

#include "cells.h"
#include "ocsimp/core/error.h"

namespace ocsimp::cluster_detail {
namespace {

// ---- Packed vertices -------------------------------------------------------------------------------------

constexpr double kQuantum = static_cast<double>(1u << 21);
// A quantum's PointBox bin: its top 8 of 21 bits.
constexpr int kQuantumBinShift = 21 - 8;
static_assert(kPointBoxBins == 1 << (21 - kQuantumBinShift));
constexpr std::uint64_t kQuantumMax = (1u << 21) - 1;
static_assert(sizeof(Vec3f) == 12, "packed vertices reuse a position's 12 bytes");

std::uint64_t quantize(const Vec3d& local) {
  std::uint64_t q = 0;
  int a = 0;
#ifdef __SSE2__
  // x and y in one vector, each lane the loop's value below: max(s, 0) is 0 for s <= 0 and for NaN (maxpd
  // returns its second operand then), and min(., kQuantumMax) is the clamp (kQuantumMax + 0.5 truncates
  // to kQuantumMax).
  const __m128d s = _mm_mul_pd(_mm_loadu_pd(local.data()), _mm_set1_pd(kQuantum));
  const __m128d clamped =
      _mm_min_pd(_mm_max_pd(s, _mm_setzero_pd()), _mm_set1_pd(static_cast<double>(kQuantumMax)));
  const __m128i v = _mm_cvttpd_epi32(_mm_add_pd(clamped, _mm_set1_pd(0.5)));
  q = static_cast<std::uint32_t>(_mm_cvtsi128_si32(v)) |
      static_cast<std::uint64_t>(static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_shuffle_epi32(v, 1))))
          << 21;
  a = 2;
#endif
  for (; a < 3; ++a) {
    const double s = local[a] * kQuantum;
    std::uint64_t v = 0;
    if (s >= static_cast<double>(kQuantumMax)) {
      v = kQuantumMax;
    } else if (s > 0.0) {
      // Through a signed integer: s < 2^21, and converting to unsigned 64 bits costs a branch on x86-64.
      v = static_cast<std::uint64_t>(static_cast<std::int64_t>(s + 0.5));
    }
    q |= v << (21 * a);
  }
  return q;
}
// Bit 63 of a packed vertex's quanta, which quantize() leaves clear: the face pass sets it on every vertex a
// triangle refers to, so that the per-vertex sums after it skip the rest. A scan's unreferenced points are
// often outliers (bunny.ply has 1,113), and averaged in they moved cell means by up to half a cell.
constexpr std::uint64_t kReferenced = std::uint64_t{1} << 63;
// Axis a's offset in quanta, of quanta without kReferenced (the last axis is not masked).
std::int64_t quantum(std::uint64_t q, int a) {
  return static_cast<std::int64_t>(a == 2 ? q >> 42 : (q >> (21 * a)) & kQuantumMax);
}
// Adds a vertex of quanta q (without kReferenced) to a box of its cell's points.
void add_quanta(PointBox& box, std::uint64_t q) {
  for (int a = 0; a < 3; ++a) add_bin(box, a, static_cast<std::uint32_t>(quantum(q, a) >> kQuantumBinShift));
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

// Bit 63 of the quanta, as it sits in the slot's last word.
constexpr std::uint32_t kMark = static_cast<std::uint32_t>(kReferenced >> 32);
using SlotWord = std::uint32_t __attribute__((may_alias));

// unpack() while the face pass may be marking slots: the slot's last word (the quanta's high half, with
// kMark) goes through a relaxed atomic, the other two are only read. Returns that word; `low` is the rest.
std::uint32_t unpack_shared(const Vec3f& slot, std::uint32_t& cell, std::uint32_t& low) {
  const char* bytes = reinterpret_cast<const char*>(slot.data());
  std::memcpy(&cell, bytes, 4);
  std::memcpy(&low, bytes + 4, 4);
  return __atomic_load_n(reinterpret_cast<const SlotWord*>(bytes + 8), __ATOMIC_RELAXED);
}

// unpack() for the face pass, which also sets kReferenced in the slot and returns the quanta without it.
// Threads may mark the same vertex at once, and every writer stores the same value, so no mark is lost. It
// is stored only when missing, as a vertex is a corner of about six triangles and each store dirties a
// cache line.
void unpack_marking(Vec3f& slot, std::uint32_t& cell, std::uint64_t& q) {
  std::uint32_t low;
  const std::uint32_t high = unpack_shared(slot, cell, low);
  if (!(high & kMark)) [[unlikely]]
    __atomic_store_n(reinterpret_cast<SlotWord*>(reinterpret_cast<char*>(slot.data()) + 8), high | kMark,
                     __ATOMIC_RELAXED);
  q = low | static_cast<std::uint64_t>(high & ~kMark) << 32;
}

// A packed vertex's position, from its cell and quanta, while the face pass may be marking it.
Vec3f packed_position(const Vec3f& slot, const std::vector<CellKey>& keys, const Grid& grid) {
  std::uint32_t cell, low;
  const std::uint32_t high = unpack_shared(slot, cell, low);
  const std::uint64_t q = low | static_cast<std::uint64_t>(high & ~kMark) << 32;
  return (grid.cell_origin(keys[cell]) + dequantize(q) * grid.cell).cast<float>();
}

// Points a stream's position source at the packed vertices for as long as it lives.
class PositionsFromCells {
 public:
  PositionsFromCells(TriangleStream& stream, const Vec3f* packed, const std::vector<CellKey>& keys,
                     const Grid& grid)
      : stream_(stream) {
    stream_.set_position_source(
        [packed, &keys, grid](Index v) { return packed_position(packed[v], keys, grid); });
  }
  ~PositionsFromCells() { stream_.set_position_source({}); }
  PositionsFromCells(const PositionsFromCells&) = delete;
  PositionsFromCells& operator=(const PositionsFromCells&) = delete;

 private:
  TriangleStream& stream_;
};

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

// Adds integers modulo 2^bits: wrapping is harmless as long as the final totals fit (see BorderSums).
template <class T, class U>
void add_wrapping(T& to, U value) {
  using W = std::make_unsigned_t<T>;
  to = static_cast<T>(static_cast<W>(static_cast<W>(to) + static_cast<W>(value)));
}
template <class T, class U, std::size_t N>
void add_wrapping(std::array<std::array<T, N>, 3>& to, const std::array<std::array<U, N>, 3>& part) {
  for (int a = 0; a < 3; ++a)
    for (std::size_t c = 0; c < N; ++c) add_wrapping(to[a][c], part[a][c]);
}
bool is_zero(const ExactSums& sums) {
  std::int32_t any = 0;
  for (const auto& slot : sums)
    for (std::int32_t v : slot) any |= v;
  return any == 0;
}

// round(x) modulo 2^32, for |x| < 2^51: the low bits of x + 1.5 * 2^52, which the addition rounds to an
// integer, ties to even. So round(-x) = -round(x): terms that are exact opposites give exact opposites.
std::uint32_t fixed_point(double x) {
  return static_cast<std::uint32_t>(std::bit_cast<std::uint64_t>(x + 0x1.8p52));
}
// Four of them at once, in two vector adds and a shuffle.
using Lanes = std::uint32_t __attribute__((vector_size(16)));
using Pair = double __attribute__((vector_size(16)));
Lanes fixed_points(double a, double b, double c, double d) {
  const Pair lo = Pair{a, b} + 0x1.8p52, hi = Pair{c, d} + 0x1.8p52;
  // A cast between vector types of one size keeps the bits.
  return __builtin_shufflevector((Lanes)lo, (Lanes)hi, 0, 2, 4, 6);
}

// What the face loop adds to per cell, in one record: a triangle that touches a cell updates its quadric and,
// if it crosses a cell face, its border sums, and separate arrays would cost separate cache misses. The
// border sums are 32-bit here, each slot laid out for a half-edge's three vector adds: lanes
// [u0 u1 u2 m0 | m1 m2 0 0 | w0 w1 w2 o], with u, w = y x u the exact sums and m, o = -m . y the crease
// sums (see BorderSums); the first two vectors are the same for both ends of an edge.
struct alignas(64) CellRecord {
  Quadric quadric;
  Lanes border[3][3];

  bool has_exact() const {
    const Lanes t = border[0][0] | border[0][2] | border[1][0] | border[1][2] | border[2][0] | border[2][2];
    return (t[0] | t[1] | t[2]) != 0;
  }
  ExactSums exact() const {
    ExactSums x;
    for (int k = 0; k < 3; ++k) {
      const Lanes(&v)[3] = border[k];
      x[k] = {static_cast<std::int32_t>(v[0][0]), static_cast<std::int32_t>(v[0][1]),
              static_cast<std::int32_t>(v[0][2]), static_cast<std::int32_t>(v[2][0]),
              static_cast<std::int32_t>(v[2][1]), static_cast<std::int32_t>(v[2][2])};
    }
    return x;
  }
  void set_border(const ExactSums& x, const CreaseSums<std::int32_t>& c) {
    for (int k = 0; k < 3; ++k) {
      auto u = [](std::int32_t v) { return static_cast<std::uint32_t>(v); };
      border[k][0] = Lanes{u(x[k][0]), u(x[k][1]), u(x[k][2]), u(c[k][0])};
      border[k][1] = Lanes{u(c[k][1]), u(c[k][2]), 0, 0};
      border[k][2] = Lanes{u(x[k][3]), u(x[k][4]), u(x[k][5]), u(c[k][3])};
    }
  }
};
static_assert(sizeof(CellRecord) == 256, "a cell record is four cache lines");

// The cells' totals, in the arrays FineCells hands on where the types agree, so that the pass ends without
// copying them into new memory: every fresh page costs a fault, and this VM takes faults one at a time
// whatever the thread count (about 70 ms for the 80 MB of 1 M cells' quadrics).
template <class C>
struct CellStore {
  std::vector<Quadric> quadrics;
  ZeroedVector<CreaseSums<C>> crease;  // empty when the pass keeps no border sums
  std::vector<ExactSums> exact;        // empty but in soup passes: an indexed pass keeps them sparse
  ZeroedVector<std::uint32_t> points;
  ZeroedVector<Vec3f> point_sum;
  ZeroedVector<PointBox> point_box;

  // Marks the cell as touched by a triangle, after its contribution is added. A touched cell's quadric has a
  // positive trace (every proper triangle adds its area to it); one touched only by zero-area triangles
  // carries the mark in the sign of its zero constant term instead of a byte of its own.
  void touch(std::uint32_t i) {
    Quadric& q = quadrics[i];
    if (!(q.trace() > 0.0)) q.c = -0.0;
  }
  static bool touched(const Quadric& q) { return q.trace() > 0.0 || std::signbit(q.c); }

  // Adds a chunk's partial sums to cell i (but for the exact border sums of an indexed pass).
  void add(std::uint32_t i, const CellRecord& part) {
    quadrics[i] += part.quadric;
    if (!crease.empty()) {
      CreaseSums<C>& to = crease[i];
      for (int k = 0; k < 3; ++k) {
        const Lanes(&v)[3] = part.border[k];
        add_wrapping(to[k][0], v[0][3]);
        add_wrapping(to[k][1], v[1][0]);
        add_wrapping(to[k][2], v[1][1]);
        add_wrapping(to[k][3], v[2][3]);
      }
    }
    if (!exact.empty()) add_wrapping(exact[i], part.exact());
  }
  void push_back() {
    quadrics.emplace_back();
    crease.emplace_back();
    exact.emplace_back();
    points.push_back(0);
    point_sum.emplace_back(Vec3f::Zero());
    point_box.push_back(PointBox{});
  }
  // Hands the sums over to `cells`, but for the border sums.
  void move_into(FineCells& cells) {
    const std::size_t n = quadrics.size();
    cells.touched.resize(n);
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
      Quadric& q = quadrics[i];
      cells.touched[i] = touched(q) ? 1 : 0;
      if (q.c == 0.0) q.c = 0.0;  // drops the mark's sign
    });
    cells.quadrics = std::move(quadrics);
    quadrics = {};
    cells.points = std::move(points);
    cells.point_sum = std::move(point_sum);
    cells.point_box = std::move(point_box);
  }
};

// The area-weighted plane quadric of a triangle with unnormalized normal c (|c| = twice the area) and
// offset dc = -c . p0: every coefficient is a product of c and dc over 2|c|, so one square root and one
// division serve all ten. Held as five pairs in Quadric's order, (a00 a01) (a02 a11) (a12 a22) (b0 b1)
// (b2 c): each pair is one vector multiply and one vector add, the same products and sums lane by lane.
static_assert(sizeof(Quadric) == 10 * sizeof(double), "a quadric is five pairs of doubles");
// Five named pairs rather than an array, which the compiler kept on the stack instead of in registers.
struct QuadricPairs {
  Pair p0, p1, p2, p3, p4;

  static Pair load(const Quadric& q, int i) {
    Pair v;
    std::memcpy(&v, reinterpret_cast<const char*>(&q) + sizeof(Pair) * i, sizeof(Pair));
    return v;
  }
  static void store(Quadric& q, int i, Pair v) {
    std::memcpy(reinterpret_cast<char*>(&q) + sizeof(Pair) * i, &v, sizeof(Pair));
  }
  static QuadricPairs of(const Quadric& q) {
    return {load(q, 0), load(q, 1), load(q, 2), load(q, 3), load(q, 4)};
  }
  void store(Quadric& q) const {
    store(q, 0, p0), store(q, 1, p1), store(q, 2, p2), store(q, 3, p3), store(q, 4, p4);
  }
};
struct TriangleQuadric {
  QuadricPairs v;
  // `s` = 1 / (2 |c|).
  TriangleQuadric(double x, double y, double z, double dc, double s) {
    const Pair xy = {x, y}, zd = {z, dc};
    const Pair sxy = s * xy, szd = s * zd;  // sx sy, sz sd
    const Pair sx = __builtin_shufflevector(sxy, sxy, 0, 0), sd = __builtin_shufflevector(szd, szd, 1, 1);
    v.p0 = sx * xy;                                                                          // sx x, sx y
    v.p1 = sxy * __builtin_shufflevector(zd, xy, 0, 3);                                      // sx z, sy y
    v.p2 = __builtin_shufflevector(sxy, szd, 1, 2) * __builtin_shufflevector(zd, zd, 0, 0);  // sy z, sz z
    v.p3 = sd * xy;                                                                          // sd x, sd y
    v.p4 = sd * zd;                                                                          // sd z, sd dc
  }
  [[gnu::always_inline]] void add_to(QuadricPairs& q, int multiplicity) const {
    if (multiplicity == 1) {
      q.p0 += v.p0, q.p1 += v.p1, q.p2 += v.p2, q.p3 += v.p3, q.p4 += v.p4;
    } else {
      const double m = multiplicity;
      q.p0 += m * v.p0, q.p1 += m * v.p1, q.p2 += m * v.p2, q.p3 += m * v.p3, q.p4 += m * v.p4;
    }
  }
  [[gnu::always_inline]] void add_to(Quadric& q, int multiplicity) const {
    QuadricPairs sum = QuadricPairs::of(q);
    add_to(sum, multiplicity);
    sum.store(q);
  }
};

// One chunk slot's overflowing surviving triangles: appended as they come (a hash set would cost a cache miss
// per triangle in the face loop), sorted and merged whenever the log fills, so memory stays proportional to
// the distinct triangles however often they repeat.
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

// Reads the next batch on one task while `work(batch)` (which runs its own parallel loops) handles the
// current one. `first(batch)` sees the first batch before any work, while the stream has read nothing more.
template <class First, class Work>
std::uint64_t run_batches(TriangleStream& stream, const ProgressFn& progress, First&& first, Work&& work) {
  TriangleBatch current, next;
  std::uint64_t triangles = 0;
  bool have = stream.next(current);
  if (have) first(current);
  while (have) {
    bool have_next = false;
    tbb::task_group reader;
    reader.run([&] { have_next = stream.next(next); });
    std::exception_ptr failure;
    try {
      work(current);
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
template <class Work>
std::uint64_t run_batches(TriangleStream& stream, const ProgressFn& progress, Work&& work) {
  return run_batches(
      stream, progress, [](const TriangleBatch&) {}, work);
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
bool distinct_cells(const std::string& path, std::span<const Vec3f> positions, const Grid& grid,
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
                      // A copy the compiler may keep in registers: the set's stores could alias the caller's.
                      const Grid local_grid = grid;
                      CellKey last = kNoKey;  // runs of vertices share a cell
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const Vec3f& p = positions[i];
                        if (!p.allFinite()) {
                          std::size_t seen = first_bad.load();
                          while (i < seen && !first_bad.compare_exchange_weak(seen, i)) {
                          }
                          continue;
                        }
                        const CellKey key = local_grid.locate_float(p);
                        if (key == last) continue;
                        last = key;
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
// `points()`: the distinct points among `positions`, the most cells any grid can hold; asked only when the
// cells fall short of the target.
template <class Points>
std::vector<std::uint64_t> choose_cells(const std::string& path, std::span<const Vec3f> positions,
                                        Points&& points, const Box3& bounds, const PassOptions& options,
                                        Grid& grid) {
  std::vector<std::uint64_t> codes;
  if (options.target_cells == 0 || grid.level < 0) {
    distinct_cells(path, positions, grid, 0, codes);
    return codes;
  }
  const double target = static_cast<double>(options.target_cells);
  const double needed = static_cast<double>(options.needed_cells);
  int level = grid.level;
  // The coarsest level a refinement below allows: coarsening back under it would undo the refinement, and the
  // two would take turns. And the cells counted before that refinement.
  int floor_level = 0;
  double count_before_refining = 0;
  // Refinements stop after this many attempts (every level about twice over: no rule below should get
  // there). Then the loop can only coarsen, and a grid of one cell always fits, so it ends on a counted grid.
  constexpr int kMaxRefinements = 2 * kCoordBits + 4;
  for (int attempt = 0;; ++attempt) {
    grid = Grid::power_of_two(bounds, level);
    const std::size_t cap = static_cast<std::size_t>(std::min(8 * target + 1024, 4e9));
    if (!distinct_cells(path, positions, grid, cap, codes)) {
      if (level == 0) break;  // cannot happen: one cell
      level = std::max(0, level - 2);
      continue;
    }
    // Halving the grid merges each group of up to 8 siblings, which are contiguous in Morton order. Never
    // below the cells the target needs: that undid the refinement below, and the two took turns forever.
    std::vector<std::uint64_t> coarser;
    while (codes.size() > 2 * target && grid.level > floor_level) {
      coarser.resize(codes.size());
      std::transform(codes.begin(), codes.end(), coarser.begin(), [](std::uint64_t c) { return c >> 3; });
      coarser.erase(std::unique(coarser.begin(), coarser.end()), coarser.end());
      if (static_cast<double>(coarser.size()) < needed) break;
      codes.swap(coarser);
      grid = grid.coarser();
    }
    level = grid.level;
    const double count = static_cast<double>(codes.size());
    // Too few cells: refine, if the input has the vertices to fill them. The first level assumes a surface
    // spanning its box; one that fills little of it (parts far apart, or outlier points no face uses
    // stretching the box) got a fine grid several times coarser than the target, and outputs made of fine
    // cells barely smaller than their own. (bunny.ply with one unused point 700 diagonals away, to 7,000
    // faces: 7,497 fine cells for a 28,000 target and 23 % more RMS error than without the point; now 23,971
    // cells and the same error.) A surface's cells grow about 4x per level, so below half the target the
    // next level is the nearer one, as above twice the target the coarser one is (the loop above, which
    // never coarsens back past a refinement). The first two refinements jump by the levels the shortfall
    // suggests, later ones take one level at a time, and only while a level still at least doubles the
    // cells: once they near one per distinct position, more levels add nothing (a mesh whose triangles each
    // have their own three vertices fills about one cell per six vertices, under the quarter allowed here,
    // and went on to the finest level, one pass over the vertices per level).
    // Separately, while there are fewer cells than the target needs, one level at a time until every vertex
    // has a cell of its own: parts much closer together than the surface is wide (two layers of a thin
    // shell) need many more levels. One level multiplies the cells by at most 8, which keeps the count under
    // the cap (8 x target, and target >= needed).
    const bool few = count < target / 2 && count >= 2 * count_before_refining && count < points() / 4;
    const bool short_of_target = count < needed && count < points();
    if ((few || short_of_target) && level < kCoordBits && attempt < kMaxRefinements) {
      const int step =
          few && attempt < 2
              ? std::max(1, static_cast<int>(std::lround(std::log(target / count) / std::log(4.0))))
              : 1;
      floor_level = level + 1;
      count_before_refining = count;
      level = std::min(kCoordBits, level + step);
      continue;
    }
    break;
  }
  return codes;
}

// Surviving triangles of all chunks in one array sized up front: each chunk slot claims blocks of it, so the
// face loop appends without hashing (a hash set costs a cache miss per triangle) and without per-slot
// vectors that would have to be concatenated (a second copy at the memory peak). A slot that finds the
// array full keeps a private log instead, compacted whenever it fills.
class TriangleBuffer {
 public:
  static constexpr std::size_t kBlock = 4096;
  static constexpr CellTriangle kUnused{~std::uint32_t{0}, ~std::uint32_t{0}, ~std::uint32_t{0}};

  TriangleBuffer(std::size_t expected, unsigned owners) : items_(expected + kBlock * owners) {
    add_owners(owners);
  }
  // Owners numbered up to `owners` - 1 may add from now on; not while any owner adds.
  void add_owners(std::size_t owners) {
    while (overflow_.size() < owners) overflow_.emplace_back(kBlock);
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
    // Blocks that did not fit whole were never handed out.
    items_.resize(std::min(items_.size() / kBlock * kBlock, claimed_.load()));
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

// ---- Chunks ----------------------------------------------------------------------------------------------

// Triangles (or vertices) per chunk. The cuts count from the start of each batch, and batches do not depend
// on the thread count, so neither do the chunks.
constexpr std::size_t kChunkTriangles = 8192;
constexpr std::size_t kChunkVertices = 1 << 16;

// The cells one chunk touches -> the chunk's own numbering of them, in order of first touch. Open addressing
// over a table that stays in cache: a chunk of a coherent input touches a few hundred cells. Keys: cell
// numbers (indexed input) or cell keys (soups); all ones is never one.
template <class Key>
class ChunkTable {
 public:
  ChunkTable() : table_(kInitial, Entry{kEmpty, 0}), mask_(kInitial - 1) {}

  // The chunk's number for `cell`; `inserted` says it is new (numbered ids().size() - 1).
  std::uint32_t slot(Key cell, bool& inserted) {
    inserted = false;
    if (cell == last_cell_) return last_slot_;
    std::size_t i = hash(cell);
    for (; table_[i].key != kEmpty; i = (i + 1) & mask_) {
      if (table_[i].key == cell) {
        last_cell_ = cell;
        last_slot_ = table_[i].slot;
        return last_slot_;
      }
    }
    // Grown only when a cell is added, which most lookups do not.
    if (2 * (ids_.size() + 1) > table_.size()) {
      rehash(2 * table_.size());
      for (i = hash(cell); table_[i].key != kEmpty; i = (i + 1) & mask_) {
      }
    }
    const auto local = static_cast<std::uint32_t>(ids_.size());
    table_[i] = {cell, local};
    ids_.push_back(cell);
    inserted = true;
    last_cell_ = cell;
    last_slot_ = local;
    return local;
  }
  void clear() {
    // A table grown by one scattered chunk shrinks back rather than being wiped whole for every chunk.
    if (table_.size() > kInitial && table_.size() > 8 * ids_.size()) {
      table_.assign(kInitial, Entry{kEmpty, 0});
      mask_ = kInitial - 1;
    } else {
      std::fill(table_.begin(), table_.end(), Entry{kEmpty, 0});
    }
    ids_.clear();
    order_.clear();
    last_cell_ = kEmpty;
  }
  // Lists the chunk's numbers by ascending cell, for merge_chunks.
  void sort_by_cell() {
    order_.resize(ids_.size());
    for (std::uint32_t s = 0; s < order_.size(); ++s) order_[s] = s;
    std::sort(order_.begin(), order_.end(),
              [&](std::uint32_t a, std::uint32_t b) { return ids_[a] < ids_[b]; });
  }
  const std::vector<Key>& ids() const { return ids_; }
  const std::vector<std::uint32_t>& order() const { return order_; }

 private:
  struct Entry {
    Key key;
    std::uint32_t slot;
  };
  static constexpr std::size_t kInitial = 2048;
  static constexpr Key kEmpty = ~Key{0};
  std::size_t hash(Key cell) const {
    return static_cast<std::size_t>(static_cast<std::uint64_t>(cell) * 0x9E3779B97F4A7C15ull >> 32) & mask_;
  }
  void rehash(std::size_t capacity) {
    table_.assign(capacity, Entry{kEmpty, 0});
    mask_ = capacity - 1;
    for (std::uint32_t s = 0; s < ids_.size(); ++s) {
      std::size_t i = hash(ids_[s]);
      while (table_[i].key != kEmpty) i = (i + 1) & mask_;
      table_[i] = {ids_[s], s};
    }
  }

  std::vector<Entry> table_;
  std::size_t mask_;
  std::vector<Key> ids_;              // number -> cell
  std::vector<std::uint32_t> order_;  // numbers by ascending cell
  Key last_cell_ = kEmpty;
  std::uint32_t last_slot_ = 0;
};

// One chunk of faces: partial quadric and border sums of the cells it touches, and its surviving triangles'
// place in the shared buffer.
struct FaceChunk {
  ChunkTable<std::uint32_t> table;
  std::vector<CellRecord> records;
  std::vector<CellKey> keys;
  std::vector<Vec3d> origins;
  TriangleBuffer::Cursor cursor;
  std::uint64_t survived = 0;
  struct Corners {
    std::uint64_t q[3];
    std::uint32_t cell[3];
  };
  // A triangle inside one cell: its cross product in world units and plane offset, then 1 / (2 |cross|).
  struct Flat {
    double cross[3];
    double offset, squared, scale;
    std::uint32_t slot;
  };
  // Scratch, kept from chunk to chunk.
  std::vector<Corners> gathered;
  std::vector<Flat> flats;
  std::vector<std::uint32_t> crossing;  // the rest, by their place in `gathered`

  std::uint32_t slot(std::uint32_t cell, const std::vector<CellKey>& all_keys, const Grid& grid) {
    bool inserted;
    const std::uint32_t s = table.slot(cell, inserted);
    if (inserted) {
      records.emplace_back();
      keys.push_back(all_keys[cell]);
      origins.push_back(grid.cell_origin(keys.back()));
    }
    return s;
  }
  CellKey key(std::uint32_t s) const { return keys[s]; }
  const Vec3d& origin(std::uint32_t s) const { return origins[s]; }
  Quadric& quadric(std::uint32_t s) { return records[s].quadric; }
  CellRecord& record(std::uint32_t s) { return records[s]; }
  void clear() {
    table.clear();
    records.clear();
    keys.clear();
    origins.clear();
    survived = 0;
  }
  void sort_by_cell() { table.sort_by_cell(); }
};

// One triangle as a chunk sees it, in scalars: Eigen's 3-vector temporaries cost several times the
// arithmetic on this path (every triangle of a soup, every crossing triangle of an indexed input).
struct Facet {
  double local[3][3];      // corners in their cells' frames (cell units from each cell's lower corner)
  double p[3][3];          // corners in world units
  double cross[3];         // (p1 - p0) x (p2 - p0)
  double inverse_length;   // 1 / |cross|, 0 for a degenerate triangle
  std::uint32_t index[3];  // the corners' cells in the chunk's numbering

  void set_cross() {
    const double ux = p[1][0] - p[0][0], uy = p[1][1] - p[0][1], uz = p[1][2] - p[0][2];
    const double vx = p[2][0] - p[0][0], vy = p[2][1] - p[0][1], vz = p[2][2] - p[0][2];
    cross[0] = uy * vz - uz * vy;
    cross[1] = uz * vx - ux * vz;
    cross[2] = ux * vy - uy * vx;
  }
};

// 1 / |cross| for a block of facets, apart from the rest of the work: the square roots and divisions
// pipeline back to back instead of each stalling a triangle's dependency chain.
void set_inverse_lengths(Facet* facets, int count) {
  for (int i = 0; i < count; ++i) {
    const double(&c)[3] = facets[i].cross;
    const double squared = (c[0] * c[0] + c[1] * c[1]) + c[2] * c[2];
    const bool proper = squared > 0.0 && squared <= std::numeric_limits<double>::max();
    facets[i].inverse_length = proper ? 1.0 / std::sqrt(squared) : 0.0;
  }
}

// Adds one triangle to its corners' cells: its plane quadric, and the border sums of its edges between two
// cells.
// `fine`, when given, holds the corners' cells on a finer grid the pass used before (a soup pass that
// coarsened): an edge between two of those cells adds its border sums even if its ends now share a cell.
template <class Chunk>
void contribute(const Facet& f, Chunk& chunk, bool boundary, const CellKey* fine = nullptr) {
  // A zero-area triangle adds no quadric (and no border sums: it has no normal).
  const bool proper = f.inverse_length > 0.0;
  const double(&c)[3] = f.cross;
  const double dc = -((c[0] * f.p[0][0] + c[1] * f.p[0][1]) + c[2] * f.p[0][2]);
  const TriangleQuadric q(c[0], c[1], c[2], dc, 0.5 * f.inverse_length);
  const std::uint32_t(&cell)[3] = f.index;
  if (proper) {
    // Each distinct cell once, with its corner count.
    if (cell[0] == cell[1] && cell[1] == cell[2]) {
      q.add_to(chunk.quadric(f.index[0]), 3);
    } else if (cell[0] == cell[1]) {
      q.add_to(chunk.quadric(f.index[0]), 2);
      q.add_to(chunk.quadric(f.index[2]), 1);
    } else if (cell[1] == cell[2]) {
      q.add_to(chunk.quadric(f.index[0]), 1);
      q.add_to(chunk.quadric(f.index[1]), 2);
    } else if (cell[2] == cell[0]) {
      q.add_to(chunk.quadric(f.index[0]), 2);
      q.add_to(chunk.quadric(f.index[1]), 1);
    } else {
      q.add_to(chunk.quadric(f.index[0]), 1);
      q.add_to(chunk.quadric(f.index[1]), 1);
      q.add_to(chunk.quadric(f.index[2]), 1);
    }
  }
  if (!boundary || !proper) return;
  // The unit normal, times the crease units per exact unit (u below is in exact units).
  const double to_crease = f.inverse_length * (kCreaseScale / kExactScale);
  const double n[3] = {c[0] * to_crease, c[1] * to_crease, c[2] * to_crease};
  for (int a = 0; a < 3; ++a) {
    const int b = a == 2 ? 0 : a + 1;
    if (fine ? fine[a] == fine[b] : cell[a] == cell[b]) continue;
    // The two half-edges of an interior edge compute e with exactly opposite bits and each end's offset in
    // its cell with exactly equal bits, so u, y x u and their rounded values are exact opposites.
    const double e[3] = {f.p[b][0] - f.p[a][0], f.p[b][1] - f.p[a][1], f.p[b][2] - f.p[a][2]};
    const double e_squared = (e[0] * e[0] + e[1] * e[1]) + e[2] * e[2];
    if (!(e_squared > 0.0)) continue;
    const double r = kExactScale / std::sqrt(e_squared);
    const double u[3] = {e[0] * r, e[1] * r, e[2] * r};  // in exact units
    const double m[3] = {u[1] * n[2] - u[2] * n[1], u[2] * n[0] - u[0] * n[2], u[0] * n[1] - u[1] * n[0]};
    const double ax = std::abs(e[0]), ay = std::abs(e[1]), az = std::abs(e[2]);
    const int slot = ax >= ay && ax >= az ? 0 : (ay >= az ? 1 : 2);
    const Lanes shared[2] = {fixed_points(u[0], u[1], u[2], m[0]), fixed_points(m[1], m[2], 0.0, 0.0)};
    for (const int k : {a, b}) {
      const double(&y)[3] = f.local[k];
      Lanes(&to)[3] = chunk.record(f.index[k]).border[slot];
      to[0] += shared[0];
      to[1] += shared[1];
      to[2] += fixed_points(y[1] * u[2] - y[2] * u[1], y[2] * u[0] - y[0] * u[2], y[0] * u[1] - y[1] * u[0],
                            -((m[0] * y[0] + m[1] * y[1]) + m[2] * y[2]));
    }
  }
}

// Vertex attributes summed per cell (or per slot of a chunk), for those the input has: an indexed pass sums
// its vertices', a soup's pass its corners' (TriangleBatch::corner_normals and the others).
struct AttributeSums {
  bool normals = false, colors = false, uvs = false;
  std::vector<Vec3f> normal_sum;
  std::vector<std::array<std::uint64_t, 4>> color_sum;
  std::vector<Vec2d> uv_sum;

  // Which attributes a soup's batch with triangles carries; throws when it carries one for only some corners.
  static AttributeSums carried_by(const TriangleBatch& batch, const std::string& path) {
    const std::size_t n = batch.corners.size();
    auto carried = [&](std::size_t size) {
      if (size != 0 && size != n)
        throw Error(path, {}, "a triangle soup stream delivered corner attributes for only some corners");
      return size == n;
    };
    AttributeSums a;
    a.normals = carried(batch.corner_normals.size());
    a.colors = carried(batch.corner_colors.size());
    a.uvs = carried(batch.corner_uvs.size());
    return a;
  }
  bool same_kinds(const AttributeSums& other) const {
    return normals == other.normals && colors == other.colors && uvs == other.uvs;
  }
  void same_as(const AttributeSums& other) {
    normals = other.normals, colors = other.colors, uvs = other.uvs;
  }
  void push_back() {
    if (normals) normal_sum.emplace_back(Vec3f::Zero());
    if (colors) color_sum.push_back({0, 0, 0, 0});
    if (uvs) uv_sum.emplace_back(Vec2d::Zero());
  }
  void clear() {
    normal_sum.clear();
    color_sum.clear();
    uv_sum.clear();
  }
  void add_vertex(std::uint32_t s, const IndexedMesh& vertices, std::size_t v) {
    if (normals) normal_sum[s] += vertices.normals[v];
    if (colors) {
      for (int c = 0; c < 4; ++c) color_sum[s][c] += vertices.colors[v][c];
    }
    if (uvs) uv_sum[s] += vertices.uvs[v].cast<double>();
  }
  void add_corner(std::uint32_t s, const TriangleBatch& batch, std::size_t t, int k) {
    if (normals) normal_sum[s] += batch.corner_normals[t][k];
    if (colors) {
      for (int c = 0; c < 4; ++c) color_sum[s][c] += batch.corner_colors[t][k][c];
    }
    if (uvs) uv_sum[s] += batch.corner_uvs[t][k].cast<double>();
  }
  void add(std::uint32_t i, const AttributeSums& from, std::uint32_t j) {
    if (normals) normal_sum[i] += from.normal_sum[j];
    if (colors) {
      for (int c = 0; c < 4; ++c) color_sum[i][c] += from.color_sum[j][c];
    }
    if (uvs) uv_sum[i] += from.uv_sum[j];
  }
  // Adds entry j to cell i of `cells`, whose attribute arrays hold these kinds.
  void add_to(FineCells& cells, std::uint32_t i, std::uint32_t j) const {
    if (normals) cells.normal_sum[i] += normal_sum[j];
    if (colors) {
      for (int c = 0; c < 4; ++c) cells.color_sum[i][c] += color_sum[j][c];
    }
    if (uvs) cells.uv_sum[i] += uv_sum[j];
  }
  // Sizes the attribute arrays of `cells` for `count` cells of these kinds, at zero.
  void size_cells(FineCells& cells, std::size_t count) const {
    if (normals) cells.normal_sum.assign(count, Vec3f::Zero());
    if (colors) cells.color_sum.assign(count, {0, 0, 0, 0});
    if (uvs) cells.uv_sum.assign(count, Vec2d::Zero());
  }
};

// One chunk of vertices: partial sums of what is averaged per cell.
struct PointChunk {
  ChunkTable<std::uint32_t> table;
  std::vector<std::uint32_t> points;
  std::vector<Vec3f> point_sum;
  std::vector<PointBox> point_box;
  AttributeSums attributes;

  std::uint32_t slot(std::uint32_t cell) {
    bool inserted;
    const std::uint32_t s = table.slot(cell, inserted);
    if (inserted) {
      points.push_back(0);
      point_sum.emplace_back(Vec3f::Zero());
      point_box.push_back(PointBox{});
      attributes.push_back();
    }
    return s;
  }
  void clear() {
    table.clear();
    points.clear();
    point_sum.clear();
    point_box.clear();
    attributes.clear();
  }
  void sort_by_cell() { table.sort_by_cell(); }
};

// Cells per block of merge_chunks: one task merges a whole block.
constexpr int kMergeBlockBits = 14;

// Adds chunks 0..n-1's partial sums to the cells' totals: `add(chunk, number, cell)`, then
// `block_done(block)` for each block of 2^kMergeBlockBits cells, all on the one task that merged the block.
// Each cell receives its chunks' partials in chunk order, so its totals are the same floating-point sums
// however the cells are split among threads here and however many threads produced the chunks.
template <class Chunk, class Add, class BlockDone>
void merge_chunks(const Chunk* chunks, std::size_t n, std::size_t cells, Add&& add, BlockDone&& block_done) {
  const auto blocks = static_cast<std::uint32_t>((cells + (1 << kMergeBlockBits) - 1) >> kMergeBlockBits);
  tbb::parallel_for(
      tbb::blocked_range<std::uint32_t>(0, blocks), [&](const tbb::blocked_range<std::uint32_t>& r) {
        const std::uint32_t begin = r.begin() << kMergeBlockBits;
        const auto end = static_cast<std::uint32_t>(std::min<std::size_t>(cells, r.end() << kMergeBlockBits));
        for (std::size_t j = 0; j < n; ++j) {
          const std::vector<std::uint32_t>& ids = chunks[j].table.ids();
          const std::vector<std::uint32_t>& order = chunks[j].table.order();
          auto it = std::partition_point(order.begin(), order.end(),
                                         [&](std::uint32_t s) { return ids[s] < begin; });
          for (; it != order.end() && ids[*it] < end; ++it) add(chunks[j], *it, ids[*it]);
        }
        for (std::uint32_t b = r.begin(); b != r.end(); ++b) block_done(b);
      });
}
template <class Chunk, class Add>
void merge_chunks(const Chunk* chunks, std::size_t n, std::size_t cells, Add&& add) {
  merge_chunks(chunks, n, cells, add, [](std::uint32_t) {});
}

// An indexed pass's exact border sums, kept only for the cells where they do not cancel so far: the
// original's borders, and interior edges whose other triangle is in a chunk not merged yet. Dense, they
// would be the largest sums of a cell at the pass's memory peak, and in a coherent input they cancel within
// a chunk or the next few for all but a few cells. One list per merge block, sorted by cell after each
// merge; integer sums, so the order of additions does not matter.
struct ExactEntry {
  std::uint32_t cell;
  ExactSums sums;
};
class SparseExactSums {
 public:
  explicit SparseExactSums(std::size_t cells)
      : blocks_((cells + (1 << kMergeBlockBits) - 1) >> kMergeBlockBits) {}
  // Only from the task merging the cell's block.
  void add(std::uint32_t cell, const CellRecord& part) {
    if (part.has_exact()) blocks_[cell >> kMergeBlockBits].push_back({cell, part.exact()});
  }
  // Merges the block's repeated cells and drops those whose sums cancelled.
  void settle(std::uint32_t block) {
    std::vector<ExactEntry>& v = blocks_[block];
    if (v.empty()) return;
    std::sort(v.begin(), v.end(), [](const ExactEntry& a, const ExactEntry& b) { return a.cell < b.cell; });
    std::size_t out = 0;
    for (std::size_t i = 0; i < v.size();) {
      ExactEntry e = v[i];
      for (++i; i < v.size() && v[i].cell == e.cell; ++i) add_wrapping(e.sums, v[i].sums);
      if (!is_zero(e.sums)) v[out++] = e;
    }
    v.resize(out);
    // Most of a merge's entries are chunks' shared edges that cancel right here: hand back what they took,
    // or every block would keep the most a batch ever put in it.
    if (v.capacity() > 4 * out + 16) v.shrink_to_fit();
  }
  // Writes the sums into `border` (one per cell, zero where absent).
  void write(ZeroedVector<BorderSums>& border) const {
    for (const std::vector<ExactEntry>& v : blocks_)
      for (const ExactEntry& e : v) border[e.cell].exact = e.sums;
  }

 private:
  std::vector<std::vector<ExactEntry>> blocks_;
};

FineCells accumulate_indexed(TriangleStream& stream, const PassOptions& options) {
  IndexedMesh& vertices = stream.scratch_vertices();
  std::vector<Vec3f>& positions = vertices.positions;
  const std::size_t vertex_count = positions.size();
  const Box3 bounds = stream.bounds();

  FineCells cells;
  cells.grid = options.grid;
  cells.input_vertices = vertex_count;
  std::vector<std::uint64_t> codes = choose_cells(
      stream.path(), positions, [&] { return static_cast<double>(positions.size()); }, bounds, options,
      cells.grid);
  const Grid grid = cells.grid;
  if (options.accept_fine_cells && !options.accept_fine_cells(codes.size())) {
    cells.declined_cells = codes.size();
    return cells;
  }
  check_cell_count(codes.size());
  const std::size_t count = codes.size();
  cells.keys.resize(count);
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t i) { cells.keys[i] = key_of_morton(codes[i]); });
  codes = {};

  // The face pass's quadric sums take their fresh pages (faults, which this VM serves one at a time) on
  // another thread while this one builds the key -> cell map, in about the same time; the border sums wait
  // for the map to go, so that the two never add to the memory peak together.
  CellStore<std::int16_t> store;
  {
    tbb::task_group allocate;
    allocate.run([&] { store.quadrics.resize(count); });
    CellMap map(count);
    bool inserted;
    for (std::size_t i = 0; i < count; ++i)
      map.insert(cells.keys[i], static_cast<std::uint32_t>(i), inserted);
    allocate.wait();
    // Vertex pass: resolve each vertex's cell once and pack it, with the vertex's offset inside the cell,
    // into the vertex's own 12 bytes. Each vertex is read and written by the same task.
    constexpr std::size_t kChunk = 1 << 20;
    for (std::size_t start = 0; start < vertex_count; start += kChunk) {
      const std::size_t end = std::min(vertex_count, start + kChunk);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(start, end, 1 << 18),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          RecentCells recent;
                          // A copy the compiler may keep in registers: the packed stores could alias the
                          // caller's.
                          const Grid local_grid = grid;
                          CellKey last_key = kNoKey;  // runs of vertices share a cell
                          std::uint32_t cell = 0;
                          for (std::size_t v = r.begin(); v != r.end(); ++v) {
                            Vec3d local;
                            const CellKey key = local_grid.locate_float(positions[v], local);
                            if (key != last_key) {
                              last_key = key;
                              cell = recent.find(key);
                              if (cell == CellMap::kMissing) {
                                cell = map.find(key);
                                recent.remember(key, cell);
                              }
                            }
                            pack(positions[v], cell, quantize(local));
                          }
                        });
      report(options.progress, "cluster: vertices", end, vertex_count);
    }
  }

  // The stream splits the polygons still to come by their corners' positions, which the packing has
  // overwritten: it reads them back from the cells, to 2^-21 of a cell (a fan of garbage cut concave
  // polygons across their outside, and quads along either diagonal).
  const PositionsFromCells positions_from_cells(stream, positions.data(), cells.keys, grid);
#ifdef __GLIBC__
  // The temporaries above (per-thread key sets, the key -> cell map) were freed into the heap; give their
  // pages back before the face pass, the memory peak, allocates its own.
  malloc_trim(0);
#endif
  if (options.boundary) store.crease.resize(count);
  SparseExactSums exact(count);
  // Face pass, in fixed chunks of each batch (see the top of this file).
  // About two distinct triangles per cell on a closed surface; repeats are few when cells are much larger
  // than triangles.
  TriangleBuffer triangles(count * 23 / 10, 16);
  std::vector<FaceChunk> chunks;
  Vec3f* packed = positions.data();
  const std::string& path = stream.path();
  auto process = [&](const std::vector<Triangle>& batch, std::size_t j) {
    FaceChunk& chunk = chunks[j];
    chunk.clear();
    const std::size_t begin = j * kChunkTriangles, end = std::min(batch.size(), begin + kChunkTriangles);
    // The corners first, in a loop of independent loads: they are random reads into the vertex array, and
    // many of them then wait on memory at once instead of one per triangle.
    const std::size_t size = end - begin;
    chunk.gathered.resize(size);
    FaceChunk::Corners* gathered = chunk.gathered.data();
    const Triangle* triangles_in = batch.data() + begin;
    for (std::size_t i = 0; i < size; ++i) {
      const Triangle& t = triangles_in[i];
      const Index largest = std::max(t[0], std::max(t[1], t[2]));
      if (largest >= vertex_count) [[unlikely]] {
        throw Error(
            path, {},
            "a triangle refers to vertex " + std::to_string(largest) + " of " + std::to_string(vertex_count));
      }
      FaceChunk::Corners& g = gathered[i];
      for (int k = 0; k < 3; ++k) unpack_marking(packed[t[k]], g.cell[k], g.q[k]);
    }
    // Then in phases over the chunk, each a loop of independent steps: a triangle's square root and
    // division would otherwise stall its own dependency chain.
    std::vector<FaceChunk::Flat>& flats = chunk.flats;
    std::vector<std::uint32_t>& crossing = chunk.crossing;
    // Only grows: every entry in use is written before it is read, and clearing it per chunk cost a memset.
    if (flats.size() < size) flats.resize(size);
    crossing.clear();
    FaceChunk::Flat* flat = flats.data();
    // Powers of two folded into the cell's constants once per chunk: scaling by one is exact, so
    // cell * (x * 2^-21) and (cell * 2^-21) * x round the same (no product here comes near the subnormals: a
    // cell is at least the float box's extent over 2^21, or the box is one point and every offset zero).
    const double cell_size = grid.cell;
    const double area_scale = grid.cell * grid.cell * (1.0 / (kQuantum * kQuantum));
    const double quantum_size = grid.cell * (1.0 / kQuantum);
    // The last cell looked up, its chunk number and origin: runs of triangles share a cell, and this skips
    // the table (whose own last-cell check sits behind a call) for them.
    std::uint32_t run_cell = ~std::uint32_t{0}, run_slot = 0;
    Vec3d run_origin = Vec3d::Zero();
    auto slot_of = [&](std::uint32_t cell) {
      if (cell != run_cell) {
        run_cell = cell;
        run_slot = chunk.slot(cell, cells.keys, grid);
        run_origin = chunk.origin(run_slot);
      }
      return run_slot;
    };
    for (std::uint32_t i = 0; i < size; ++i) {
      const FaceChunk::Corners& g = gathered[i];
      const std::uint32_t(&cell)[3] = g.cell;
      if (cell[0] == cell[1] && cell[1] == cell[2]) {
        // Most triangles lie inside one cell: one key, no border crossing, no survivor. In cell units the
        // corners are small numbers: the cross product loses nothing to cancellation.
        // In scalars: Eigen's 3-vector temporaries here were stored as two halves and reloaded as one
        // packet, a store-forwarding stall that took about a tenth of this loop's time.
        FaceChunk::Flat& f = *flat++;
        f.slot = slot_of(cell[0]);
        // The cross product in quanta, exactly, in integers: every difference and product of two quantized
        // offsets is exact in double as well, so this is bit for bit what the same formula gives on the
        // dequantized offsets (but for the sign of a zero, which no sum keeps), with three conversions
        // instead of nine.
        const std::int64_t x0 = quantum(g.q[0], 0), y0 = quantum(g.q[0], 1), z0 = quantum(g.q[0], 2);
        const std::int64_t ax = quantum(g.q[1], 0) - x0, ay = quantum(g.q[1], 1) - y0,
                           az = quantum(g.q[1], 2) - z0;
        const std::int64_t bx = quantum(g.q[2], 0) - x0, by = quantum(g.q[2], 1) - y0,
                           bz = quantum(g.q[2], 2) - z0;
        const double cx = area_scale * static_cast<double>(ay * bz - az * by);
        const double cy = area_scale * static_cast<double>(az * bx - ax * bz);
        const double cz = area_scale * static_cast<double>(ax * by - ay * bx);
        f.cross[0] = cx, f.cross[1] = cy, f.cross[2] = cz;
        const Vec3d& o = run_origin;
        f.offset = -(cx * (o.x() + quantum_size * static_cast<double>(x0)) +
                     cy * (o.y() + quantum_size * static_cast<double>(y0)) +
                     cz * (o.z() + quantum_size * static_cast<double>(z0)));
        continue;
      }
      crossing.push_back(i);
      if (cell[0] != cell[1] && cell[1] != cell[2] && cell[2] != cell[0]) {
        triangles.add(chunk.cursor, static_cast<unsigned>(j), CellTriangle::of(cell[0], cell[1], cell[2]));
        ++chunk.survived;
      }
    }
    const std::span<FaceChunk::Flat> in_one_cell(flats.data(), flat);
    for (FaceChunk::Flat& f : in_one_cell) {
      f.squared = f.cross[0] * f.cross[0] + f.cross[1] * f.cross[1] + f.cross[2] * f.cross[2];
      f.scale = 0.5 / std::sqrt(f.squared);
    }
    {
      // Runs of triangles in one cell add to a quadric held in registers (the same additions in the same
      // order), stored when the cell changes.
      std::uint32_t current = ~std::uint32_t{0};
      QuadricPairs sum;
      for (const FaceChunk::Flat& f : in_one_cell) {
        if (!(f.squared > 0.0 && f.squared <= std::numeric_limits<double>::max())) continue;
        if (f.slot != current) {
          if (current != ~std::uint32_t{0}) sum.store(chunk.quadric(current));
          current = f.slot;
          sum = QuadricPairs::of(chunk.quadric(current));
        }
        TriangleQuadric(f.cross[0], f.cross[1], f.cross[2], f.offset, f.scale).add_to(sum, 3);
      }
      if (current != ~std::uint32_t{0}) sum.store(chunk.quadric(current));
    }
    constexpr std::size_t kBlock = 64;
    Facet facets[kBlock];
    for (std::size_t start = 0; start < crossing.size(); start += kBlock) {
      const int m = static_cast<int>(std::min(kBlock, crossing.size() - start));
      for (int b = 0; b < m; ++b) {
        const FaceChunk::Corners& g = gathered[crossing[start + b]];
        Facet& f = facets[b];
        for (int k = 0; k < 3; ++k) {
          f.index[k] = slot_of(g.cell[k]);
          const Vec3d& o = run_origin;
          for (int a = 0; a < 3; ++a) {
            f.local[k][a] = static_cast<double>(quantum(g.q[k], a)) * (1.0 / kQuantum);
            f.p[k][a] = o[a] + cell_size * f.local[k][a];
          }
        }
        f.set_cross();
      }
      set_inverse_lengths(facets, m);
      for (int b = 0; b < m; ++b) contribute(facets[b], chunk, options.boundary);
    }
    chunk.sort_by_cell();
  };
  cells.input_triangles = run_batches(stream, options.progress, [&](const TriangleBatch& batch) {
    if (!batch.corners.empty()) throw Error(path, {}, "an indexed stream delivered a triangle soup batch");
    const std::size_t n = (batch.triangles.size() + kChunkTriangles - 1) / kChunkTriangles;
    if (chunks.size() < n) {
      chunks.resize(n);
      triangles.add_owners(n);
    }
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t j) { process(batch.triangles, j); });
    merge_chunks(
        chunks.data(), n, count,
        [&](const FaceChunk& chunk, std::uint32_t s, std::uint32_t cell) {
          store.add(cell, chunk.records[s]);
          store.touch(cell);
          if (options.boundary) exact.add(cell, chunk.records[s]);
        },
        [&](std::uint32_t block) { exact.settle(block); });
    for (std::size_t j = 0; j < n; ++j) cells.surviving_instances += chunks[j].survived;
  });
  std::vector<TriangleBuffer::Cursor> cursors;
  for (const FaceChunk& chunk : chunks) cursors.push_back(chunk.cursor);
  chunks = {};
  cells.triangles = triangles.finish(cursors);

  // What is averaged per vertex, from the packed vertices, in fixed chunks of the vertex array merged in
  // order: deferred to here so that these sums do not sit in memory through the face pass.
  CellStore<std::int16_t>& sums = store;
  sums.points.resize(count);  // zeros that take memory only as they are written
  sums.point_sum.resize(count);
  sums.point_box.resize(count);
  const bool normals = vertices.normals.size() == vertex_count;
  const bool colors = vertices.colors.size() == vertex_count;
  const bool uvs = vertices.uvs.size() == vertex_count;
  AttributeSums kinds;
  kinds.normals = normals, kinds.colors = colors, kinds.uvs = uvs;
  kinds.size_cells(cells, count);
  constexpr std::size_t kBlock = 1 << 20;
  static_assert(kBlock % kChunkVertices == 0, "blocks hold whole chunks");
  std::vector<PointChunk> point_chunks(kBlock / kChunkVertices);
  for (std::size_t start = 0; start < vertex_count; start += kBlock) {
    const std::size_t end = std::min(vertex_count, start + kBlock);
    const std::size_t n = (end - start + kChunkVertices - 1) / kChunkVertices;
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t j) {
      PointChunk& chunk = point_chunks[j];
      chunk.clear();
      chunk.attributes.same_as(kinds);
      const std::size_t first = start + j * kChunkVertices, last = std::min(end, first + kChunkVertices);
      if (!normals && !colors && !uvs) {
        // Positions only, the common case, in a loop of its own: a run of vertices in one cell adds to a
        // sum and a box held in registers (the same additions in the same order), stored when the cell
        // changes.
        std::uint32_t current = ~std::uint32_t{0}, s = 0, count_in_run = 0;
        float sx = 0, sy = 0, sz = 0;
        PointBox run_box{};
        auto flush = [&] {
          if (current == ~std::uint32_t{0}) return;
          chunk.points[s] += count_in_run;
          chunk.point_sum[s] = Vec3f(sx, sy, sz);
          merge_box(chunk.point_box[s], run_box);
        };
        for (std::size_t v = first; v < last; ++v) {
          std::uint32_t cell;
          std::uint64_t q;
          unpack(packed[v], cell, q);
          if (!(q & kReferenced)) continue;
          q &= ~kReferenced;
          if (cell != current) {
            flush();
            current = cell;
            s = chunk.slot(cell);
            count_in_run = 0;
            run_box = PointBox{};
            const Vec3f& sum = chunk.point_sum[s];
            sx = sum.x(), sy = sum.y(), sz = sum.z();
          }
          ++count_in_run;
          add_quanta(run_box, q);
          // An offset in quanta is exact in float, and so is its scaling: the bits of dequantize()'s value
          // rounded to float.
          sx += static_cast<float>(quantum(q, 0)) * static_cast<float>(1.0 / kQuantum);
          sy += static_cast<float>(quantum(q, 1)) * static_cast<float>(1.0 / kQuantum);
          sz += static_cast<float>(quantum(q, 2)) * static_cast<float>(1.0 / kQuantum);
        }
        flush();
        chunk.sort_by_cell();
        return;
      }
      for (std::size_t v = first; v < last; ++v) {
        std::uint32_t cell;
        std::uint64_t q;
        unpack(packed[v], cell, q);
        if (!(q & kReferenced)) continue;
        q &= ~kReferenced;
        const std::uint32_t s = chunk.slot(cell);
        ++chunk.points[s];
        chunk.point_sum[s] += dequantize(q).cast<float>();
        add_quanta(chunk.point_box[s], q);
        chunk.attributes.add_vertex(s, vertices, v);
      }
      chunk.sort_by_cell();
    });
    merge_chunks(point_chunks.data(), n, count,
                 [&](const PointChunk& chunk, std::uint32_t s, std::uint32_t cell) {
                   // A cell's mean stays that of the vertices counted, should its count ever saturate.
                   if (sums.points[cell] <= std::numeric_limits<std::uint32_t>::max() - chunk.points[s]) {
                     sums.points[cell] += chunk.points[s];
                     sums.point_sum[cell] += chunk.point_sum[s];
                   }
                   merge_box(sums.point_box[cell], chunk.point_box[s]);
                   chunk.attributes.add_to(cells, cell, s);
                 });
    // These vertices are done with: hand their pages back now rather than when the whole array goes, so that
    // the sums above never sit in memory beside all of it.
    release_pages(positions.data() + start, positions.data() + end);
    if (normals) release_pages(vertices.normals.data() + start, vertices.normals.data() + end);
    if (colors) release_pages(vertices.colors.data() + start, vertices.colors.data() + end);
    if (uvs) release_pages(vertices.uvs.data() + start, vertices.uvs.data() + end);
  }
  point_chunks = {};
  // The stream is exhausted: its vertex array (the largest block of memory in play) is no longer needed.
  vertices = IndexedMesh();

  store.move_into(cells);
  if (options.boundary) {
    cells.border.resize(count);
    tbb::parallel_for(std::size_t{0}, count,
                      [&](std::size_t i) { cells.border[i].crease = store.crease[i]; });
    store.crease = {};
    exact.write(cells.border);
  }
  return cells;
}

// ---- Triangle soups --------------------------------------------------------------------------------------

// What a soup pass says of a NaN or infinite corner, wherever it meets one first.
constexpr const char* kNonFiniteCorner = "a triangle has a non-finite corner";

// One chunk of a triangle soup: partial sums of the cells it touches, by cell key, and its surviving
// triangles.
struct SoupChunk {
  ChunkTable<CellKey> table;
  std::vector<CellRecord> records;
  std::vector<std::uint32_t> points;
  std::vector<Vec3f> point_sum;
  std::vector<PointBox> point_box;
  AttributeSums attributes;
  std::vector<CellTriple<CellKey>> survivors;

  std::uint32_t slot(CellKey key) {
    bool inserted;
    const std::uint32_t s = table.slot(key, inserted);
    if (inserted) {
      records.emplace_back();
      points.push_back(0);
      point_sum.emplace_back(Vec3f::Zero());
      point_box.push_back(PointBox{});
      attributes.push_back();
    }
    return s;
  }
  Quadric& quadric(std::uint32_t s) { return records[s].quadric; }
  CellRecord& record(std::uint32_t s) { return records[s]; }
  void clear() {
    table.clear();
    records.clear();
    points.clear();
    point_sum.clear();
    point_box.clear();
    attributes.clear();
    survivors.clear();
  }
};

// A soup pass's cells, numbered in order of first appearance, chunk by chunk: the numbering, like the sums,
// follows the input alone. Its crease sums are 32-bit until the end of the pass: coarsening halves them,
// which sums wrapped around 16 bits would not survive.
struct SoupCells {
  CellMap map;
  std::vector<CellKey> keys;
  CellStore<std::int32_t> store;
  AttributeSums attributes;

  std::uint32_t number(CellKey key) {
    bool inserted;
    const std::uint32_t i = map.insert(key, static_cast<std::uint32_t>(keys.size()), inserted);
    if (inserted) {
      check_cell_count(keys.size() + 1);
      keys.push_back(key);
      store.push_back();
      attributes.push_back();
    }
    return i;
  }
  // Adds partial sums to cell i, its attributes' from entry j of `from`; `touched`: some triangle touched the
  // part.
  void add(std::uint32_t i, const CellRecord& part, bool touched, std::uint32_t points,
           const Vec3f& point_sum, const PointBox& point_box, const AttributeSums& from, std::uint32_t j) {
    store.add(i, part);
    if (touched) store.touch(i);
    merge_box(store.point_box[i], point_box);
    // A cell's means stay those of the points counted, should its count ever saturate.
    if (store.points[i] <= std::numeric_limits<std::uint32_t>::max() - points) {
      store.points[i] += points;
      store.point_sum[i] += point_sum;
      attributes.add(i, from, j);
    }
  }
};

// The sums gathered so far, moved onto the grid of half the resolution: a soup gives no vertex array to count
// cells on before the pass, so a target-driven pass halves its grid whenever the cells outgrow the target,
// which bounds its memory by the output's size whatever the surface. Every sum is linear, so the result is
// what a pass on the coarser grid would have gathered, except that the border planes of edges that crossed
// between sibling cells stay in their parent (a border running through the cell, where a coarse pass would
// have missed the edges inside it).
void coarsen_soup(Grid& grid, SoupCells& cells, TripleSet<CellKey>& survivors) {
  grid = grid.coarser();
  SoupCells parents;
  parents.map = CellMap(cells.keys.size() / 4);
  parents.attributes.same_as(cells.attributes);
  for (std::size_t i = 0; i < cells.keys.size(); ++i) {
    const auto c = key_coords(cells.keys[i]);
    const Vec3f offset(static_cast<float>(c[0] & 1), static_cast<float>(c[1] & 1),
                       static_cast<float>(c[2] & 1));
    CellRecord part{};
    part.quadric = cells.store.quadrics[i];
    ExactSums exact = cells.store.exact[i];
    CreaseSums<std::int32_t> crease = cells.store.crease[i];
    // The child's frame is y = 2 y' - offset in the parent's. u and m are the same in any frame;
    // y' x u = (y x u + offset x u) / 2 and -m . y' = (-m . y - m . offset) / 2, rounded back to whole units
    // (ties to even) from the exact totals.
    const double o[3] = {offset.x(), offset.y(), offset.z()};
    for (std::array<std::int32_t, 6>& x : exact) {
      const double u[3] = {static_cast<double>(x[0]), static_cast<double>(x[1]), static_cast<double>(x[2])};
      x[3] = static_cast<std::int32_t>(fixed_point(0.5 * (x[3] + (o[1] * u[2] - o[2] * u[1]))));
      x[4] = static_cast<std::int32_t>(fixed_point(0.5 * (x[4] + (o[2] * u[0] - o[0] * u[2]))));
      x[5] = static_cast<std::int32_t>(fixed_point(0.5 * (x[5] + (o[0] * u[1] - o[1] * u[0]))));
    }
    for (std::array<std::int32_t, 4>& w : crease) {
      const double mo = (w[0] * o[0] + w[1] * o[1]) + w[2] * o[2];
      w[3] = static_cast<std::int32_t>(fixed_point(0.5 * (w[3] - mo)));
    }
    part.set_border(exact, crease);
    const std::uint32_t points = cells.store.points[i];
    // A bin b of the child is bin (b + 256 offset) / 2 of the parent, rounded down at both ends: outward.
    const PointBox& box = cells.store.point_box[i];
    PointBox parent_box{};
    if (!box_empty(box)) {
      for (int a = 0; a < 3; ++a) {
        const std::uint32_t shift = (c[a] & 1) * 256;
        add_bin(parent_box, a, (255u - box[a] + shift) / 2);
        add_bin(parent_box, a, (box[a + 3] + shift) / 2);
      }
    }
    parents.add(parents.number(parent_key(cells.keys[i])), part,
                CellStore<std::int32_t>::touched(part.quadric), points,
                0.5f * (cells.store.point_sum[i] + static_cast<float>(points) * offset), parent_box,
                cells.attributes, static_cast<std::uint32_t>(i));
  }
  std::vector<CellTriple<CellKey>> triples;
  survivors.drain_into(triples);
  survivors = TripleSet<CellKey>(triples.size());
  for (const CellTriple<CellKey>& t : triples) {
    const CellKey a = parent_key(t.first()), b = parent_key(t.second()), c = parent_key(t.third());
    if (a == b || b == c || c == a) continue;
    // The canonical order is the input's orientation when seen forward; keep both flags.
    if (t.seen_forward()) survivors.add(CellTriple<CellKey>::of(a, b, c));
    if (t.seen_reversed()) survivors.add(CellTriple<CellKey>::of(a, c, b));
  }
  cells = std::move(parents);
}

// A target-driven soup pass's grid, refined on its first batch. The grid sized for a surface spanning the box
// is too coarse for one that fills little of it (parts far apart, outlier points stretching the box): two
// copies of bunny.stl 50 diagonals apart made 14 faces for --faces 5000. A soup has no vertex array to count
// cells on, so the batch's corners stand in for it: they get the indexed pass's rule (choose_cells), for the
// share of the target that the batch's share of the input would fill. Only refinements are taken; a grid too
// fine for the whole input is coarsened by the pass as its cells outgrow the target, as before, while one too
// coarse could only be refined by a second pass.
Grid refine_on_first_batch(const TriangleStream& stream, const TriangleBatch& first, const Box3& bounds,
                           const PassOptions& options, const Grid& grid) {
  static_assert(sizeof(std::array<Vec3f, 3>) == 3 * sizeof(Vec3f), "a batch's corners lie end to end");
  const std::span<const Vec3f> corners(first.corners.front().data(), 3 * first.corners.size());
  for (const Vec3f& p : corners) {
    if (!p.allFinite()) throw Error(stream.path(), {}, kNonFiniteCorner);
  }
  // The input's triangles: the file says, or its size over the first batch's bytes does (ASCII STL).
  const auto batch = static_cast<double>(first.corners.size());
  double total = static_cast<double>(stream.triangles_hint());
  if (total < batch) {
    const auto read = static_cast<double>(stream.bytes_read());
    total = read > 0 ? batch * static_cast<double>(stream.bytes_total()) / read : batch;
  }
  const double share = std::min(1.0, batch / total);
  PassOptions scaled = options;
  scaled.target_cells = std::max<std::uint64_t>(
      1, static_cast<std::uint64_t>(std::llround(static_cast<double>(options.target_cells) * share)));
  scaled.needed_cells =
      static_cast<std::uint64_t>(std::llround(static_cast<double>(options.needed_cells) * share));
  // A corner's position recurs in each of its triangles: its distinct positions are what the finest grid
  // tells apart.
  double points = -1;
  auto count_points = [&] {
    if (points < 0) {
      std::vector<std::uint64_t> finest;
      distinct_cells(stream.path(), corners, Grid::power_of_two(bounds, kCoordBits), 0, finest);
      points = static_cast<double>(finest.size());
    }
    return points;
  };
  Grid chosen = grid;
  choose_cells(stream.path(), corners, count_points, bounds, scaled, chosen);
  return chosen.level > grid.level ? chosen : grid;
}

FineCells accumulate_soup(TriangleStream& stream, const PassOptions& options) {
  FineCells cells;
  cells.grid = options.grid;
  const bool targeted = options.target_cells > 0 && cells.grid.level >= 0;
  const Box3 bounds = stream.bounds();
  if (targeted) {
    // Sized so a surface spanning the box occupies about the target (a closed surface in its box occupies
    // 1-5 x cells^2 cells); refined on the first batch below.
    const double side = std::sqrt(static_cast<double>(options.target_cells) / 2.0);
    const int level = std::clamp(static_cast<int>(std::ceil(std::log2(std::max(1.0, side)))), 0, kCoordBits);
    cells.grid = Grid::power_of_two(bounds, level);
  }
  Grid grid = cells.grid;
  // The grid the pass starts on (after its first batch): once it has coarsened, an edge that crossed between
  // two of its cells still adds its border sums, now to one cell. Its twin, read before the coarsening,
  // added them to two cells the coarsening merged; skipped, it left them unmatched, an open border in the
  // middle of the surface that pulled the cell's vertex, and where the twins fell about the coarsening
  // followed the input's order (a shuffled bunny.obj clustered out of core moved vertices by 6 % of its
  // size and changed 4,107 of 3,000-odd faces' corners).
  Grid start = grid;
  SoupCells seen;
  bool attributes_known = false;  // set by the first batch with triangles
  TripleSet<CellKey> survivors;
  std::vector<SoupChunk> chunks;
  auto first = [&](const TriangleBatch& batch) {
    if (targeted && !batch.corners.empty())
      grid = refine_on_first_batch(stream, batch, bounds, options, grid);
    start = grid;
  };
  cells.input_triangles = run_batches(stream, options.progress, first, [&](const TriangleBatch& batch) {
    if (!batch.triangles.empty()) {
      throw Error(stream.path(), {}, "a triangle soup stream delivered indexed triangles");
    }
    if (!batch.corners.empty()) {
      const AttributeSums carried = AttributeSums::carried_by(batch, stream.path());
      if (!attributes_known) {
        seen.attributes.same_as(carried);
        attributes_known = true;
      } else if (!seen.attributes.same_kinds(carried)) {
        throw Error(stream.path(), {}, "a triangle soup stream changed the corner attributes it delivers");
      }
    }
    const std::size_t n = (batch.corners.size() + kChunkTriangles - 1) / kChunkTriangles;
    if (chunks.size() < n) chunks.resize(n);
    const bool coarsened = options.boundary && start.level != grid.level;
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t j) {
      SoupChunk& chunk = chunks[j];
      chunk.clear();
      chunk.attributes.same_as(seen.attributes);
      const std::size_t end = std::min(batch.corners.size(), (j + 1) * kChunkTriangles);
      for (std::size_t i = j * kChunkTriangles; i < end; ++i) {
        const auto& corners = batch.corners[i];
        Facet f;
        CellKey key[3], fine[3];
        for (int k = 0; k < 3; ++k) {
          const Vec3d p = corners[k].cast<double>();
          if (!p.allFinite()) throw Error(stream.path(), {}, kNonFiniteCorner);
          Vec3d local;
          key[k] = grid.locate(p, local);
          if (coarsened) fine[k] = start.locate(p);
          const std::uint32_t s = chunk.slot(key[k]);
          f.index[k] = s;
          ++chunk.points[s];
          chunk.point_sum[s] += local.cast<float>();
          add_local(chunk.point_box[s], local);
          chunk.attributes.add_corner(s, batch, i, k);
          for (int a = 0; a < 3; ++a) f.p[k][a] = p[a], f.local[k][a] = local[a];
        }
        f.set_cross();
        set_inverse_lengths(&f, 1);
        contribute(f, chunk, options.boundary, coarsened ? fine : nullptr);
        if (key[0] != key[1] && key[1] != key[2] && key[2] != key[0]) {
          chunk.survivors.push_back(CellTriple<CellKey>::of(key[0], key[1], key[2]));
        }
      }
    });
    // In chunk order, on one thread: the cells' numbers come from this map. A chunk touches few cells and
    // keeps few triangles, next to the work of its triangles.
    for (std::size_t j = 0; j < n; ++j) {
      const SoupChunk& chunk = chunks[j];
      const std::vector<CellKey>& ids = chunk.table.ids();
      for (std::uint32_t s = 0; s < ids.size(); ++s) {
        seen.add(seen.number(ids[s]), chunk.records[s], true, chunk.points[s], chunk.point_sum[s],
                 chunk.point_box[s], chunk.attributes, s);
      }
      for (const CellTriple<CellKey>& t : chunk.survivors) survivors.add(t);
      cells.surviving_instances += chunk.survivors.size();
    }
    // Between batches, whose cuts do not depend on the thread count, so neither does the grid.
    while (options.target_cells > 0 && grid.level > 0 && seen.keys.size() > 2 * options.target_cells) {
      coarsen_soup(grid, seen, survivors);
    }
  });
  cells.grid = grid;
  chunks = {};
  seen.map = CellMap();
  std::vector<CellKey>& keys = seen.keys;
  CellStore<std::int32_t>& store = seen.store;

  // Number the cells in Morton order. Each array moves into that order and is freed before the next one
  // moves, and the triangles are renumbered before any sum moves: with every array copied at once, beside
  // the triangles' set, gen 1 M clustered out of core on a grid of 1024 (501 k cells) peaked at 284 MB.
  const std::size_t count = keys.size();
  std::vector<std::uint32_t> order(count);
  {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> entries(count);
    for (std::size_t i = 0; i < count; ++i) entries[i] = {morton(keys[i]), static_cast<std::uint32_t>(i)};
    tbb::parallel_sort(entries.begin(), entries.end());
    for (std::size_t i = 0; i < count; ++i) order[i] = entries[i].second;
  }
  // Fills `to` with `from` in Morton order and frees `from`.
  auto reorder = [&](auto& to, auto& from, auto&& assign) {
    to.resize(count);
    tbb::parallel_for(std::size_t{0}, count, [&](std::size_t i) { assign(to[i], from[order[i]]); });
    std::remove_reference_t<decltype(from)>().swap(from);
  };
  auto copy = [](auto& to, const auto& from) { to = from; };
  reorder(cells.keys, keys, copy);
  {
    CellMap numbering(count);
    for (std::size_t i = 0; i < count; ++i) {
      bool inserted;
      numbering.insert(cells.keys[i], static_cast<std::uint32_t>(i), inserted);
    }
    std::vector<CellTriple<CellKey>> triples;
    survivors.drain_into(triples);
    cells.triangles.reserve(triples.size());
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
  CellStore<std::int32_t> sorted;
  reorder(sorted.quadrics, store.quadrics, copy);
  if (options.boundary) {
    cells.border.resize(count);
    reorder(cells.border, store.exact, [](BorderSums& to, const ExactSums& from) { to.exact = from; });
    reorder(cells.border, store.crease,
            [](BorderSums& to, const CreaseSums<std::int32_t>& from) { add_wrapping(to.crease, from); });
  }
  reorder(sorted.points, store.points, copy);
  reorder(sorted.point_sum, store.point_sum, copy);
  reorder(sorted.point_box, store.point_box, copy);
  store = {};
  const AttributeSums& attributes = seen.attributes;
  attributes.size_cells(cells, count);
  for (std::size_t i = 0; i < count; ++i) attributes.add_to(cells, static_cast<std::uint32_t>(i), order[i]);
  seen.attributes = {};
  sorted.move_into(cells);
  return cells;
}

}  // namespace

FineCells accumulate(TriangleStream& stream, const PassOptions& options) {
  if (stream.indexed()) return accumulate_indexed(stream, options);
  return accumulate_soup(stream, options);
}

}  // namespace ocsimp::cluster_detail
