#!/usr/bin/env bash
# Two-stage simplification (cluster, then decimate with the cluster quadrics carried) against pure
# decimation at the same face count: two-sided RMS distance to the original (`ocsimp compare --json`) and
# CPU time (user + system), as ratios two-stage / pure, with the intermediate's face count ("none": the input
# is no larger than its intermediate, so the pipeline decimates it directly). Meshes: a generated scan
# (GENERATED triangles, default 10^7) and the meshes of ../shared/data; face counts 1% and 0.1% of the input.
#
#   bench/two_stage_quality.sh [BUILD_DIR]      (default: build)
#   env: GENERATED (default 10000000; 0 to skip), RATIOS (default "0.01 0.001"), SAMPLES (compare samples,
#        default 1000000), MESHES (default: all eight shared meshes; "" for none), DATA (default ../shared/data)
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-$ROOT/build}
DATA=${DATA:-$ROOT/../shared/data}
GENERATED=${GENERATED:-10000000}
RATIOS=${RATIOS:-0.01 0.001}
SAMPLES=${SAMPLES:-1000000}
MESHES=${MESHES-bunny horse igea fandisk rocker-arm spot homer teapot}
ocsimp="$BUILD/bin/ocsimp"
[[ -x $ocsimp ]] || { echo "no $ocsimp: build the ocsimp target first" >&2; exit 1; }
work=$(mktemp -d "${TMPDIR:-/tmp}/ocsimp-two-stage.XXXXXX")
trap 'rm -rf "$work"' EXIT INT TERM

inputs=()
if [[ $GENERATED != 0 ]]; then
  "$ocsimp" gen -q -o "$work/gen.ply" --triangles "$GENERATED"
  inputs+=("$work/gen.ply")
fi
for mesh in $MESHES; do
  for ext in ply obj; do
    if [[ -f $DATA/$mesh.$ext ]]; then
      inputs+=("$DATA/$mesh.$ext")
      break
    fi
  done
done

# CPU seconds (user + system) of one command, its output discarded.
cpu() {
  /usr/bin/time -f "%U %S" -o "$work/time" "$@" >/dev/null
  awk '{print $1 + $2}' "$work/time"
}
rms() { "$ocsimp" compare -q --json --samples "$SAMPLES" "$1" "$2" | python3 -c 'import json,sys; print(json.load(sys.stdin)["rms"])'; }

echo "load average: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
printf "%-10s %8s %10s %12s %12s %12s %8s %9s %9s %8s\n" mesh ratio faces intermediate "rms pure" "rms 2-stage" \
  "rms x" "cpu pure" "cpu 2-st" speedup
for input in "${inputs[@]}"; do
  faces_in=$("$ocsimp" info --json "$input" | python3 -c 'import json,sys; print(json.load(sys.stdin)["faces"])')
  name=$(basename "${input%.*}")
  for ratio in $RATIOS; do
    faces=$(python3 -c "print(max(4, round($ratio * $faces_in)))")
    pure_cpu=$(cpu "$ocsimp" decimate -q "$input" -o "$work/pure.ply" --faces "$faces")
    two_cpu=$(cpu "$ocsimp" simplify -q "$input" -o "$work/two.ply" --faces "$faces" --two-stage \
      --report "$work/report.json")
    inter=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["intermediate_faces"])' "$work/report.json")
    pure_rms=$(rms "$input" "$work/pure.ply")
    two_rms=$(rms "$input" "$work/two.ply")
    python3 -c "
p, t, pc, tc = $pure_rms, $two_rms, $pure_cpu, $two_cpu
print(f'%-10s %8s %10d %12s %12.4g %12.4g %8.3f %9.2f %9.2f %8.2f' % ('$name', '$ratio', $faces, '$inter' if $inter else 'none', p, t, t / p if p else float('nan'), pc, tc, pc / tc if tc else float('nan')))"
  done
done
