#!/bin/sh
# The issue's speed requirement for `ocsimp compare`, end to end through files: a 10 M-triangle scan-like
# original against a 100 k-triangle smooth version, default options (1 M area samples each way plus every
# vertex). Prints wall/CPU seconds and peak memory of the compare run alone.
#
#   bench/compare_large.sh [BUILD_DIR] [ORIGINAL_TRIANGLES] [RESULT_TRIANGLES]
#
# The meshes go to a temporary folder under ${TMPDIR:-/tmp} that is removed on exit.
set -eu
build=${1:-build}
big=${2:-10000000}
small=${3:-100000}
ocsimp="$build/bin/ocsimp"
[ -x "$ocsimp" ] || { echo "no $ocsimp: build the ocsimp target first" >&2; exit 1; }
work=$(mktemp -d "${TMPDIR:-/tmp}/ocsimp-compare.XXXXXX")
trap 'rm -rf "$work"' EXIT INT TERM

"$ocsimp" gen -q -o "$work/original.ply" --triangles "$big"
"$ocsimp" gen -q -o "$work/result.ply" --triangles "$small" --noise 0
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
/usr/bin/time -f "compare: %e s wall, %U s user, %S s system, %M KB peak" \
  "$ocsimp" compare -q "$work/original.ply" "$work/result.ply" --report "$work/report.json"
