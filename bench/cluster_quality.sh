#!/usr/bin/env bash
# Quality of ocsimp's vertex clustering at equal output size (bench/cluster_quality.cpp): the quadric grid
# against meshopt_simplifySloppy at equal face count, quadric against mean and constrained placement on the
# same grid, the octree against the grid at equal vertex count; two-sided RMS and Hausdorff distance as % of
# the original's diagonal. Meshes: bunny, horse and igea from ../shared/data and a generated 10 M-triangle
# scan.
#
#   bench/cluster_quality.sh [BUILD_DIR]      (default: build)
#   env: RATIOS (default 0.1,0.02,0.005), SAMPLES (default 1000000), RUNS (default 3), GENERATED (default
#        10000000 triangles; 0 to skip), DATA (default ../shared/data), SWEEP (default 1)
#
# SWEEP=N measures each ratio r at N nearby ratios instead, r * 1.02^k for N consecutive k starting at
# -floor(N/2), and the closing counts are over all of them. A Hausdorff distance is one worst place, and at a coarse grid it moves
# by tens of percent when the cell size changes by 2 % (a thin leg falls into one cell or two): a comparison
# at a single cell size can go either way by chance, so SWEEP=8 shows how often each one holds.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-$ROOT/build}
DATA=${DATA:-$ROOT/../shared/data}
RATIOS=${RATIOS:-0.1,0.02,0.005}
SAMPLES=${SAMPLES:-1000000}
RUNS=${RUNS:-3}
GENERATED=${GENERATED:-10000000}

SWEEP=${SWEEP:-1}
if [[ ! $SWEEP =~ ^[1-9][0-9]*$ ]]; then
  echo "cluster_quality.sh: SWEEP must be a count of ratios (1 or more), got '$SWEEP'" >&2
  exit 2
fi
if ((SWEEP > 1)); then
  RATIOS=$(awk -v list="$RATIOS" -v n="$SWEEP" 'BEGIN {
    count = split(list, r, ",");
    for (i = 1; i <= count; ++i)
      for (k = -int(n / 2); k < n - int(n / 2); ++k)
        out = out (out == "" ? "" : ",") sprintf("%.6g", r[i] * 1.02 ^ k);
    print out }')
fi

cmake --build "$BUILD" --target cluster_quality >/dev/null
args=(--ratios "$RATIOS" --samples "$SAMPLES" --runs "$RUNS")
for mesh in bunny horse igea; do
  [[ -f $DATA/$mesh.ply ]] && args+=("$mesh=$DATA/$mesh.ply")
done
if [[ $GENERATED != 0 ]]; then args+=(--generate "gen$((GENERATED / 1000000))M=$GENERATED"); fi
"$BUILD/bin/cluster_quality" "${args[@]}"
