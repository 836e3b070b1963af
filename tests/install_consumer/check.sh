#!/usr/bin/env bash
# Installs Prime from the build tree into a scratch prefix, then configures,
# builds and runs an outside project that does find_package(prime).
set -euo pipefail
build=$1 source=$2 work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build" --prefix "$work/prefix" >/dev/null
cmake -S "$source" -B "$work/build" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/build" >/dev/null
"$work/build/consumer"
echo "find_package(prime) consumer built and ran"
