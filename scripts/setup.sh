#!/usr/bin/env bash
# Installs every Debian package Holoport needs. Idempotent and non-interactive:
# packages already installed are skipped, so a second run does nothing.
set -euo pipefail

PACKAGES=(
  build-essential cmake pkg-config ninja-build
  libeigen3-dev libopencv-dev libceres-dev libopenmesh-dev
  liblz4-dev libopus-dev libopenal-dev libglfw3-dev libasio-dev
  libcli11-dev libyaml-cpp-dev nlohmann-json3-dev libspdlog-dev
  libgtest-dev
  libzstd-dev libturbojpeg0-dev libmeshoptimizer-dev libdraco-dev clang libclang-rt-14-dev lld
  python3-open3d
  openssl libepoxy-dev libegl-dev libgl1-mesa-dri xvfb xauth libssl-dev espeak-ng
  libsoxr-dev
  libjpeg62-turbo-dev
  libwebrtc-audio-processing-dev libspeexdsp-dev libmysofa-dev
  libavcodec-dev libavutil-dev
  nginx-light
  chromium
)
# The browser viewer (web/) builds and tests with Node.js and npm: Debian's
# when the machine has none of its own.
if ! command -v npm >/dev/null 2>&1; then PACKAGES+=(nodejs npm); fi

# npm packages of the browser viewer, pinned by web/package-lock.json.
web_npm() {
  local web
  web="$(cd "$(dirname "$0")/.." && pwd)/web"
  if [[ ! -d "$web/node_modules" || "$web/package-lock.json" -nt "$web/node_modules" ]]; then
    echo "setup: npm ci in web/"
    (cd "$web" && npm ci --no-audit --no-fund --loglevel=error && touch node_modules)
  fi
}

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]} == 0)); then
  echo "setup: all ${#PACKAGES[@]} packages already installed"
  web_npm
  exit 0
fi

echo "setup: installing ${#missing[@]} packages: ${missing[*]}"
SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
web_npm
echo "setup: done"
