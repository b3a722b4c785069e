// Open-addressing hash tables for the cluster stage: cell keys, cell key -> index, cell triangles.
// Linear probing over flat arrays: the pass spends its time in these lookups, and node-based maps would cost
// a pointer chase and an allocation per cell.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "grid.h"

namespace ocsimp::cluster_detail {

inline std::size_t power_of_two_at_least(std::size_t n) {
  std::size_t p = 16;
  while (p < n) p <<= 1;
  return p;
}

// A set of cell keys, at most half full.
class KeySet {
 public:
  explicit KeySet(std::size_t expected = 0) { rehash(power_of_two_at_least(2 * expected)); }

  bool insert(CellKey key) {
    if (2 * (size_ + 1) > slots_.size()) rehash(2 * slots_.size());
    std::size_t i = mix64(key) & mask_;
    while (slots_[i] != kNoKey) {
      if (slots_[i] == key) return false;
      i = (i + 1) & mask_;
    }
    slots_[i] = key;
    ++size_;
    return true;
  }
  std::size_t size() const { return size_; }
  template <class F>
  void for_each(F&& f) const {
    for (CellKey key : slots_)
      if (key != kNoKey) f(key);
  }
  void clear() {
    slots_ = {};
    size_ = 0;
    rehash(16);
  }

 private:
  void rehash(std::size_t capacity) {
    std::vector<CellKey> old = std::move(slots_);
    slots_.assign(capacity, kNoKey);
    mask_ = capacity - 1;
    for (CellKey key : old) {
      if (key == kNoKey) continue;
      std::size_t i = mix64(key) & mask_;
      while (slots_[i] != kNoKey) i = (i + 1) & mask_;
      slots_[i] = key;
    }
  }

  std::vector<CellKey> slots_;
  std::size_t mask_ = 0;
  std::size_t size_ = 0;
};

// Cell key -> 32-bit value, at most half full.
class CellMap {
 public:
  static constexpr std::uint32_t kMissing = ~std::uint32_t{0};

  explicit CellMap(std::size_t expected = 0) { rehash(power_of_two_at_least(2 * expected)); }

  // The value stored for `key`; stores `value` first when the key is new (and sets `inserted`).
  std::uint32_t insert(CellKey key, std::uint32_t value, bool& inserted) {
    if (2 * (size_ + 1) > slots_.size()) rehash(2 * slots_.size());
    std::size_t i = mix64(key) & mask_;
    while (slots_[i].key != kNoKey) {
      if (slots_[i].key == key) {
        inserted = false;
        return slots_[i].value;
      }
      i = (i + 1) & mask_;
    }
    slots_[i] = {key, value};
    ++size_;
    inserted = true;
    return value;
  }
  std::uint32_t find(CellKey key) const {
    std::size_t i = mix64(key) & mask_;
    while (slots_[i].key != kNoKey) {
      if (slots_[i].key == key) return slots_[i].value;
      i = (i + 1) & mask_;
    }
    return kMissing;
  }
  std::size_t size() const { return size_; }
  template <class F>
  void for_each(F&& f) const {
    for (const Slot& s : slots_)
      if (s.key != kNoKey) f(s.key, s.value);
  }

 private:
  struct Slot {
    CellKey key;
    std::uint32_t value;
  };
  void rehash(std::size_t capacity) {
    std::vector<Slot> old = std::move(slots_);
    slots_.assign(capacity, Slot{kNoKey, 0});
    mask_ = capacity - 1;
    for (const Slot& s : old) {
      if (s.key == kNoKey) continue;
      std::size_t i = mix64(s.key) & mask_;
      while (slots_[i].key != kNoKey) i = (i + 1) & mask_;
      slots_[i] = s;
    }
  }

  std::vector<Slot> slots_;
  std::size_t mask_ = 0;
  std::size_t size_ = 0;
};

// A triangle of three distinct cells, stored with its cells ascending. The top bit of `b` says the input
// showed it as (a, b, c) (or a rotation), the top bit of `c` as (a, c, b): keeping both instead of the first
// one seen makes the output orientation independent of the input's triangle order.
template <class T>
struct CellTriple {
  static constexpr T kFlag = T{1} << (8 * sizeof(T) - 1);
  static constexpr T kEmpty = ~T{0};
  T a, b, c;

