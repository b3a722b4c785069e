#!/usr/bin/env bash
# One-pass clustering throughput on a big binary PLY from `ocsimp gen`, read from page cache, beside the time
# `cat` takes to read the same file, and the run's peak RSS against the cluster stage's budget: 12 bytes per
# input vertex plus 200 bytes per occupied fine cell.
#
#   bench/cluster_throughput.sh [BUILD_DIR]      (default: build)
#   env: TRIANGLES (default 100000000), GRID (cells along the longest axis, default 500: about 1 M cells on
#        the generated blob), RUNS (default 3), THREADS (default 0: all cores), SEED (default 7),
#        WORK (default a fresh folder under /tmp; the PLY is deleted at the end unless KEEP=1)
#
# Times are medians of RUNS. "wall" is `ocsimp cluster` end to end (open, read, cluster, write the result);
# "cpu" its user + system time; "Mtri/s" input triangles per wall second; "vs cat" cat's time over ours.
# On a shared machine wall time also counts waiting for a core: cpu / cores is what an idle machine would
# approach when the work splits evenly.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-$ROOT/build}
TRIANGLES=${TRIANGLES:-100000000}
GRID=${GRID:-500}
RUNS=${RUNS:-3}
THREADS=${THREADS:-0}
SEED=${SEED:-7}
WORK=${WORK:-$(mktemp -d /tmp/ocsimp-cluster-XXXXXX)}
mkdir -p "$WORK"
if [[ ${KEEP:-0} != 1 ]]; then trap 'rm -rf "$WORK"' EXIT; fi

cmake --build "$BUILD" --target ocsimp >/dev/null
OCSIMP=$BUILD/bin/ocsimp
INPUT=$WORK/scan.ply
[[ -f $INPUT ]] || "$OCSIMP" gen -q -o "$INPUT" --triangles "$TRIANGLES" --seed "$SEED"
header=$(head -c 400 "$INPUT" | tr -d '\r')
vertices=$(grep -a '^element vertex' <<<"$header" | cut -d' ' -f3)
faces=$(grep -a '^element face' <<<"$header" | cut -d' ' -f3)
bytes=$(stat -c %s "$INPUT")
echo "input: ocsimp gen --triangles $TRIANGLES --seed $SEED: $vertices vertices, $faces faces, $((bytes / 1000000)) MB"
echo "cluster: --grid $GRID --threads $THREADS ($(nproc) cores); $RUNS runs, medians"

now_ns() { date +%s%N; }
median() { sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
json() { python3 -c "import json,sys; r=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))" "$@"; }

cat "$INPUT" >/dev/null  # into page cache
cat_s=() wall_s=() cpu_s=() cluster_s=() rss=()
for ((run = 0; run < RUNS; ++run)); do
  start=$(now_ns); cat "$INPUT" >/dev/null; end=$(now_ns)
  cat_s+=("$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.3f", (b - a) / 1e9 }')")
  /usr/bin/time -f "%e %U %S" -o "$WORK/time.txt" \
    "$OCSIMP" cluster "$INPUT" -o "$WORK/out.ply" --grid "$GRID" --threads "$THREADS" -q --report "$WORK/report.json"
  read -r e u s <"$WORK/time.txt"
  wall_s+=("$e")
  cpu_s+=("$(awk -v u="$u" -v s="$s" 'BEGIN { printf "%.2f", u + s }')")
  cluster_s+=("$(json "$WORK/report.json" "round(r['seconds']['cluster'], 3)")")
  rss+=("$(json "$WORK/report.json" "r['peak_rss_bytes']")")
done
cells=$(json "$WORK/report.json" "r['cells']['fine']")
out_faces=$(json "$WORK/report.json" "r['output']['faces']")
cat_m=$(printf '%s\n' "${cat_s[@]}" | median)
wall_m=$(printf '%s\n' "${wall_s[@]}" | median)
cpu_m=$(printf '%s\n' "${cpu_s[@]}" | median)
cluster_m=$(printf '%s\n' "${cluster_s[@]}" | median)
rss_m=$(printf '%s\n' "${rss[@]}" | median)
budget=$((12 * vertices + 200 * cells))
awk -v f="$faces" -v cat="$cat_m" -v wall="$wall_m" -v cpu="$cpu_m" -v cl="$cluster_m" -v rss="$rss_m" \
    -v budget="$budget" -v cells="$cells" -v out="$out_faces" -v v="$vertices" -v cores="$(nproc)" 'BEGIN {
  printf "%-26s %s\n", "occupied fine cells", cells
  printf "%-26s %s\n", "output faces", out
  printf "%-26s %.3f s (%.0f MB/s)\n", "cat (page cache)", cat, 0
  printf "%-26s %.2f s wall, %.2f s in cluster(), %.2f s cpu\n", "ocsimp cluster", wall, cl, cpu
  printf "%-26s %.1f M triangles/s (wall), %.1f M/s at cpu/%d cores\n", "throughput", f / wall / 1e6, f / (cpu / cores) / 1e6, cores
  printf "%-26s %.2f (cat time / ours)\n", "vs cat", cat / wall
  printf "%-26s %.1f MiB = %.2f B/input vertex; budget 12 B/vertex + 200 B/cell = %.1f MiB (%.1f%% of it)\n", "peak RSS", rss / 1048576, rss / v, budget / 1048576, 100 * rss / budget
}' | sed "s/(0 MB\/s)/($(awk -v b="$bytes" -v t="$cat_m" 'BEGIN { printf "%.0f", b / t / 1e6 }') MB\/s)/"
