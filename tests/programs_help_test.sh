#!/usr/bin/env bash
# Every program in BIN_DIR (holoport-*, not the fuzz targets) answers --help
# with exit 0 and some text, and refuses an option it does not know (non-zero
# exit, the option named on stderr, no run). The same for every benchmark of
# holoport-bench (holoport-bench --list), which must exit 2 on an unknown one
# and on a common option (--workload, --frames, --repeats) it does not read.
# Every program and benchmark takes --log-level (named in its --help).
set -uo pipefail
BIN=${1:?usage: programs_help_test.sh BIN_DIR}
BOGUS=--no-such-option-for-holoport
fail=0
check() {  # NAME CMD...: --help and an unknown option
  local name=$1; shift
  local out rc
  out=$(timeout 20 "$@" --help 2>&1); rc=$?
  if ((rc != 0)) || [[ -z "$out" ]]; then
    echo "FAIL: $name --help exited $rc (output: ${out:0:200})"; fail=1
  elif [[ "$out" != *--log-level* ]]; then
    echo "FAIL: $name --help does not list --log-level"; fail=1
  fi
  out=$(timeout 20 "$@" "$BOGUS" 2>&1 < /dev/null); rc=$?
  if ((rc == 0)) || ((rc == 124)); then
    echo "FAIL: $name $BOGUS was not refused (exit $rc)"; fail=1
  elif [[ "$out" != *"$BOGUS"* ]]; then
    echo "FAIL: $name $BOGUS: the error does not name the option: ${out:0:200}"; fail=1
  fi
  out=$(timeout 20 "$@" --log-level loud 2>&1 < /dev/null); rc=$?
  if ((rc == 0)) || ((rc == 124)) || [[ "$out" != *--log-level* ]]; then
    echo "FAIL: $name --log-level loud was not refused with the option named (exit $rc): ${out:0:200}"; fail=1
  fi
  echo "$name: --help ok, unknown option and log level refused (exit $rc)"
}
shopt -s nullglob
programs=("$BIN"/holoport-*)
((${#programs[@]} > 0)) || { echo "FAIL: no programs in $BIN"; exit 1; }
for p in "${programs[@]}"; do
  [[ "$(basename "$p")" == holoport-fuzz-* ]] && continue
  check "$(basename "$p")" "$p"
done
if [[ -x "$BIN/holoport-bench" ]]; then
  while read -r name; do
    out=$(timeout 20 "$BIN/holoport-bench" "$name" --help 2>&1); rc=$?
    if ((rc != 0)) || [[ -z "$out" ]]; then echo "FAIL: holoport-bench $name --help exited $rc"; fail=1; fi
    if [[ "$out" != *--log-level* ]]; then echo "FAIL: holoport-bench $name --help does not list --log-level"; fail=1; fi
    out=$(timeout 20 "$BIN/holoport-bench" "$name" "$BOGUS" 2>&1); rc=$?
    if ((rc != 2)) || [[ "$out" != *"$BOGUS"* ]]; then
      echo "FAIL: holoport-bench $name $BOGUS: exit $rc, ${out:0:200}"; fail=1
    fi
    echo "holoport-bench $name: --help ok, unknown option refused"
  done < <("$BIN/holoport-bench" --list)
  # A common option that a benchmark does not read is refused too, not ignored.
  for cmd in "soak --repeats 2" "audio --frames 5"; do
    read -r name option value <<< "$cmd"
    out=$(timeout 20 "$BIN/holoport-bench" "$name" "$option" "$value" 2>&1 < /dev/null); rc=$?
    if ((rc != 2)) || [[ "$out" != *"$option"* ]]; then
      echo "FAIL: holoport-bench $cmd: exit $rc, ${out:0:200}"; fail=1
    fi
    echo "holoport-bench $cmd: refused"
  done
fi
exit $fail
