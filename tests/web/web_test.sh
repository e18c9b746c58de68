#!/usr/bin/env bash
# The browser viewer's tests (web/), run by CTest:
#   web_test.sh fixture  BUILD_DIR SOURCE_DIR   recording + golden decodes (G1, G3, colour; once per build)
#   web_test.sh decoders BUILD_DIR SOURCE_DIR   JS decoders vs the C++ decoders (node)
#   web_test.sh live     BUILD_DIR SOURCE_DIR   the player's part sequencing against a scripted edge (node)
#   web_test.sh playback BUILD_DIR SOURCE_DIR   headless Chromium vs the native renderer, PSNR ≥ 30 dB
#   web_test.sh playback_v1 BUILD_DIR SOURCE_DIR   the same with the colour as V1 video (WebCodecs)
#   web_test.sh faults   BUILD_DIR SOURCE_DIR   damaged part, stalled edge: message, then recovery
# Exit 77 (CTest skip) only when Chromium cannot start; a missing node or
# npm packages is a failure (scripts/setup.sh installs both).
set -uo pipefail
what=${1:?usage: web_test.sh fixture|decoders|live|playback|playback_v1|faults BUILD_DIR SOURCE_DIR}
build=$(cd "${2:?build dir}" && pwd)
src=$(cd "${3:?source dir}" && pwd)
fx="$build/web-fixture"
fixture_bin="$build/bin/holoport-web-fixture"
command -v node >/dev/null || { echo "FAIL: node is not installed (scripts/setup.sh)"; exit 1; }
[[ -d "$src/web/node_modules" ]] || { echo "FAIL: web/node_modules is missing: run scripts/setup.sh (npm ci in web/)"; exit 1; }

case "$what" in
  fixture)
    mkdir -p "$fx"
    # The recording is kept while the fixture program is unchanged (~30 s to make).
    if [[ ! -s "$fx/rec.hrec" || "$fixture_bin" -nt "$fx/rec.hrec" ]]; then
      rm -f "$fx/rec.hrec"
      "$fixture_bin" record --out "$fx/rec.hrec" --seconds 4 || exit 1
    fi
    # The same recording with its colour as V1 video (a few seconds to make).
    "$fixture_bin" to-v1 --recording "$fx/rec.hrec" --out "$fx/rec_v1.hrec" || exit 1
    rm -rf "$fx/golden"
    "$fixture_bin" golden --recording "$fx/rec.hrec" --out-dir "$fx/golden" --count 3 --g3 3 || exit 1
    node "$src/web/build.mjs" "$fx/dist" || exit 1
    ;;
  decoders)
    node "$src/web/test/decoders_test.mjs" "$fx/rec.hrec" "$fx/golden"
    ;;
  live)
    node "$src/web/test/live_test.mjs"
    ;;
  playback|playback_v1|faults)
    chromium=${HOLO_CHROMIUM:-/usr/bin/chromium}
    if [[ ! -x "$chromium" ]]; then echo "SKIP: Chromium is not installed ($chromium)"; exit 77; fi
    if ! out=$(timeout 60 "$chromium" --headless=new --no-sandbox --disable-gpu --dump-dom about:blank 2>&1); then
      echo "SKIP: Chromium cannot start here: $(echo "$out" | grep -v -i dbus | tail -2)"; exit 77
    fi
    rec="$fx/rec.hrec" outdir="$build/web-test-output"
    [[ "$what" == playback_v1 ]] && { what=playback; rec="$fx/rec_v1.hrec"; outdir="$build/web-test-output-v1"; }
    node "$src/web/test/browser_test.mjs" "$what" --recording "$rec" --dist "$fx/dist" \
      --fixture "$fixture_bin" --out "$outdir" --color projective --chromium "$chromium"
    ;;
  *) echo "unknown test $what"; exit 2 ;;
esac
