#!/usr/bin/env bash
# Compiles every C++ block of the README as it is written: each ```cpp block
# follows a line "<!-- compiles with tests/readme/<prologue> -->" naming what
# it takes as given (the user's own types and functions), and is compiled
# after that prologue. A block without that line fails the check.
#
#   compile_blocks.sh <compiler> <README.md> <source dir> <compiler flags...>
set -euo pipefail
compiler=$1 readme=$2 source=$3
shift 3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

awk -v out="$work" '
  /^ *<!-- compiles with tests\/readme\/[A-Za-z0-9_.]+ -->$/ { prologue = $4; sub(/.*\//, "", prologue); next }
  /^ *```cpp$/ {
    n++; file = out "/block" n ".cpp"
    if (prologue == "") { print "README block " n " (line " NR ") has no \"<!-- compiles with ... -->\" line" > "/dev/stderr"; bad = 1 }
    else print "#include \"" prologue "\"" > file
    printf "#line %d \"README.md\"\n", NR + 1 > file
    inside = 1; prologue = ""; next
  }
  /^ *```$/ && inside { inside = 0; close(file); next }
  inside { print > file }
  END { if (n == 0) { print "no C++ block found in the README" > "/dev/stderr"; bad = 1 } exit bad }
' "$readme"

status=0
for block in "$work"/block*.cpp; do
  if ! "$compiler" -std=c++23 -fsyntax-only -I"$source" "$@" "$block"; then
    echo "README block $(basename "$block" .cpp) does not compile as written" >&2
    status=1
  fi
done
[ $status -eq 0 ] && echo "every C++ block of the README compiles ($(ls "$work"/block*.cpp | wc -l) blocks)"
exit $status