  T first() const { return a; }
  T second() const { return b & ~kFlag; }
  T third() const { return c & ~kFlag; }
  bool seen_forward() const { return (b & kFlag) != 0; }
  bool seen_reversed() const { return (c & kFlag) != 0; }
  bool same_cells(const CellTriple& o) const {
    return a == o.a && second() == o.second() && third() == o.third();
  }

  // Triangle (x, y, z) in the input's orientation; the three must be distinct and below kFlag.
  static CellTriple of(T x, T y, T z) {
    bool even;
    T lo, mid, hi;
    if (x < y) {
      if (y < z) {
        lo = x, mid = y, hi = z, even = true;
      } else if (x < z) {
        lo = x, mid = z, hi = y, even = false;
      } else {
        lo = z, mid = x, hi = y, even = true;
      }
    } else {
      if (x < z) {
        lo = y, mid = x, hi = z, even = false;
      } else if (y < z) {
        lo = y, mid = z, hi = x, even = true;
      } else {
        lo = z, mid = y, hi = x, even = false;
      }
    }
    return {lo, even ? (mid | kFlag) : mid, even ? hi : (hi | kFlag)};
  }
  void merge_flags(const CellTriple& o) {
    b |= o.b & kFlag;
    c |= o.c & kFlag;
  }
  // The output triangle: the orientation the input showed, or (a, b, c) when it showed both.
  std::array<T, 3> oriented() const {
    if (seen_reversed() && !seen_forward()) return {a, third(), second()};
    return {a, second(), third()};
  }
  std::uint64_t hash() const {
    return mix64((static_cast<std::uint64_t>(a) * 0x9E3779B97F4A7C15ull) ^
                 mix64(static_cast<std::uint64_t>(second()) + 0x632BE59BD9B4E019ull * third()));
  }
  bool operator<(const CellTriple& o) const {
    if (a != o.a) return a < o.a;
    if (second() != o.second()) return second() < o.second();
    return third() < o.third();
  }
};

// A set of cell triangles merging the orientation flags of repeats. Capacity is not a power of two (slots
// are found by multiply-shift) so that it can be sized close to the expected count: triangles are a good
// part of the cluster stage's memory.
template <class T>
class TripleSet {
 public:
  using Triple = CellTriple<T>;

  explicit TripleSet(std::size_t expected = 0) { rehash(std::max<std::size_t>(16, expected * 4 / 3 + 16)); }

  // Returns true when the three cells are new.
  bool add(const Triple& t) {
    if (4 * (size_ + 1) > 3 * slots_.size()) rehash(slots_.size() + slots_.size() / 2);
    std::size_t i = slot_of(t.hash());
    while (slots_[i].a != Triple::kEmpty) {
      if (slots_[i].same_cells(t)) {
        slots_[i].merge_flags(t);
        return false;
      }
      if (++i == slots_.size()) i = 0;
    }
    slots_[i] = t;
    ++size_;
    return true;
  }
  std::size_t size() const { return size_; }
  // Appends the triangles to `out` and empties the set.
  void drain_into(std::vector<Triple>& out) {
    out.reserve(out.size() + size_);  // grown by doubling, it took up to twice the room beside the slots
    for (const Triple& t : slots_)
      if (t.a != Triple::kEmpty) out.push_back(t);
    slots_ = {};
    size_ = 0;
  }

 private:
  std::size_t slot_of(std::uint64_t hash) const {
    return static_cast<std::size_t>((static_cast<unsigned __int128>(hash) * slots_.size()) >> 64);
  }
  void rehash(std::size_t capacity) {
    std::vector<Triple> old = std::move(slots_);
    slots_.assign(capacity, Triple{Triple::kEmpty, 0, 0});
    for (const Triple& t : old) {
      if (t.a == Triple::kEmpty) continue;
      std::size_t i = slot_of(t.hash());
      while (slots_[i].a != Triple::kEmpty)
        if (++i == slots_.size()) i = 0;
      slots_[i] = t;
    }
  }

  std::vector<Triple> slots_;
  std::size_t size_ = 0;
};

}  // namespace ocsimp::cluster_detail
