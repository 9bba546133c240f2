#!/usr/bin/env bash
# Rebuild the report's 3D viewer, o3d_seqcc/report/viewer.min.js, from viewer/src/viewer.js and the exact
# npm packages of viewer/package-lock.json (three.js, its GLTFLoader and OrbitControls; esbuild bundles and
# minifies them into one file that ships as package data and is inlined into every report.html).
#
#   viewer/build.sh          rebuild the shipped bundle
#   viewer/build.sh --check  build into a temporary file and fail unless it is byte for byte the shipped one
set -euo pipefail
cd "$(dirname "$0")"
out=../o3d_seqcc/report/viewer.min.js
# npm ci again only when the lock file changed since the last install
if [[ ! -x node_modules/.bin/esbuild ]] || ! cmp -s package-lock.json node_modules/.o3d-seqcc-lock 2>/dev/null; then
  npm ci --no-audit --no-fund --loglevel=error >&2
  cp package-lock.json node_modules/.o3d-seqcc-lock
fi
target=$out
[[ ${1:-} == --check ]] && target=$(mktemp --suffix=.js)
node_modules/.bin/esbuild src/viewer.js --bundle --minify --format=iife --target=es2020 --legal-comments=eof \
  --charset=utf8 --log-level=warning --outfile="$target"
if [[ ${1:-} == --check ]]; then
  if cmp -s "$target" "$out"; then echo "viewer.min.js is what viewer/build.sh produces ($(wc -c <"$out") bytes)"; rm -f "$target"
  else echo "viewer.min.js differs from what viewer/build.sh produces: run viewer/build.sh and commit it" >&2; rm -f "$target"; exit 1; fi
fi
