#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test with ctest: the Release build, then an
# AddressSanitizer + UndefinedBehaviorSanitizer build (skip the latter with OCSIMP_SKIP_SANITIZE=1).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
jobs=$(nproc)

OCSIMP_BUILD_DIR=build scripts/build.sh
(cd build && ctest --output-on-failure -j"$jobs")

if [ "${OCSIMP_SKIP_SANITIZE:-0}" != 1 ]; then
  # The sanitizer build skips the benchmarks (they are not tests) to save build time.
  OCSIMP_BUILD_DIR=build-asan scripts/build.sh -DCMAKE_BUILD_TYPE=RelWithDebInfo -DOCSIMP_SANITIZE=ON \
    -DOCSIMP_BUILD_BENCH=OFF
  (cd build-asan && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --output-on-failure -j"$jobs")
fi
