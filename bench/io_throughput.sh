#!/usr/bin/env bash
# PLY read and write throughput against `cat`, measured in the same run from page cache.
#
#   bench/io_throughput.sh [BUILD_DIR]      (default: build)
#   env: TRIANGLES (default 10000000), RUNS (default 5), WORK (default a fresh folder under /tmp)
#
# Makes a binary PLY of TRIANGLES triangles (with `ocsimp gen` when built, else bench_io_throughput gen) and
# its ascii twin, then for each case takes the median of RUNS runs of `cat FILE > /dev/null` (for writes:
# `cat FILE > NEW_FILE`, the same bytes) and of ours, and prints a table. "vs cat" is our throughput over
# cat's: 1.0 is as fast as cat, 0.5 half as fast. Our time is measured inside the process around the call
# (read_mesh, draining the stream, or write_mesh); cat's around the whole command. "ours cpu" is the CPU
# time of the call: on a shared machine, wall time also counts waiting for a core.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-$ROOT/build}
TRIANGLES=${TRIANGLES:-10000000}
RUNS=${RUNS:-5}
WORK=${WORK:-$(mktemp -d /tmp/ocsimp-io-XXXXXX)}
mkdir -p "$WORK"
trap 'rm -rf "$WORK"' EXIT

cmake --build "$BUILD" --target bench_io_throughput >/dev/null
BENCH=$BUILD/bin/bench_io_throughput
OCSIMP=$BUILD/bin/ocsimp

BINARY=$WORK/binary.ply
ASCII=$WORK/ascii.ply
if [[ -x $OCSIMP ]] && "$OCSIMP" gen -q -o "$BINARY" --triangles "$TRIANGLES" 2>/dev/null; then
  generator="ocsimp gen"
else
  "$BENCH" gen "$BINARY" --triangles "$TRIANGLES" >/dev/null
  generator="bench_io_throughput gen (wavy torus)"
fi
"$BENCH" write "$BINARY" "$ASCII" --ascii >/dev/null
OBJ=$WORK/mesh.obj
"$BENCH" write "$BINARY" "$OBJ" >/dev/null
echo "inputs: $generator, $(head -c 400 "$BINARY" | grep -a '^element face' | cut -d' ' -f3) faces; $RUNS runs each; medians"

now_ns() { date +%s%N; }
median() { sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
field() { tr ' ' '\n' | grep "^$1=" | cut -d= -f2; }

printf '%-22s %7s %8s %8s %9s %9s %7s\n' case MB "cat s" "ours s" "ours cpu" "ours MB/s" "vs cat"

# run_case NAME FILE_FOR_CAT WRITE(0/1) COMMAND...
run_case() {
  local name=$1 input=$2 write=$3
  shift 3
  local cat_times=() our_times=() our_cpu=() bytes=0
  cat "$input" >/dev/null  # into page cache
  for ((run = 0; run < RUNS; ++run)); do
    local start end out
    if [[ $write == 1 ]]; then
      rm -f "$WORK/cat_copy.ply"
      start=$(now_ns); cat "$input" >"$WORK/cat_copy.ply"; end=$(now_ns)
      rm -f "$WORK/cat_copy.ply" "$WORK/out.ply"  # new files: ext4 flushes files replaced in place
    else
      start=$(now_ns); cat "$input" >/dev/null; end=$(now_ns)
    fi
    cat_times+=("$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.6f", (b - a) / 1e9 }')")
    out=$("$@")
    our_times+=("$(echo "$out" | field seconds)")
    our_cpu+=("$(echo "$out" | field cpu)")
    bytes=$(echo "$out" | field bytes)
  done
  rm -f "$WORK/out.ply"
  local cat_s ours_s cpu_s
  cat_s=$(printf '%s\n' "${cat_times[@]}" | median)
  ours_s=$(printf '%s\n' "${our_times[@]}" | median)
  cpu_s=$(printf '%s\n' "${our_cpu[@]}" | median)
  awk -v n="$name" -v b="$bytes" -v c="$cat_s" -v o="$ours_s" -v u="$cpu_s" 'BEGIN {
    mb = b / 1e6
    printf "%-22s %7.1f %8.4f %8.4f %9.4f %9.0f %7.2f\n", n, mb, c, o, u, mb / o, c / o
  }'
}

run_case "binary read_mesh" "$BINARY" 0 "$BENCH" read "$BINARY"
run_case "binary drain stream" "$BINARY" 0 "$BENCH" drain "$BINARY"
run_case "ascii read_mesh" "$ASCII" 0 "$BENCH" read "$ASCII"
run_case "ascii drain stream" "$ASCII" 0 "$BENCH" drain "$ASCII"
run_case "obj read_mesh" "$OBJ" 0 "$BENCH" read "$OBJ"
run_case "obj drain stream" "$OBJ" 0 "$BENCH" drain "$OBJ"
run_case "binary write_mesh" "$BINARY" 1 "$BENCH" write "$BINARY" "$WORK/out.ply"
run_case "ascii write_mesh" "$ASCII" 1 "$BENCH" write "$BINARY" "$WORK/out.ply" --ascii
