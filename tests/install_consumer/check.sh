#!/usr/bin/env bash
# Installs Prime from the build tree into a scratch prefix, then configures,
# builds and runs outside projects that do find_package(prime):
#   core      no components, Boost and pkg-config (so hiredis) hidden from
#             CMake: prime::liberty links, Shm (compiled, needing no Boost)
#             is loaded, Optimus is not;
#   media     COMPONENTS shm optimus, everything visible: prime::shm and
#             prime::optimus link into a program that runs;
#   recordings  COMPONENTS record: a recording written and played into a
#             chain through prime::record;
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
  for program in consumer media_consumer record_consumer; do
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

# No installed header includes Boost or hiredis: the media's use of them is
# compiled into libprime_shm and libprime_optimus.
if grep -rlE '#include <(boost|hiredis)/' "$work/prefix/include"; then
  fail "installed headers include Boost or hiredis (above)" ""
fi
echo "no installed header includes Boost or hiredis"
# Optimus's detail/ is inside its library: not installed. Shm's sample
# path must inline, so its detail/ is installed. Either way each installed
# header of both media compiles alone against the prefix.
[[ -e $work/prefix/include/prime/optimus/detail ]] && fail "Optimus's detail/ headers are installed" ""
compiler=$(sed -n 's/^CMAKE_CXX_COMPILER:[A-Z]*=//p' "$build/CMakeCache.txt")
for medium in shm optimus; do
  for header in "$work/prefix/include/prime/$medium.hpp" "$work/prefix/include/prime/$medium"/*.hpp; do
    echo "#include \"${header#"$work/prefix/include/"}\"" |
      "${compiler:-c++}" -std=c++23 -fsyntax-only -DMSGPACK_NO_BOOST -I"$work/prefix/include" -x c++ - 2>"$work/header.log" ||
      fail "the installed ${header#"$work/prefix/include/"} does not compile on its own" "$work/header.log"
  done
  echo "$medium: each installed header compiles on its own"
done
for header in "$work/prefix/include/prime/record"/*.hpp; do
  echo "#include \"${header#"$work/prefix/include/"}\"" |
    "${compiler:-c++}" -std=c++23 -fsyntax-only -I"$work/prefix/include" -x c++ - 2>"$work/header.log" ||
    fail "the installed ${header#"$work/prefix/include/"} does not compile on its own" "$work/header.log"
done
echo "record: each installed header compiles on its own"
for library in libprime_shm.so libprime_shm.a libprime_optimus.so libprime_optimus.a libprime_record.so libprime_record.a; do
  compgen -G "$work/prefix/lib*/$library" >/dev/null || compgen -G "$work/prefix/lib*/*/$library" >/dev/null ||
    fail "$library is not installed" ""
done
echo "libprime_shm, libprime_optimus and libprime_record installed, shared and static"
# The Python package, installed where Debian's python3 looks, imports from
# the prefix (its module finds libprime_shm there through its RUNPATH).
if [[ -d $work/prefix/lib/python3/dist-packages/prime ]]; then
  PYTHONPATH=$work/prefix/lib/python3/dist-packages /usr/bin/python3 -c \
    'import prime, prime.shm; assert issubclass(prime.TypeMismatch, prime.Error)' 2>"$work/python.log" ||
    fail "the installed prime Python package does not import" "$work/python.log"
  echo "python: the installed package imports"
fi
consumer core -DPRIME_LOADED=shm "$hide_boost" "$hide_hiredis"
[[ -x $work/core/media_consumer ]] && fail "core: the media were linked though their dependencies are hidden" ""
consumer media "-DPRIME_COMPONENTS=shm;optimus" "-DPRIME_LOADED=shm;optimus"
[[ -x $work/media/media_consumer ]] || fail "media: prime::shm and prime::optimus were not linked" ""
consumer recordings "-DPRIME_COMPONENTS=record" "-DPRIME_LOADED=record"
[[ -x $work/recordings/record_consumer ]] || fail "recordings: prime::record was not linked" ""
configure all "-DPRIME_LOADED=shm;optimus;record" || fail "all: configuring" "$work/all.log"
echo "all: every component loaded"
not_found optimus_without_hiredis "hiredis" -DPRIME_COMPONENTS=optimus "$hide_hiredis"
echo "find_package(prime) consumers built and ran"

# Prime itself configures without Boost, hiredis or CLI11 when the media and
# the tool that need them are left out; left in, the message names the
# Debian package and the option.
without="-DPRIME_WITH_SHM=OFF -DPRIME_WITH_OPTIMUS=OFF -DPRIME_WITH_TOOLS=OFF"
hide_cli11=-DCMAKE_DISABLE_FIND_PACKAGE_CLI11=ON
# shellcheck disable=SC2086
cmake -S "$source/../.." -B "$work/core_only" $without "$hide_boost" "$hide_hiredis" "$hide_cli11" \
  >"$work/core_only.log" 2>&1 || fail "prime without Shm, Optimus and the tool did not configure" "$work/core_only.log"
cmake --install "$work/core_only" --prefix "$work/core_prefix" >>"$work/core_only.log" 2>&1 ||
  fail "prime without Shm, Optimus and the tool did not install" "$work/core_only.log"
echo "core only: configured and installed without Boost, hiredis or CLI11"
if cmake -S "$source/../.." -B "$work/no_boost" "$hide_boost" >"$work/no_boost.log" 2>&1; then
  fail "prime configured with Shm on and Boost hidden" "$work/no_boost.log"
fi
grep -q "libboost-dev" "$work/no_boost.log" && grep -q "PRIME_WITH_SHM=OFF" "$work/no_boost.log" ||
  fail "the message does not name libboost-dev and PRIME_WITH_SHM=OFF" "$work/no_boost.log"
echo "Shm on, Boost hidden: refused, naming libboost-dev and PRIME_WITH_SHM=OFF"
# A consumer of that install finds the core, and not the media it lacks.
configure from_core_only -DCMAKE_PREFIX_PATH="$work/core_prefix" || fail "from_core_only: configuring" "$work/from_core_only.log"
echo "from_core_only: the core found, and neither medium"
not_found shm_from_core_only "built without it" -DCMAKE_PREFIX_PATH="$work/core_prefix" -DPRIME_COMPONENTS=shm

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
