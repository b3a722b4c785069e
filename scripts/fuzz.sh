#!/usr/bin/env bash
# Builds the libFuzzer targets (one per reader: ply obj stl drc) with clang, ASan and UBSan into build-fuzz, then
# runs each for a bounded time, seeded from tests/fuzz/seeds, tests/data and the shared meshes when present.
# Exits non-zero if any target finds a crash, a leak, a hang or an oversized allocation; the input that did it
# is saved under build-fuzz/artifacts/<format>/.
#
# Usage: scripts/fuzz.sh [SECONDS_PER_TARGET (default 60)] [FORMAT...]
# Environment: OCSIMP_FUZZ_BUILD (build folder, default <repo>/build-fuzz), OCSIMP_FUZZ_MAX_LEN (bytes, default
# 65536: larger inputs make each run slow; the shared meshes are cut to this length as seeds).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
seconds=${1:-60}
[[ $# -gt 0 ]] && shift
formats=("$@")
[[ ${#formats[@]} -eq 0 ]] && formats=(ply obj stl drc)
build=${OCSIMP_FUZZ_BUILD:-$root/build-fuzz}
max_len=${OCSIMP_FUZZ_MAX_LEN:-65536}
shared=${OCSIMP_SHARED_DATA:-$root/../shared/data}

CC=clang CXX=clang++ cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DOCSIMP_FUZZ=ON \
  -DOCSIMP_BUILD_TESTS=OFF -DOCSIMP_BUILD_BENCH=OFF >/dev/null
cmake --build "$build" -j2 --target "${formats[@]/#/fuzz_}"

failed=()
for format in "${formats[@]}"; do
  corpus=$build/corpus/$format  # grows across runs: libFuzzer adds inputs that reach new code here
  seeds=$build/seeds/$format
  artifacts=$build/artifacts/$format
  mkdir -p "$corpus" "$artifacts"
  rm -rf "$seeds" && mkdir -p "$seeds"
  for folder in "$root/tests/fuzz/seeds/$format" "$root/tests/data" "$shared"; do
    [[ -d $folder ]] || continue
    find "$folder" -type f -iname "*.$format" -print0 | while IFS= read -r -d '' file; do
      cp "$file" "$seeds/$(echo "$file" | md5sum | cut -c1-12)-$(basename "$file")"
    done
  done
  dict=()
  [[ -f $root/tests/fuzz/$format.dict ]] && dict=(-dict="$root/tests/fuzz/$format.dict")  # the format's keywords
  echo "== fuzz_$format: ${seconds}s, $(ls "$seeds" | wc -l) seeds, corpus $(ls "$corpus" | wc -l) inputs"
  if ! "$build/bin/fuzz_$format" -max_total_time="$seconds" -max_len="$max_len" -timeout=10 -rss_limit_mb=2048 \
    -malloc_limit_mb=1024 -print_final_stats=1 -artifact_prefix="$artifacts/" "${dict[@]}" "$corpus" "$seeds" \
    2>"$build/fuzz_$format.log"; then
    failed+=("$format")
    echo "!! fuzz_$format failed; see $build/fuzz_$format.log and $artifacts/" >&2
  fi
  grep -E "^stat::number_of_executed_units|^stat::peak_rss_mb|^#[0-9]+.*DONE" "$build/fuzz_$format.log" || true
done

if [[ ${#failed[@]} -gt 0 ]]; then
  echo "fuzzing found problems in: ${failed[*]}" >&2
  exit 1
fi
echo "fuzzing: no crashes in ${formats[*]} (${seconds}s each)"
