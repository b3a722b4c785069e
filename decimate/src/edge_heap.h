// A d-ary min-heap of (key, edge) with each edge's position kept in the caller's edge records, so a key can
// go up or down in place after a re-cost. Keys are floats: 8-byte entries keep the heap compact (the
// decimator scales costs into float's range), and with 8 children a node's children fill about one cache line
// (measured against 4: about 5 % fewer cycles on a 1 M-triangle decimation).
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "ocsimp/core/big_vector.h"

namespace ocsimp::decimate_detail {

// Slot values at or above `first_state` are not heap positions but states of an edge that is out of the heap.
constexpr std::uint32_t first_state = 0xFFFFFFF0u;

struct HeapEntry {
  float key;
  std::uint32_t edge;
};

class EdgeHeap {
 public:
  static constexpr std::size_t arity = 8;

  // Edge e's slot is slots[e * stride] (it lives inside the caller's edge records, which must outlive the
  // heap).
  EdgeHeap(std::uint32_t* slots, std::size_t stride) : slots_(slots), stride_(stride) {}

  std::size_t size() const { return entries_.size(); }
  bool empty() const { return entries_.empty(); }
  const HeapEntry& top() const { return entries_.front(); }
  const HeapEntry& entry(std::size_t i) const { return entries_[i]; }
  void prefetch(std::size_t i) const { __builtin_prefetch(&entries_[i]); }
  // The edge at heap position i got a new id (its record, slot included, moved there).
  void rename(std::size_t i, std::uint32_t edge) { entries_[i].edge = edge; }

  // Takes `entries` (any order) as the whole heap and orders it in linear time.
  void assign(BigVector<HeapEntry> entries) {
    entries_ = std::move(entries);
    for (std::size_t i = 0; i < entries_.size(); ++i) slot(entries_[i].edge) = static_cast<std::uint32_t>(i);
    if (entries_.size() > 1) {
      for (std::size_t i = (entries_.size() - 2) / arity + 1; i-- > 0;) sift_down(i);
    }
  }

  void push(std::uint32_t edge, float key) {
    entries_.push_back({key, edge});
    sift_up(entries_.size() - 1);
  }

  // Sets a contained edge's key, moving it either way.
  void update(std::uint32_t edge, float key) {
    const std::size_t i = slot(edge);
    const float old = entries_[i].key;
    entries_[i].key = key;
    if (key < old) {
      sift_up(i);
    } else if (key > old) {
      sift_down(i);
    }
  }

  // Removes a contained edge and marks its slot with `state`.
  void remove(std::uint32_t edge, std::uint32_t state) {
    const std::size_t i = slot(edge);
    slot(edge) = state;
    const HeapEntry last = entries_.back();
    entries_.pop_back();
    if (i == entries_.size()) return;
    entries_[i] = last;
    if (i > 0 && last.key < entries_[(i - 1) / arity].key) {
      sift_up(i);
    } else {
      sift_down(i);
    }
  }

 private:
  std::uint32_t& slot(std::uint32_t edge) { return slots_[edge * stride_]; }

  void sift_up(std::size_t i) {
    const HeapEntry moving = entries_[i];
    while (i > 0) {
      const std::size_t parent = (i - 1) / arity;
      if (!(moving.key < entries_[parent].key)) break;
      entries_[i] = entries_[parent];
      slot(entries_[i].edge) = static_cast<std::uint32_t>(i);
      i = parent;
    }
    entries_[i] = moving;
    slot(moving.edge) = static_cast<std::uint32_t>(i);
  }

  void sift_down(std::size_t i) {
    const HeapEntry moving = entries_[i];
    const std::size_t n = entries_.size();
    HeapEntry* const entries = entries_.data();
    for (;;) {
      const std::size_t first = arity * i + 1;
      if (first >= n) break;
      // The first child with the least key, as a left-to-right scan finds it; written so that the compiler
      // selects instead of branching, and unrolled for a full set of children.
      std::size_t best = first;
      float best_key = entries[first].key;
      auto visit = [&](std::size_t c) {
        const float k = entries[c].key;
        const bool less = k < best_key;
        best = less ? c : best;
        best_key = less ? k : best_key;
      };
      if (first + arity <= n) {
        for (std::size_t c = first + 1; c < first + arity; ++c) visit(c);
      } else {
        for (std::size_t c = first + 1; c < n; ++c) visit(c);
      }
      if (!(best_key < moving.key)) break;
      entries[i] = entries[best];
      slot(entries[i].edge) = static_cast<std::uint32_t>(i);
      i = best;
    }
    entries[i] = moving;
    slot(moving.edge) = static_cast<std::uint32_t>(i);
  }

  BigVector<HeapEntry> entries_;
  std::uint32_t* slots_;
  std::size_t stride_;
};

}  // namespace ocsimp::decimate_detail
