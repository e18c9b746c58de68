#!/usr/bin/env bash
# Checks that dependencies between the top-level modules point one way:
#
#   common <- protocol <- net, audio, studio <- texture <- server, client
#
# (server is the capture site; server and client never include each other).
# A module is a top-level folder; a file belongs to the module of its first
# path component. Two kinds of edge are checked, without building anything:
#   * every quoted include whose first component names a module,
#     `#include "server/net/site_publisher.h"`, in *.h / *.cc files;
#   * every library a module's CMakeLists.txt names (holo_<module>...), so a
#     module cannot link what it may not include (comment lines are skipped).
# bench/, tests/ and the libFuzzer targets (protocol/fuzz/) are harnesses and
# may use every module. A new top-level folder with C++ sources must be added
# to ALLOWED below, or the check fails.
#
# Usage: scripts/check_deps.sh [ROOT]   (default: the repository this script is in)
# Exit 0 when every edge is allowed; 1 with one line per forbidden edge,
# "FILE:LINE: forbidden edge A -> B (...)"; 2 on a usage error.
set -euo pipefail

# Which modules each module may use (besides itself). "*" = any.
declare -A ALLOWED=(
  [common]=""
  [protocol]="common"
  [net]="common protocol"
  [audio]="common protocol"
  [studio]="common protocol"
  [texture]="common protocol studio"
  [server]="common protocol net audio studio texture"
  [client]="common protocol net audio studio texture"
  [bench]="*"
  [tests]="*"
  [protocol/fuzz]="*"
)
# Top-level folders that hold no C++ module (not reported as unknown).
NOT_MODULES=" cmake config docs scripts web "

case "${1:-}" in
  -h | --help) sed -n '2,20p' "$0"; exit 0 ;;
  -*) echo "check_deps.sh: unknown option $1" >&2; exit 2 ;;
esac
ROOT=${1:-"$(cd "$(dirname "$0")/.." && pwd)"}
[[ -d "$ROOT" ]] || { echo "check_deps.sh: no such directory: $ROOT" >&2; exit 2; }
cd "$ROOT"

# Sets MODULE to the module a repository-relative path belongs to ("" for a
# file at the root). No subshell: this runs once per include line.
module_of() {
  case "$1" in
    protocol/fuzz/*) MODULE=protocol/fuzz ;;
    */*) MODULE=${1%%/*} ;;
    *) MODULE="" ;;
  esac
}

allowed() {  # FROM TO
  local from=$1 to=$2
  [[ "$from" == "$to" ]] && return 0
  [[ "$from" == protocol/fuzz && "$to" == protocol ]] && return 0
  local list=" ${ALLOWED[$from]} "
  [[ "$list" == *" * "* || "$list" == *" $to "* ]]
}

is_module() { [[ -n "${ALLOWED[$1]+x}" && "$1" != protocol/fuzz ]]; }

# Source files, skipping build trees, dependencies and hidden folders.
list_files() {  # NAME-PATTERN...
  local args=() p
  for p in "$@"; do args+=(-o -name "$p"); done
  find . \( -path './build*' -o -path '*/node_modules' -o -path './.*' \) -prune -o \
    -type f \( "${args[@]:1}" \) -print | sed 's#^\./##' | LC_ALL=C sort
}

violations=0
report() {  # FILE LINE FROM TO WHAT
  echo "$1:$2: forbidden edge $3 -> $4 ($5; $3 may use: ${ALLOWED[$3]:-nothing})"
  violations=$((violations + 1))
}

mapfile -t sources < <(list_files '*.h' '*.cc' '*.hpp' '*.cpp')
declare -A unknown=()
for f in "${sources[@]}"; do
  module_of "$f"; from=$MODULE
  [[ -z "$from" ]] && continue
  if [[ -z "${ALLOWED[$from]+x}" ]]; then
    unknown[$from]=1
    continue
  fi
done
for m in "${!unknown[@]}"; do
  if [[ "$NOT_MODULES" != *" $m "* ]]; then
    echo "$m/: top-level folder with C++ sources that scripts/check_deps.sh does not know: add it to ALLOWED"
    violations=$((violations + 1))
  fi
done

# Quoted includes: FILE:LINE:TARGET-PATH, one grep over every source file.
if ((${#sources[@]})); then
  while IFS=: read -r f line target; do
    module_of "$f"; from=$MODULE
    [[ -z "$from" || -z "${ALLOWED[$from]+x}" ]] && continue
    to=${target%%/*}
    [[ "$target" == */* ]] && is_module "$to" || continue
    allowed "$from" "$to" || report "$f" "$line" "$from" "$to" "#include \"$target\""
  done < <(grep -HnE '^[[:space:]]*#[[:space:]]*include[[:space:]]*"[^"]+"' "${sources[@]}" |
           sed -E 's/^([^:]+):([0-9]+):[[:space:]]*#[[:space:]]*include[[:space:]]*"([^"]+)".*/\1:\2:\3/')
fi

# Libraries named in the modules' CMakeLists.txt (holo_<module> or holo_<module>_<part>).
mapfile -t cmakes < <(list_files CMakeLists.txt '*.cmake')
for f in "${cmakes[@]}"; do
  module_of "$f"; from=$MODULE
  [[ -z "$from" || -z "${ALLOWED[$from]+x}" ]] && continue
  while IFS=: read -r line text; do
    [[ "$text" =~ ^[[:space:]]*# ]] && continue
    for lib in $(grep -oE '\bholo_[a-z0-9_]+' <<< "$text" || true); do
      name=${lib#holo_}
      to=${name%%_*}
      is_module "$to" || continue
      allowed "$from" "$to" || report "$f" "$line" "$from" "$to" "links $lib"
    done
  done < <(grep -nE '\bholo_[a-z0-9_]+' "$f" || true)
done

if ((violations)); then
  echo "check_deps: $violations forbidden dependency edge(s); the allowed edges are in scripts/check_deps.sh" >&2
  exit 1
fi
echo "check_deps: ${#sources[@]} source files, ${#cmakes[@]} CMake files: every dependency edge is allowed"
