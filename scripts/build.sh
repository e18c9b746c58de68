#!/usr/bin/env bash
# Configures and builds Holoport (Release) into build/. Extra arguments go to
# cmake's configure step, e.g. ./scripts/build.sh -DHOLO_SANITIZE=ON.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${HOLO_BUILD_DIR:-build}
GENERATOR=()
if command -v ninja > /dev/null; then GENERATOR=(-G Ninja); fi
# ccache, when installed, makes rebuilds across worktrees cheap; optional.
LAUNCHER=()
if command -v ccache > /dev/null; then LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
if [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]]; then
  cmake -S . -B "$BUILD_DIR" "${GENERATOR[@]}" -DCMAKE_BUILD_TYPE=Release "${LAUNCHER[@]}" "$@"
elif (($#)); then
  cmake -S . -B "$BUILD_DIR" "$@"
fi
cmake --build "$BUILD_DIR" --parallel "$(nproc)"
