#!/usr/bin/env bash
# Quality of ocsimp's vertex clustering at equal output size (bench/cluster_quality.cpp): the quadric grid
# against meshopt_simplifySloppy at equal face count, quadric against mean and constrained placement on the
# same grid, the octree against the grid at equal vertex count; two-sided RMS and Hausdorff distance as % of
# the original's diagonal. Meshes: bunny, horse and igea from ../shared/data and a generated 10 M-triangle
# scan.
#
#   bench/cluster_quality.sh [BUILD_DIR]      (default: build)
#   env: RATIOS (default 0.1,0.02,0.005), SAMPLES (default 1000000), RUNS (default 3), GENERATED (default
#        10000000 triangles; 0 to skip), DATA (default ../shared/data)
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-$ROOT/build}
DATA=${DATA:-$ROOT/../shared/data}
RATIOS=${RATIOS:-0.1,0.02,0.005}
SAMPLES=${SAMPLES:-1000000}
RUNS=${RUNS:-3}
GENERATED=${GENERATED:-10000000}

cmake --build "$BUILD" --target cluster_quality >/dev/null
args=(--ratios "$RATIOS" --samples "$SAMPLES" --runs "$RUNS")
for mesh in bunny horse igea; do
  [[ -f $DATA/$mesh.ply ]] && args+=("$mesh=$DATA/$mesh.ply")
done
if [[ $GENERATED != 0 ]]; then args+=(--generate "gen$((GENERATED / 1000000))M=$GENERATED"); fi
"$BUILD/bin/cluster_quality" "${args[@]}"
