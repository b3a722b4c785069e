#!/usr/bin/env bash
# ocsimp decimate against meshoptimizer's meshopt_simplify: speed, quality and memory.
#
#   bench/decimate_vs_meshopt.sh [BUILD_DIR]        (default build dir: build)
#
# 1. Builds the `ocsimp` and `decimate_vs_meshopt` targets.
# 2. Generates scan-like 1 M and 10 M triangle meshes with `ocsimp gen` under $TMPDIR (default /tmp).
# 3. Runs both simplifiers in one process on bunny, horse and igea (../shared/data) and the generated meshes,
#    to 10 % and 1 % of the faces (or RATIOS): time of the call (RUNS runs alternating between the two,
#    medians of the times and of the run-by-run ratios; one run for 10 M), two-sided RMS and Hausdorff
#    distance to the original (SAMPLES area samples each way, plus vertices; the Hausdorff distance refined).
# 4. Runs `ocsimp decimate` on the 10 M mesh and prints its peak RSS per input triangle (the issue's limit is 150).
# 5. Deletes the generated meshes.
#
# Environment: RUNS (default 3), SAMPLES (default 1000000), THREADS (default 0: all cores), DATA (default
# <repo>/../shared/data), RATIOS (the targets, default 0.1,0.01), SKIP_10M=1 to leave out the 10 M mesh.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-$repo/build}"
runs="${RUNS:-3}"
samples="${SAMPLES:-1000000}"
threads="${THREADS:-0}"
ratio_args=()  # the bench's own default targets unless RATIOS is given
[[ -n "${RATIOS:-}" ]] && ratio_args=(--ratios "$RATIOS")
data="${DATA:-$repo/../shared/data}"
work="$(mktemp -d "${TMPDIR:-/tmp}/decimate-bench.XXXXXX")"
trap 'rm -rf "$work"' EXIT

cmake --build "$build" -j2 --target ocsimp decimate_vs_meshopt >/dev/null
ocsimp="$build/bin/ocsimp"
bench="$build/bin/decimate_vs_meshopt"

echo "## generating meshes in $work"
"$ocsimp" gen -o "$work/gen1m.ply" --triangles 1000000 --seed 1 -q
if [[ "${SKIP_10M:-0}" != 1 ]]; then
  "$ocsimp" gen -o "$work/gen10m.ply" --triangles 10000000 --seed 2 -q
fi

echo "## speed and quality (bench: $bench)"
meshes=()
for name in bunny horse igea; do
  [[ -f "$data/$name.ply" ]] && meshes+=("$name=$data/$name.ply")
done
"$bench" --runs "$runs" --samples "$samples" --threads "$threads" "${ratio_args[@]}" "${meshes[@]}" "gen1m=$work/gen1m.ply"
if [[ "${SKIP_10M:-0}" != 1 ]]; then
  "$bench" --runs 1 --samples "$samples" --threads "$threads" "${ratio_args[@]}" "gen10m=$work/gen10m.ply" | tail -n +5

  echo
  echo "## memory: ocsimp decimate on the 10 M mesh to 1 %"
  "$ocsimp" decimate "$work/gen10m.ply" -o "$work/out.ply" --ratio 0.01 --threads "$threads" \
    --report "$work/report.json" -q
  python3 - "$work/report.json" <<'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
print(f"input {r['input']['faces']} faces -> {r['output']['faces']} faces in {r['seconds']['decimate']:.1f} s "
      f"(total {r['seconds']['total']:.1f} s); peak RSS {r['peak_rss_bytes'] / 2**20:.0f} MiB = "
      f"{r['peak_rss_bytes_per_input_face']:.1f} bytes per input triangle")
EOF
fi
