#!/usr/bin/env bash
# Configures the sanitizer build directory (default build-asan/): ASan+UBSan,
# -O0 with line tables (fast to build, readable stack traces), no benchmarks;
# the libraries the sanitizer tests compute in are built at -O1 (the list
# HOLO_SANITIZE_O1_TARGETS in CMakeLists.txt).
# With clang (preferred) it is also the libFuzzer build (-DHOLO_FUZZ=ON): the
# parsing tests and the fuzz targets share its objects. Without clang, gcc
# and no fuzz targets.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build-asan}
GENERATOR=()
if command -v ninja > /dev/null; then GENERATOR=(-G Ninja); fi
LAUNCHER=()
if command -v ccache > /dev/null; then LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
FUZZ=(-DHOLO_FUZZ=OFF)
if command -v clang++ > /dev/null; then
  export CXX=clang++
  FUZZ=(-DHOLO_FUZZ=ON)
  FLAGS="-O0 -gline-tables-only"
else
  FLAGS="-O0 -g1"
fi
cmake -S . -B "$BUILD" "${GENERATOR[@]}" -DHOLO_SANITIZE=ON "${FUZZ[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=$FLAGS" -DHOLO_BUILD_BENCH=OFF "${LAUNCHER[@]}" > /dev/null
