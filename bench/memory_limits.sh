#!/usr/bin/env bash
# Whether `ocsimp simplify --memory-limit L` keeps within L: generated scans (with and without normals and
# colors) simplified to each of RATIOS under each of LIMITS. Per run: the path taken (in core, clustered,
# dereferenced out of core), the intermediate and output faces, the peak RSS and its ratio to the limit, and
# whether the run warned that the limit was too small for its target (the only case where it may go over).
#
#   bench/memory_limits.sh [BUILD_DIR]          (default: build)
#   env: TRIANGLES (default 20000000), RATIOS (default "0.01 0.001"), LIMITS (default "100M 200M 300M 400M
#        600M 800M"), TMPDIR (where the meshes and out-of-core files go; default /tmp)
#
# Disk: about 27 bytes a triangle for the plain mesh and 39 for the attributed one, plus what the out-of-core
# runs need under TMPDIR (about 70 bytes a triangle with the attributes). Everything is removed on exit.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-$ROOT/build}
TRIANGLES=${TRIANGLES:-20000000}
RATIOS=${RATIOS:-0.01 0.001}
LIMITS=${LIMITS:-100M 200M 300M 400M 600M 800M}
ocsimp="$BUILD/bin/ocsimp"
[[ -x $ocsimp ]] || { echo "no $ocsimp: build the ocsimp target first" >&2; exit 1; }

work=$(mktemp -d "${TMPDIR:-/tmp}/ocsimp-memory-limits.XXXXXX")
trap 'rm -rf "$work"' EXIT
"$ocsimp" gen -q --triangles "$TRIANGLES" --seed 4 -o "$work/plain.ply"
"$ocsimp" gen -q --triangles "$TRIANGLES" --seed 4 --normals --colors -o "$work/attributed.ply"

echo "| mesh | ratio | limit | path | intermediate | faces | peak RSS | peak / limit | warned |"
echo "|---|---|---|---|---|---|---|---|---|"
over=0
over_unwarned=0
for mesh in plain attributed; do
  for ratio in $RATIOS; do
    for limit in $LIMITS; do
      "$ocsimp" simplify -q "$work/$mesh.ply" -o "$work/out.ply" --ratio "$ratio" --memory-limit "$limit" \
        --report "$work/report.json" 2>"$work/stderr.txt"
      warned=no
      grep -q "over the memory limit" "$work/stderr.txt" && warned=yes
      line=$(python3 - "$work/report.json" "$mesh" "$ratio" "$limit" "$warned" <<'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
mesh, ratio, limit, warned = sys.argv[2:6]
path = "out of core" if r["out_of_core"] else "clustered" if r["clustered"] else "in core"
peak, budget = r["peak_rss_bytes"], r["memory_limit_bytes"]
print(f"| {mesh} | {ratio} | {limit} | {path} | {r['intermediate_faces']} | {r['output_faces']} | "
      f"{peak / 2**20:.0f} MiB | {peak / budget:.2f} | {warned} |")
print("OVER" if peak > budget else "within")
EOF
)
      echo "${line%$'\n'*}"
      if [[ ${line##*$'\n'} == OVER ]]; then
        over=$((over + 1))
        [[ $warned == no ]] && over_unwarned=$((over_unwarned + 1))
      fi
    done
  done
done
echo
echo "runs over their limit: $over, of which without a warning: $over_unwarned"
