#!/usr/bin/env bash
# Sets up a fresh machine, builds, and runs every test:
#   1. the Release build, all tests (unit and slow), every program's --help;
#   2. the sanitizer build (ASan + UBSan, build-asan/, see configure_asan.sh):
#      only the tests labelled "parsing" (code that reads untrusted bytes) and
#      the libraries they link, then a few seconds of each libFuzzer target
#      on its corpus (scripts/fuzz.sh --smoke; clang only).
# ./scripts/test.sh --quick skips slow tests and the sanitizer stage.
# Prints the time of each stage at the end (and to build/test-stages.json).
set -euo pipefail
cd "$(dirname "$0")/.."
QUICK=0
for a in "$@"; do
  case "$a" in
    --quick) QUICK=1 ;;
    -h|--help) sed -n '2,9p' "$0"; exit 0 ;;
    *) echo "test.sh: unknown option $a" >&2; exit 2 ;;
  esac
done

STAGES=()
t0=$(date +%s)
stage_start=$t0
stage_done() {  # NAME: records the seconds since the previous stage ended
  local now; now=$(date +%s)
  STAGES+=("$1 $((now - stage_start))")
  echo "== $1: $((now - stage_start)) s"
  stage_start=$now
}

./scripts/setup.sh
stage_done setup
./scripts/build.sh
stage_done release_build
if ((QUICK)); then
  ctest --test-dir build --output-on-failure --parallel "$(nproc)" -LE slow
  stage_done release_ctest
else
  ctest --test-dir build --output-on-failure --parallel "$(nproc)"
  stage_done release_ctest
  echo "== sanitizer build (ASan+UBSan) for parsing tests =="
  [[ -f build-asan/CMakeCache.txt ]] || ./scripts/configure_asan.sh build-asan
  cmake -S . -B build-asan > /dev/null
  mapfile -t targets < <(ctest --test-dir build-asan -N -L parsing | sed -n 's/^ *Test *#[0-9]*: //p')
  echo "sanitizer build of ${#targets[@]} test programs: ${targets[*]}"
  cmake --build build-asan --parallel "$(nproc)" --target "${targets[@]}"
  stage_done asan_build
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir build-asan --output-on-failure --parallel "$(nproc)" -L parsing
  stage_done asan_ctest
  if grep -q '^HOLO_FUZZ:BOOL=ON' build-asan/CMakeCache.txt; then
    echo "== fuzz smoke (each libFuzzer target a few seconds on its corpus) =="
    ./scripts/fuzz.sh --smoke
    stage_done fuzz_smoke
  else
    echo "test.sh: no clang, fuzz smoke skipped" >&2
  fi
fi
{
  printf '{"total_s":%d' $(( $(date +%s) - t0 ))
  for s in "${STAGES[@]}"; do printf ',"%s_s":%s' ${s% *} ${s#* }; done
  printf '}\n'
} | tee build/test-stages.json
echo "test.sh: all tests passed in $(( $(date +%s) - t0 )) s"
