#!/usr/bin/env bash
# The issue's headline run: an `ocsimp gen` mesh of TRIANGLES triangles (default 10^9, about 19 GB of binary
# PLY) simplified to FACES faces, once with the default memory budget and once with --memory-limit LIMIT
# (which dereferences the vertices out of core when their array does not fit what clustering leaves of the
# budget). Per run: wall, user and system seconds, peak RSS (/usr/bin/time %M) and the pipeline's phases
# (from --report); beside them the time `cat` takes to read the file, the floor for one pass over it. The
# file is read once with cat first so every run starts from page cache.
#
#   bench/simplify_large.sh [BUILD_DIR]          (default: build)
#   env: TRIANGLES (default 1000000000), FACES (default 1000000), LIMIT (default 2G; "" to skip that run),
#        TMPDIR (where the mesh and the out-of-core files go; default /tmp),
#        INPUT (an existing `ocsimp gen` PLY to use instead of generating one; it is kept)
#
# Disk: the input takes about 19 bytes a triangle; the LIMIT run adds about 46 bytes a triangle of unlinked
# temporary files under TMPDIR (12 a vertex, 36 a triangle of corner positions, and the coded vertex ids:
# 3-4 bytes a triangle on a generated scan, up to 15 on a scattered one). The script checks `df` first and skips what
# does not fit. Everything it creates is removed on exit.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-$ROOT/build}
TRIANGLES=${TRIANGLES:-1000000000}
FACES=${FACES:-1000000}
LIMIT=${LIMIT-2G}
ocsimp="$BUILD/bin/ocsimp"
[[ -x $ocsimp ]] || { echo "no $ocsimp: build the ocsimp target first" >&2; exit 1; }

tmp=${TMPDIR:-/tmp}
free_bytes=$(($(df --output=avail -k "$tmp" | tail -1) * 1024))
input_bytes=$((TRIANGLES * 19 + (1 << 20)))
deref_bytes=$((TRIANGLES * 46))
echo "mesh: $TRIANGLES triangles, about $((input_bytes >> 30)) GiB; free under $tmp: $((free_bytes >> 30)) GiB"
if [[ -n ${INPUT:-} ]]; then
  input_bytes=0  # already on disk
elif ((input_bytes > free_bytes)); then
  echo "not enough disk under $tmp for the input" >&2
  exit 1
fi

work=$(mktemp -d "$tmp/ocsimp-simplify-large.XXXXXX")
trap 'rm -rf "$work"' EXIT INT TERM
mesh=${INPUT:-$work/mesh.ply}

echo "load average: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores, $(($(grep MemTotal /proc/meminfo | awk '{print $2}') >> 20)) GiB"
if [[ -z ${INPUT:-} ]]; then
  /usr/bin/time -f "gen: %e s wall, %M KB peak" "$ocsimp" gen -q -o "$mesh" --triangles "$TRIANGLES"
fi
cat "$mesh" >/dev/null  # into page cache
/usr/bin/time -f "cat: %e s wall (one read of $(($(stat -c %s "$mesh") >> 20)) MiB from page cache)" \
  cat "$mesh" >/dev/null

# One simplify run: /usr/bin/time's numbers, then the report's phases.
run() {
  local name=$1
  shift
  local report="$work/$name.json"
  /usr/bin/time -f "$name: %e s wall, %U s user, %S s system, %M KB peak RSS" \
    "$ocsimp" simplify -q "$mesh" -o "$work/$name.ply" --faces "$FACES" --report "$report" "$@"
  python3 - "$report" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print(f"  {r['input_faces']} -> {r['output_faces']} faces, clustered={r['clustered']}, "
      f"out_of_core={r['out_of_core']}, intermediate={r['intermediate_faces']}, "
      f"budget={r['memory_limit_bytes'] / 2**30:.2f} GiB, max_error={r['max_error']:.4g}")
for p in r["phases"]:
    print(f"  {p['name']:<10} {p['seconds']:9.2f} s  {p['triangles_in']:>12} -> {p['triangles_out']:<12}"
          f" peak RSS {p['peak_rss_bytes'] / 2**30:.2f} GiB")
PY
  rm -f "$work/$name.ply"
}

run default
if [[ -n $LIMIT ]]; then
  if ((deref_bytes > free_bytes - input_bytes)); then
    echo "skipping --memory-limit $LIMIT: its out-of-core files need about $((deref_bytes >> 30)) GiB under $tmp" >&2
  else
    run "limit-$LIMIT" --memory-limit "$LIMIT"
  fi
fi
