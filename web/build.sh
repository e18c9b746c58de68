#!/usr/bin/env bash
# Builds the browser viewer into web/dist/ (or the directory given) (npm ci with the pinned lockfile
# when node_modules is missing, then esbuild).
set -euo pipefail
cd "$(dirname "$0")"
if [[ ! -d node_modules ]]; then npm ci --no-audit --no-fund; fi
node build.mjs "$@"
