#!/usr/bin/env bash
# Installs Prime from the build tree into a scratch prefix, then configures,
# builds and runs outside projects that do find_package(prime):
#   core      no components, Boost and pkg-config (so hiredis) hidden from
#             CMake: prime::liberty links, and no component is loaded;
#   media     COMPONENTS shm optimus, everything visible: prime::shm and
#             prime::optimus link into a program that runs;
#   all       no components, everything visible: every component is loaded;
#   and a component asked for whose dependency is hidden: prime is not found,
#   with a message that names what is missing.
set -euo pipefail
build=$1 source=$2 work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build" --prefix "$work/prefix" >/dev/null
hide_boost=-DCMAKE_DISABLE_FIND_PACKAGE_Boost=ON
hide_hiredis=-DCMAKE_DISABLE_FIND_PACKAGE_PkgConfig=ON

# configure <name> <cmake arguments>...: configures the consumer in $work/<name>.
configure() {
  local name=$1
  shift
  cmake -S "$source" -B "$work/$name" -DCMAKE_PREFIX_PATH="$work/prefix" "$@" >"$work/$name.log" 2>&1
}
fail() {
  echo "FAILED: $1" >&2
  [[ -f $2 ]] && cat "$2" >&2
  exit 1
}

# consumer <name> <cmake arguments>...: configures, builds and runs it.
consumer() {
  local name=$1
  configure "$@" || fail "$name: configuring" "$work/$name.log"
  cmake --build "$work/$name" >>"$work/$name.log" 2>&1 || fail "$name: building" "$work/$name.log"
  for program in consumer media_consumer; do
    if [[ -x $work/$name/$program ]]; then
      "$work/$name/$program" || fail "$name: $program returned $?" ""
      echo "$name: $program built and ran"
    fi
  done
}

# not_found <name> <what must be named> <cmake arguments>...
not_found() {
  local name=$1 missing=$2
  shift 2
  if configure "$name" "$@"; then fail "$name: prime was found, though a component asked for cannot be" "$work/$name.log"; fi
  grep -q "$missing" "$work/$name.log" || fail "$name: the message does not name '$missing'" "$work/$name.log"
  echo "$name: not found, naming $missing"
}

consumer core "$hide_boost" "$hide_hiredis"
[[ -x $work/core/media_consumer ]] && fail "core: the media were linked though their dependencies are hidden" ""
consumer media "-DPRIME_COMPONENTS=shm;optimus" "-DPRIME_LOADED=shm;optimus"
[[ -x $work/media/media_consumer ]] || fail "media: prime::shm and prime::optimus were not linked" ""
configure all "-DPRIME_LOADED=shm;optimus" || fail "all: configuring" "$work/all.log"
echo "all: every component loaded"
not_found shm_without_boost "Boost" -DPRIME_COMPONENTS=shm "$hide_boost"
not_found optimus_without_hiredis "hiredis" -DPRIME_COMPONENTS=optimus "$hide_hiredis"
echo "find_package(prime) consumers built and ran"

# The installed prime finds its benchmarks where they are installed, and
# names that place when they are not there (a build without the benchmarks).
bench=$work/prefix/libexec/prime/bench
if [[ -d $build/bench ]]; then
  [[ -x $bench/ipc/prime_ipc && -x $bench/prime_table1 ]] || fail "the benchmarks are not installed in $bench" ""
  mv "$bench" "$work/moved"
  env -u PRIME_BENCH_DIR "$work/prefix/bin/prime" bench --out "$work/report" >"$work/bench.log" 2>&1 && status=0 || status=$?
  [[ $status -eq 2 ]] || fail "prime bench without its benchmarks exited $status, not 2" "$work/bench.log"
  grep -q "in $bench or" "$work/bench.log" || fail "prime bench does not name $bench" "$work/bench.log"
  echo "prime bench: looks for its benchmarks in $bench"
fi
