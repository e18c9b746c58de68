#!/usr/bin/env bash
# The main job: a complete two-site Holoport call on this machine (~20 s).
#  * two site servers (holoport-server --listen) on the synthetic studio with
#    different people: Alice's room (S8-QVGA: one person and a ball) and
#    Bob's room (S8-VGA: two people, a ball and a crate). Each site runs its
#    real capture pipeline on its pods' frames (segmentation, fusion, the
#    compact stream mesh, texturing, G1 + C1) and streams its *reconstruction*;
#    both sites and both viewers share this machine's cores, so the sites are
#    paced below 30 fps (Alice 10, Bob 2 by default; the summary prints the
#    rates reached). --truth streams the studio's ground-truth meshes instead
#    (no reconstruction, 30 fps);
#  * two viewers (holoport-client --call): each watches the other room, placed
#    face to face 2.5 m apart (camera and voice at
#    each room's own person's head), publishes its participant's voice
#    (espeak-ng speech, a different text and voice per site) and head pose,
#    and spatializes the other participant's voice (HRTF, listener = own head);
#  * with a display, two windows; without one (or with --headless), headless:
#    into ./demo-output/ (--out DIR): alice/ and bob/ with PNG frames, a
#    contact_sheet.png and stats.json each, alice_hears.wav and bob_hears.wav
#    (the spatialized stereo audio each participant hears); then a summary:
#    fps, latency capture->display, bitrate, drops, audio delay.
# Options: --out DIR, --seconds N (20), --headless, --size WxH (960x540),
#   --color projective|vertex (default projective: the viewer colours the mesh
#   from the pods' images, baked once per mesh; vertex: the sites texture the
#   mesh per vertex and send the colours in it, --mesh-colors),
#   --truth (stream ground truth, not the reconstruction), --pace A,B (sites' fps),
#   --no-setup (skip scripts/setup.sh and scripts/build.sh),
#   --capture-only (the previous demo instead: dataset + reconstruction of
#   one site into out/demo; with --workload W --frames N).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=demo-output
SECONDS_RUN=20
HEADLESS=0
SIZE=960x540
SETUP=1
CAPTURE_ONLY=0
WORKLOAD=S8-QVGA
FRAMES=30
OUT_SET=0
COLOR=projective
TRUTH=0
PACE=10,2
while (($#)); do
  case "$1" in
    --out) OUT=$2; OUT_SET=1; shift 2 ;;
    --seconds) SECONDS_RUN=$2; shift 2 ;;
    --headless) HEADLESS=1; shift ;;
    --size) SIZE=$2; shift 2 ;;
    --color) COLOR=$2; shift 2 ;;
    --no-setup) SETUP=0; shift ;;
    --truth) TRUTH=1; shift ;;
    --pace) PACE=$2; shift 2 ;;
    --capture-only) CAPTURE_ONLY=1; shift ;;
    --workload) WORKLOAD=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    -h|--help) sed -n '2,27p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "demo.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
if ! [[ $SECONDS_RUN =~ ^[0-9]+$ ]] || ((SECONDS_RUN < 3)); then
  echo "demo.sh: --seconds must be a whole number >= 3, got '$SECONDS_RUN'" >&2; exit 2
fi
if ! [[ $SIZE =~ ^([0-9]+)x([0-9]+)$ ]]; then echo "demo.sh: --size must be WxH, got '$SIZE'" >&2; exit 2; fi
WIDTH=${BASH_REMATCH[1]}
HEIGHT=${BASH_REMATCH[2]}
if ! [[ $PACE =~ ^([0-9]+),([0-9]+)$ ]] || ((BASH_REMATCH[1] < 1 || BASH_REMATCH[2] < 1)); then
  echo "demo.sh: --pace must be A,B (frames per second of Alice's and Bob's sites), got '$PACE'" >&2; exit 2
fi
PACE_A=${BASH_REMATCH[1]}
PACE_B=${BASH_REMATCH[2]}

if ((SETUP)); then
  ./scripts/setup.sh
  ./scripts/build.sh
fi
BIN=./build/bin
for b in holoport-server holoport-client; do
  [[ -x $BIN/$b ]] || { echo "demo.sh: $BIN/$b is missing (run without --no-setup to build)" >&2; exit 1; }
done

if ((CAPTURE_ONLY)); then
  # The capture-site demo: dataset with ground truth, then the real pipeline.
  ((OUT_SET)) || OUT=out/demo
  rm -rf "$OUT"
  mkdir -p "$OUT"
  $BIN/holoport-studio --workload "$WORKLOAD" --frames "$FRAMES" --out "$OUT/dataset" \
    --contact-sheet "$OUT/contact_sheet.png" --summary "$OUT/summary.json"
  $BIN/holoport-server --workload "$WORKLOAD" --frames "$FRAMES" --export "$OUT/meshes" \
    --stats "$OUT/server_stats.jsonl" --snapshot "$OUT/reconstruction.png"
  echo "demo: dataset in $OUT/dataset, contact sheet $OUT/contact_sheet.png, summary $OUT/summary.json,"
  echo "      meshes in $OUT/meshes, stats $OUT/server_stats.jsonl, reconstruction $OUT/reconstruction.png"
  exit 0
