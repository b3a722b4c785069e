#!/usr/bin/env bash
# The main job on a built-in default input: installs what is missing, builds, generates a scan-like mesh of
# about 2 million triangles, simplifies it to 1% of its faces, and measures how far the result is from the input.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
OCSIMP_BUILD_DIR=build scripts/build.sh
ocsimp=build/bin/ocsimp
mkdir -p out
echo "== generating a 2M-triangle scan-like mesh"
$ocsimp gen -o out/scan-2m.ply --triangles 2000000 --seed 1
$ocsimp info out/scan-2m.ply
echo "== simplifying to 20,000 faces"
$ocsimp simplify out/scan-2m.ply -o out/scan-20k.ply --faces 20000 --report out/scan-20k.json
$ocsimp info out/scan-20k.ply
echo "== distance of the result to the original"
$ocsimp compare out/scan-2m.ply out/scan-20k.ply
echo "outputs in out/: scan-2m.ply (input), scan-20k.ply (result), scan-20k.json (report)"
