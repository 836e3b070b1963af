#!/usr/bin/env bash
# Checks Prime's recordings with the MCAP project's reference reader for
# TypeScript (@mcap/core, from npm, run with Node.js):
#   reference_reader/run.sh NODE_MODULES_DIR SAMPLES_BINARY [FILE:MESSAGES:CHANNELS...]
# Installs the reader's pinned packages (package-lock.json) into
# NODE_MODULES_DIR once, writes the sample recordings (every compression)
# and checks them, and any other recordings named.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
modules=$1 samples=$2
shift 2
command -v node >/dev/null && command -v npm >/dev/null || {
  echo "FAILED: node and npm are needed (Debian: nodejs, npm; tools/run installs them)" >&2
  exit 1
}
if [[ ! -f $modules/node_modules/@mcap/core/package.json ]]; then
  mkdir -p "$modules"
  cp "$here/package.json" "$here/package-lock.json" "$modules/"
  (cd "$modules" && npm ci --no-audit --no-fund --loglevel=error) || {
    echo "FAILED: npm could not install @mcap/core from its registry" >&2
    exit 1
  }
fi
cp "$here/check.mjs" "$modules/"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mapfile -t files < <("$samples" "$work")
node "$modules/check.mjs" "${files[@]}" "$@"