fi

command -v espeak-ng > /dev/null || { echo "demo.sh: espeak-ng is missing (scripts/setup.sh installs it)" >&2; exit 1; }
rm -rf "$OUT"
mkdir -p "$OUT/logs"

PIDS=()
cleanup() {
  local p
  for p in "${PIDS[@]}"; do kill "$p" 2> /dev/null || true; done
  for p in "${PIDS[@]}"; do wait "$p" 2> /dev/null || true; done
  PIDS=()
}
trap cleanup EXIT
trap 'echo "demo.sh: interrupted, stopping the sites and viewers" >&2; cleanup; exit 130' INT TERM

port_free() { ! (exec 3<> "/dev/tcp/127.0.0.1/$1") 2> /dev/null; }
pick_port() {
  local p
  for _ in $(seq 50); do
    p=$((20000 + RANDOM % 12000))  # below the ephemeral range (32768+)
    if port_free "$p" && port_free $((p + 1)); then echo "$p"; return 0; fi
  done
  echo "demo.sh: no free port pair found" >&2; return 1
}
PORT_A=$(pick_port)
PORT_B=$((PORT_A + 1))

# Speech for each participant (espeak-ng; different text and voice).
espeak-ng -v en-us -s 150 -w "$OUT/alice_says.wav" \
  "Hello Bob, this is Alice in the first room. I can see you across the table. Can you hear me from where I stand?"
espeak-ng -v en-gb+m3 -s 140 -w "$OUT/bob_says.wav" \
  "Hi Alice, Bob here in the second room. Your voice comes from in front of me, a little to the side."

# Call configs: each side publishes to its own room and watches the other.
# Each participant is a person of their own room: the camera and the voice sit
# at that person's head (Alice: the one figure of S8-QVGA, facing +x; Bob: the
# first figure of S8-VGA), and the remote room is turned to face them 2.5 m away.
declare -A HEAD_AT=([alice]="0,0,1.6,0" [bob]="0.05,0.55,1.6,-20")
cat > "$OUT/alice.yaml" << EOF
local:  {name: alice-room, address: 127.0.0.1:$PORT_A, publisher_token: alice-pub}
remote: {name: bob-room,   address: 127.0.0.1:$PORT_B, viewer_token: bob-view}
room:   {yaw_deg: 180, translation_m: [2.5, 0, 0]}
EOF
cat > "$OUT/bob.yaml" << EOF
local:  {name: bob-room,   address: 127.0.0.1:$PORT_B, publisher_token: bob-pub}
remote: {name: alice-room, address: 127.0.0.1:$PORT_A, viewer_token: alice-view}
room:   {yaw_deg: 180, translation_m: [2.5, 0, 0]}
EOF

case "$COLOR" in
  projective) SITE_COLOR=() ;;
  # The live sites send no vertex colours unless asked (the viewer colours
  # from the pods' images): a vertex-colour viewer would show a grey person.
  vertex) SITE_COLOR=(--mesh-colors) ;;
  *) echo "demo.sh: --color must be projective or vertex, got '$COLOR'" >&2; exit 2 ;;
esac
if ((TRUTH)); then
  CONTENT=truth
  SITE_A=(--truth-mesh --truth-loop 30 --pace 30)
  SITE_B=(--truth-mesh --truth-loop 30 --pace 30)
else
  # The real pipeline on 30 pre-rendered frame sets per room, looped forward
  # and back (the studio's rendering is not a site's work: cameras deliver frames).
  CONTENT=fused
  SITE_A=(--prerender 30 --pace "$PACE_A")
  SITE_B=(--prerender 30 --pace "$PACE_B")
fi
echo "demo: starting Alice's site (S8-QVGA) on :$PORT_A and Bob's site (S8-VGA) on :$PORT_B, streaming $CONTENT content"
$BIN/holoport-server --source synthetic -w S8-QVGA "${SITE_A[@]}" "${SITE_COLOR[@]}" -n -1 -q \
  --listen "127.0.0.1:$PORT_A" --publisher-token alice-pub --viewer-token alice-view \
  --stats "$OUT/logs/alice_site.jsonl" > "$OUT/logs/alice_site.log" 2>&1 &
PIDS+=($!)
$BIN/holoport-server --source synthetic -w S8-VGA "${SITE_B[@]}" "${SITE_COLOR[@]}" -n -1 -q \
  --listen "127.0.0.1:$PORT_B" --publisher-token bob-pub --viewer-token bob-view \
  --stats "$OUT/logs/bob_site.jsonl" > "$OUT/logs/bob_site.log" 2>&1 &
