#!/usr/bin/env bash
# Runs every libFuzzer target (protocol/fuzz/fuzz_<name>.cc) on its corpus.
#   scripts/fuzz.sh MINUTES   each target for MINUTES minutes (may be 0.05)
#   scripts/fuzz.sh --smoke   each target for a few seconds (./scripts/test.sh)
# Builds the targets into build-asan/ (clang, ASan+UBSan, -DHOLO_FUZZ=ON) if
# needed. New interesting inputs go to build-asan/fuzz-corpus/<name>/ (the
# seeds in protocol/fuzz/corpus/ stay as they are); a crash writes
# build-asan/fuzz-crashes/<name>/crash-* and the script fails. Keep a crash
# input in protocol/fuzz/corpus/<name>/ once the bug is fixed.
# Prints one JSON line per target: {"fuzz":NAME,"seconds":S,"execs":N,"crashes":0,...}.
# HOLO_FUZZ_ONLY="message wav" limits the run to those targets (and builds only them);
# HOLO_FUZZ_NO_BUILD=1 runs the programs as built; HOLO_FUZZ_JOBS=N runs N targets at once
# (default: one per core).
set -euo pipefail
cd "$(dirname "$0")/.."
case "${1:-}" in
  --smoke) SECONDS_EACH=${HOLO_FUZZ_SMOKE_SECONDS:-3} ;;
  ""|-h|--help) sed -n '2,10p' "$0"; [[ -n "${1:-}" ]] && exit 0; exit 2 ;;
  *)
    if ! [[ "$1" =~ ^[0-9]+([.][0-9]+)?$ ]]; then echo "fuzz.sh: MINUTES must be a number, got '$1'" >&2; exit 2; fi
    SECONDS_EACH=$(awk -v m="$1" 'BEGIN { s = int(m * 60); print (s < 1 ? 1 : s) }') ;;
esac
(($# <= 1)) || { echo "fuzz.sh: unknown option $2" >&2; exit 2; }

BUILD=${HOLO_ASAN_BUILD_DIR:-build-asan}
if [[ ! -f "$BUILD/CMakeCache.txt" ]]; then
  ./scripts/configure_asan.sh "$BUILD"
fi
NAMES=()
for src in protocol/fuzz/fuzz_*.cc; do
  name=$(basename "$src" .cc); name=${name#fuzz_}
  if [[ -n "${HOLO_FUZZ_ONLY:-}" && " $HOLO_FUZZ_ONLY " != *" $name "* ]]; then continue; fi
  NAMES+=("$name")
done
((${#NAMES[@]} > 0)) || { echo "fuzz.sh: no target matches HOLO_FUZZ_ONLY='${HOLO_FUZZ_ONLY:-}'" >&2; exit 2; }
TARGETS=()
for name in "${NAMES[@]}"; do TARGETS+=("holoport-fuzz-${name//_/-}"); done
if [[ -z "${HOLO_FUZZ_NO_BUILD:-}" ]]; then
  cmake --build "$BUILD" --parallel "$(nproc)" --target "${TARGETS[@]}" > /dev/null
fi

# One target: its JSON line on stdout; on a failure a reason on stderr and exit 1.
run_one() {
  local name=$1
  local exe="$BUILD/bin/holoport-fuzz-${name//_/-}"
  local seeds=protocol/fuzz/corpus/$name
  [[ "$name" == decoders ]] && seeds=tests/protocol/corpus
  local work="$BUILD/fuzz-corpus/$name" crashes="$BUILD/fuzz-crashes/$name"
  mkdir -p "$work" "$crashes" "$seeds"
  local log="$BUILD/fuzz-logs/$name.log"; mkdir -p "$(dirname "$log")"
  local rc=0
  # -rss_limit_mb: a decoder must not need more than this for any input.
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    "$exe" -max_total_time="$SECONDS_EACH" -rss_limit_mb=1024 -timeout=10 -max_len=65536 -print_final_stats=1 \
    -artifact_prefix="$crashes/" "$work" "$seeds" > "$log" 2>&1 || rc=$?
  local execs cov ncrash
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1) || true
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | sed 's/cov: //') || true
  ncrash=$(find "$crashes" -type f | wc -l)
  echo "{\"fuzz\":\"$name\",\"seconds\":$SECONDS_EACH,\"execs\":${execs:-0},\"coverage\":${cov:-0},\"crashes\":$ncrash,\"exit\":$rc}"
  if ((rc != 0)) || ((ncrash > 0)); then
    { echo "fuzz.sh: $name failed (exit $rc, $ncrash crash inputs in $crashes); log: $log"
      grep -m 20 -E 'ERROR|SUMMARY|runtime error|Check failed|#0 |#1 |#2 ' "$log" || tail -n 3 "$log"; } >&2
    return 1
  fi
}

# Targets run side by side, one per core (HOLO_FUZZ_JOBS overrides): each is
# single-threaded, so N cores finish the list N times sooner.
JOBS=${HOLO_FUZZ_JOBS:-$(nproc)}
fail=0
running=0
for name in "${NAMES[@]}"; do
  if ((running >= JOBS)); then
    wait -n || fail=1
    running=$((running - 1))
  fi
  run_one "$name" &
  running=$((running + 1))
done
while ((running > 0)); do
  wait -n || fail=1
  running=$((running - 1))
done
exit $fail
