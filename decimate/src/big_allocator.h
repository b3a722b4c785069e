// An allocator for the decimator's large arrays that asks Linux for transparent huge pages. The collapse loop
// visits its records in priority order, which is random in memory: with 4 KiB pages nearly every visit to a
// multi-gigabyte mesh also misses the TLB, and 2 MiB pages remove most of those misses.
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace ocsimp::decimate_detail {

// True for record types that `resize` should leave unconstructed even though their members have default
// values: aggregates of plain numbers (so operator new's storage already holds such objects) that the loop
// filling the array right after sizing it writes in full. The vertex records are one: constructing them
// zeroed their quadrics in a serial pass over the whole array, which below 8 MiB was also the first touch of
// each page, so those page faults (about 1.6 us each on this VM) all fell on one core.
template <class T>
inline constexpr bool filled_after_resize = false;

template <class T>
struct BigAllocator {
  using value_type = T;
  // Below this, huge pages would waste more than they save.
  static constexpr std::size_t min_huge_bytes = std::size_t{8} << 20;

  BigAllocator() = default;
  template <class U>
  BigAllocator(const BigAllocator<U>&) noexcept {}

  // The kernel zeroes a page at its first touch, which on a VM costs far more than writing the page (about
  // 0.5 GB/s here). Touched in the loops that fill these arrays, that cost fell on whichever thread wrote
  // first: the vertex records are zeroed one by one as `resize` constructs them, so on a 10 M-triangle mesh a
  // serial loop took a tenth of the decimation's CPU time in page faults. Touching every page here, on all
  // cores, keeps it off the serial loops. (Fresh pages read as zero: writing a zero changes nothing.)
  static void touch_pages(char* p, std::size_t bytes) {
    constexpr std::size_t kPage = 4096, kPiece = std::size_t{2} << 20;
    tbb::parallel_for(std::size_t{0}, (bytes + kPiece - 1) / kPiece, [&](std::size_t piece) {
      const std::size_t end = std::min(bytes, (piece + 1) * kPiece);
      for (std::size_t at = piece * kPiece; at < end; at += kPage) static_cast<volatile char*>(p)[at] = 0;
    });
  }

  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T)) throw std::bad_alloc();
    const std::size_t bytes = n * sizeof(T);
#if defined(__linux__)
    if (bytes >= min_huge_bytes) {
      void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
      if (p == MAP_FAILED) throw std::bad_alloc();
      madvise(p, bytes, MADV_HUGEPAGE);  // advice only: without huge pages the memory works the same
      touch_pages(static_cast<char*>(p), bytes);
      return static_cast<T*>(p);
    }
#endif
    return static_cast<T*>(::operator new (bytes, std::align_val_t{alignof(T)}));
  }

  // Elements added by resize are default-initialized, not zeroed: every array here is written in full right
  // after it is sized, and zeroing first touched each page one more time (about 1.3 GB on a 10 M-triangle
  // mesh).
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    static_assert(!filled_after_resize<U> || std::is_trivially_destructible_v<U>);
    if constexpr (!filled_after_resize<U>) ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }

  void deallocate(T* p, std::size_t n) noexcept {
    const std::size_t bytes = n * sizeof(T);
#if defined(__linux__)
    if (bytes >= min_huge_bytes) {
      munmap(p, bytes);
      return;
    }
#endif
    ::operator delete (p, std::align_val_t{alignof(T)});
  }

  template <class U>
  bool operator==(const BigAllocator<U>&) const noexcept {
    return true;
  }
};

template <class T>
using BigVector = std::vector<T, BigAllocator<T>>;

}  // namespace ocsimp::decimate_detail
