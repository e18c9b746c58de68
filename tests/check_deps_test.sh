#!/usr/bin/env bash
# The one-way dependency check (scripts/check_deps.sh): the source tree
# passes, and a copy of it with forbidden edges injected fails, naming each
# file, line and edge — and nothing else (bench/ and tests/ may use anything).
set -uo pipefail
ROOT=${1:?usage: check_deps_test.sh SOURCE_DIR}
CHECK="$ROOT/scripts/check_deps.sh"
fail=0
expect() {  # DESCRIPTION CONDITION-RESULT
  if [[ "$2" == 0 ]]; then echo "ok: $1"; else echo "FAIL: $1"; fail=1; fi
}

# 1. The tree itself.
out=$("$CHECK" "$ROOT" 2>&1); rc=$?
echo "$out"
expect "the source tree has no forbidden edge (exit $rc)" $((rc != 0))

# 2. A copy of its sources and CMake files with forbidden edges injected.
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$ROOT" && find . \( -path './build*' -o -path '*/node_modules' -o -path './.*' -o -path './tests/data' \) -prune -o \
  -type f \( -name '*.h' -o -name '*.cc' -o -name CMakeLists.txt -o -name '*.cmake' \) -print0 |
  xargs -0 cp --parents -t "$tmp") || { echo "FAIL: could not copy the sources"; exit 1; }
cp "$CHECK" "$tmp/check_deps.sh"

inject() {  # FILE LINE-TEXT: appends the line, prints its line number
  printf '%s\n' "$2" >> "$tmp/$1"
  wc -l < "$tmp/$1" | tr -d ' '
}
l_client=$(inject client/tools/viewer_app.cc '#include "server/pipeline/capture_site.h"')
l_net=$(inject net/site_client.h '#include "client/net/participant.h"')
l_common=$(inject common/mesh.h '  #  include "protocol/messages.h"')
l_cmake=$(inject server/CMakeLists.txt 'target_link_libraries(holoport-record PRIVATE holo_client_render)')
mkdir -p "$tmp/newmodule" && echo 'int x = 0;' > "$tmp/newmodule/x.cc"
# Allowed: harnesses use everything, a module uses itself, comments in CMake are skipped.
inject bench/bench_live.cc '#include "client/net/participant.h"' > /dev/null
inject tests/net/fanout_test.cc '#include "server/pipeline/capture_site.h"' > /dev/null
inject client/pose/trace.cc '#include "client/render/view.h"' > /dev/null
inject net/CMakeLists.txt '# not a link: holo_server_pipeline' > /dev/null

out=$("$tmp/check_deps.sh" "$tmp" 2>&1); rc=$?
echo "$out"
expect "the injected copy fails with exit 1 (exit $rc)" $((rc != 1))
has() { grep -qF -- "$1" <<< "$out"; }
has "client/tools/viewer_app.cc:$l_client: forbidden edge client -> server (#include \"server/pipeline/capture_site.h\""
expect "names the client -> server include with its line ($l_client)" $?
has "net/site_client.h:$l_net: forbidden edge net -> client (#include \"client/net/participant.h\""
expect "names the net -> client include with its line ($l_net)" $?
has "common/mesh.h:$l_common: forbidden edge common -> protocol"
expect "an indented '#  include' is seen too (line $l_common)" $?
has "server/CMakeLists.txt:$l_cmake: forbidden edge server -> client (links holo_client_render"
expect "names the server CMake line linking a client library ($l_cmake)" $?
has "newmodule/: top-level folder with C++ sources"
expect "an unknown top-level module is reported" $?
n=$(grep -c 'forbidden edge\|top-level folder' <<< "$out")
expect "exactly the 5 injected problems are reported (got $n)" $((n != 5))

# 3. Usage errors.
"$CHECK" --bogus > /dev/null 2>&1; rc=$?
expect "an unknown option exits 2 (exit $rc)" $((rc != 2))

exit $fail
