#!/usr/bin/env bash
# The main job on the built-in synthetic studio: sets up the machine, builds,
#  1. renders 30 frames of workload S8-QVGA into out/demo/dataset (with ground
#     truth), out/demo/contact_sheet.png and out/demo/summary.json;
#  2. runs the capture site on the same workload (segmentation, fusion,
#     texturing): textured meshes in out/demo/meshes/, per-frame stats in
#     out/demo/server_stats.jsonl, and out/demo/reconstruction.png (ground
#     truth | ours, from a viewpoint no pod has).
# Options: --workload S8-VGA, --frames N, --out DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
WORKLOAD=S8-QVGA
FRAMES=30
OUT=out/demo
while (($#)); do
  case "$1" in
    --workload) WORKLOAD=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    --out) OUT=$2; shift 2 ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "demo.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
./scripts/setup.sh
./scripts/build.sh
rm -rf "$OUT"
mkdir -p "$OUT"
./build/bin/holoport-studio --workload "$WORKLOAD" --frames "$FRAMES" --out "$OUT/dataset" \
  --contact-sheet "$OUT/contact_sheet.png" --summary "$OUT/summary.json"
./build/bin/holoport-server --workload "$WORKLOAD" --frames "$FRAMES" --export "$OUT/meshes" \
  --stats "$OUT/server_stats.jsonl" --snapshot "$OUT/reconstruction.png"
echo "demo: dataset in $OUT/dataset, contact sheet $OUT/contact_sheet.png, summary $OUT/summary.json,"
echo "      meshes in $OUT/meshes, stats $OUT/server_stats.jsonl, reconstruction $OUT/reconstruction.png"
