#!/usr/bin/env bash
# Sets up a fresh machine, builds, and runs every test:
#   1. the Release build, all tests (unit and slow);
#   2. the sanitizer build (ASan + UBSan) on the tests that parse untrusted
#      input (label "parsing": files, network bytes, codecs, recordings).
# ./scripts/test.sh --quick skips slow tests and the sanitizer build.
set -euo pipefail
cd "$(dirname "$0")/.."
QUICK=0
for a in "$@"; do
  case "$a" in
    --quick) QUICK=1 ;;
    -h|--help) sed -n '2,7p' "$0"; exit 0 ;;
    *) echo "test.sh: unknown option $a" >&2; exit 2 ;;
  esac
done

./scripts/setup.sh
start=$(date +%s)
./scripts/build.sh
if ((QUICK)); then
  ctest --test-dir build --output-on-failure --parallel "$(nproc)" -LE slow
else
  ctest --test-dir build --output-on-failure --parallel "$(nproc)"
  echo "== sanitizer build (ASan+UBSan) for parsing tests =="
  # Configure, then build only the test programs labelled "parsing".
  GENERATOR=()
  if command -v ninja > /dev/null; then GENERATOR=(-G Ninja); fi
  LAUNCHER=()
  if command -v ccache > /dev/null; then LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
  [[ -f build-asan/CMakeCache.txt ]] || cmake -S . -B build-asan "${GENERATOR[@]}" -DHOLO_SANITIZE=ON \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHOLO_BUILD_BENCH=OFF "${LAUNCHER[@]}" > /dev/null
  cmake -S . -B build-asan > /dev/null
  mapfile -t targets < <(ctest --test-dir build-asan -N -L parsing | sed -n 's/^ *Test *#[0-9]*: //p')
  echo "sanitizer build of ${#targets[@]} test programs: ${targets[*]}"
  cmake --build build-asan --parallel "$(nproc)" --target "${targets[@]}"
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir build-asan --output-on-failure --parallel "$(nproc)" -L parsing
fi
echo "test.sh: all tests passed in $(( $(date +%s) - start )) s"