PIDS+=($!)
# Wait for both sites to listen (they render their loop of frames first).
for _ in $(seq 600); do
  if ! port_free "$PORT_A" && ! port_free "$PORT_B"; then break; fi
  for p in "${PIDS[@]}"; do
    kill -0 "$p" 2> /dev/null || { echo "demo.sh: a site server exited; its log:" >&2; cat "$OUT"/logs/*_site.log >&2; exit 1; }
  done
  sleep 0.2
done
port_free "$PORT_A" && { echo "demo.sh: the sites did not start listening within 120 s" >&2; exit 1; }

MODE=(--headless --png-interval 1.5 --contact-sheet)
if ((!HEADLESS)) && [[ -n ${DISPLAY:-}${WAYLAND_DISPLAY:-} ]]; then
  MODE=()
  echo "demo: display found: two viewer windows for ${SECONDS_RUN} s (Esc closes one)"
else
  echo "demo: no display (or --headless): two headless viewers for ${SECONDS_RUN} s, output in $OUT/"
fi
VIEWERS=()
for who in alice bob; do
  $BIN/holoport-client --call "$OUT/$who.yaml" --name "$who" "${MODE[@]}" --seconds "$SECONDS_RUN" \
    --width "$WIDTH" --height "$HEIGHT" --connect-timeout 60 --color "$COLOR" \
    --head-at "${HEAD_AT[$who]}" --audio-in "$OUT/${who}_says.wav" --audio-out "$OUT/${who}_hears.wav" --out "$OUT/$who" \
    > "$OUT/logs/${who}_viewer.log" 2>&1 &
  PIDS+=($!)
  VIEWERS+=($!)
done
STATUS=0
for v in "${VIEWERS[@]}"; do wait "$v" || STATUS=1; done
cleanup
if ((STATUS)); then
  echo "demo.sh: a viewer failed; its log:" >&2
  tail -n 20 "$OUT"/logs/*_viewer.log >&2
  exit 1
fi

python3 - "$OUT" "$CONTENT" << 'EOF'
import json, os, struct, sys, wave, math
out, content = sys.argv[1], sys.argv[2]
def wav_figures(path):
    with wave.open(path) as w:
        n, rate, ch = w.getnframes(), w.getframerate(), w.getnchannels()
        data = w.readframes(n)
    s = struct.unpack('<%dh' % (len(data) // 2), data)
    l, r = s[0::ch], s[1::ch] if ch > 1 else s[0::ch]
    rms = lambda x: math.sqrt(sum(v * v for v in x) / max(1, len(x))) / 32768
    return n / rate, rms(l), rms(r)
print("\ndemo summary (%s): the sites streamed %s content (%s)" % (out, content,
      "their own reconstruction: segmentation, fusion, stream mesh" if content == "fused" else "the studio's ground-truth meshes"))
for who, wl in (("alice", "S8-QVGA"), ("bob", "S8-VGA")):
    path = os.path.join(out, "logs", who + "_site.jsonl")
    frames = [json.loads(l) for l in open(path) if l.startswith('{"frame"')] if os.path.exists(path) else []
    tris = sorted(f.get("triangles", 0) for f in frames)
    kb = sorted((f.get("geometry_bytes", 0) + f.get("color_bytes", 0)) / 1024 for f in frames)
    lat = sorted(f.get("encoded_latency_ms", f.get("latency_ms", 0)) for f in frames)
    med = lambda v: v[len(v) // 2] if v else 0
    print("site %-5s (%s): %d frames published, median %d triangles, %.0f KB per frame, capture -> encoded %.0f ms"
          % (who, wl, len(frames), med(tris), med(kb), med(lat)))
print("%-6s %-7s %6s %8s %8s %9s %6s %9s %9s  %s" % ("viewer", "watches", "fps", "lat_p50", "lat_p95",
      "Mbit/s", "drops", "frames", "audio_ms", "heard WAV (s, RMS L/R dB)"))
for who, watches in (("alice", "bob"), ("bob", "alice")):
    j = json.load(open(os.path.join(out, who, "stats.json")))
    a = j.get("audio", {})
    secs, l, r = wav_figures(os.path.join(out, who + "_hears.wav"))
    db = lambda x: 20 * math.log10(max(x, 1e-9))
    print("%-6s %-7s %6.1f %8.0f %8.0f %9.2f %6d %9d %9.0f  %.1f s, %.1f / %.1f dB" % (
        who, watches, j["fps"], j["latency_ms_median"], j["latency_ms_p95"], j["bitrate_mbps"], j["drops"],
        j["frames_new"], a.get("audio_delay_ms", 0), secs, db(l), db(r)))
    print("       voice frames sent %d, heard %d from %d speaker(s), concealed %d; remote voice at (%.2f, %.2f, %.2f) m,"
          " azimuth %.0f deg; HRTF %s" % (a.get("voice_frames_sent", 0), a.get("remote_audio_frames", 0),
          a.get("remote_speakers", 0), a.get("concealed", 0), *a.get("remote_voice_position_m", [0, 0, 0]),
          a.get("remote_voice_azimuth_deg", 0), a.get("hrtf", "?")))
print("latency: capture (site clock) -> displayed (glFinish), through the viewer's clock-offset estimate;")
print("audio_ms: mouth -> ear estimate (remote capture -> received + jitter buffer + one 20 ms frame);")
print("drops: frames of the site's 30 fps sequence a viewer never displayed (it shows the newest).")
print("images: %s/alice/contact_sheet.png, %s/bob/contact_sheet.png; audio: %s/alice_hears.wav, %s/bob_hears.wav"
      % (out, out, out, out))
EOF
