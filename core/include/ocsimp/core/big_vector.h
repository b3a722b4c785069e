// An allocator for large arrays that asks Linux for transparent huge pages. The decimator's collapse loop and
// the octree's merge loop visit their records in priority order, which is random in memory: with 4 KiB pages
// nearly every visit to a multi-gigabyte array also misses the TLB, and 2 MiB pages remove most of those
// misses. Huge pages also cut the page faults of first touch: the 960 MB of cluster records of a 5 M-cell
// octree (a 10 M-triangle scan to 1 M faces) took 3.0 s to construct on 4 KiB pages, 1.3 s on these (one
// run each; the whole run, 13.70 -> 13.01 s, median of 3).
#pragma once

#include <cstddef>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace ocsimp {

// True for record types that `resize` should leave unconstructed even though their members have default
// values: aggregates of plain numbers (so operator new's storage already holds such objects) that the loop
// filling the array right after sizing it writes in full. The vertex records are one: constructing them
// zeroed their quadrics in a serial pass over the whole array, which below 8 MiB was also the first touch of
// each page, so those page faults (about 1.6 us each on this VM) all fell on one core.
template <class T>
inline constexpr bool filled_after_resize = false;

// `bytes` on transparent huge pages where the system has them, every page already touched, on all cores;
// throws std::bad_alloc. And its release.
void* allocate_huge(std::size_t bytes);
void free_huge(void* p, std::size_t bytes) noexcept;

template <class T>
struct BigAllocator {
  using value_type = T;
  // Below this, huge pages would waste more than they save.
  static constexpr std::size_t min_huge_bytes = std::size_t{8} << 20;

  BigAllocator() = default;
  template <class U>
  BigAllocator(const BigAllocator<U>&) noexcept {}

  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T)) throw std::bad_alloc();
    const std::size_t bytes = n * sizeof(T);
    if (bytes >= min_huge_bytes) return static_cast<T*>(allocate_huge(bytes));
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
    if (bytes >= min_huge_bytes) {
      free_huge(p, bytes);
      return;
    }
    ::operator delete (p, std::align_val_t{alignof(T)});
  }

  template <class U>
  bool operator==(const BigAllocator<U>&) const noexcept {
    return true;
  }
};

template <class T>
using BigVector = std::vector<T, BigAllocator<T>>;

}  // namespace ocsimp
