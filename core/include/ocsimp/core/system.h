// Process facts every stage needs: memory (for budgets and reports), progress reporting, cancellation.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "ocsimp/core/error.h"

namespace ocsimp {

// The memory this process can have: the machine's physical memory, or less where its control group (a
// container's memory limit) allows less. A third of it is the default --memory-limit, which in a container
// of 8 GB on a 64 GB host would otherwise be 21 GB.
std::uint64_t physical_memory_bytes();
// The address space this process may have (its RLIMIT_AS, as `ulimit -v` sets it), in bytes; 0 when there
// is no such limit. Code, libraries, thread stacks and the allocator's reserved arenas count against it too.
std::uint64_t address_space_limit();
// A control group's memory limit in bytes (cgroup v2 memory.max, or v1 memory.limit_in_bytes, as a container
// sees its own group); 0 when there is none.
std::uint64_t control_group_memory_limit();

// The threads a parallel stage runs on when asked for `requested` (0 or less: all cores): never more than
// the cores. Outputs never depend on it; more threads than cores only share them, and a thousand of them
// ran out of address space under a 4 GB limit, which TBB reports by aborting.
int worker_threads(int requested);
// Peak and current resident set size of this process (from /proc/self/status); 0 where unknown.
std::uint64_t peak_rss_bytes();
std::uint64_t current_rss_bytes();

// "2G", "512M", "1.5GiB", "100000" (bytes) -> bytes: a plain decimal number (no sign, exponent, hex or
// spaces), then optionally K, M, G, T, P or E (powers of 1024, with or without "B" or "iB", any case). A
// fraction of a unit rounds down to the byte; a byte count must be whole. Throws Error on anything else.
std::uint64_t parse_byte_size(std::string_view text);
std::string format_bytes(std::uint64_t bytes);

// Stages report `done` out of `total` units of work in `phase` (total 0 = unknown). Called from the thread
// that drives the stage, at most every few thousand units, so a callback may draw without locking.
using ProgressFn = std::function<void(std::string_view phase, std::uint64_t done, std::uint64_t total)>;

inline void report(const ProgressFn& progress, std::string_view phase, std::uint64_t done,
                   std::uint64_t total) {
  if (progress) progress(phase, done, total);
}

}  // namespace ocsimp
