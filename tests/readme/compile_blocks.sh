#!/usr/bin/env bash
# Compiles every C++ block of the README and the docs as it is written: each
# ```cpp block follows a line "<!-- compiles with tests/readme/<prologue> -->"
# naming what it takes as given (the user's own types and functions), and is
# compiled after that prologue. A block without that line fails the check,
# and so does a C++ block fenced otherwise (```c++, ```cc, ```cxx), which
# the check would pass over.
#
#   compile_blocks.sh <compiler> <file.md>... <source dir> <compiler flags...>
#
# A file with no C++ block passes; if none of the files has one, the check
# fails (it would be checking nothing).
set -euo pipefail
compiler=$1
shift
files=()
while [ $# -gt 0 ] && [[ $1 == *.md ]]; do
  files+=("$1")
  shift
done
if [ ${#files[@]} -eq 0 ] || [ $# -eq 0 ]; then
  echo "usage: compile_blocks.sh <compiler> <file.md>... <source dir> <compiler flags...>" >&2
  exit 2
fi
source=$1
shift
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

status=0
for doc in "${files[@]}"; do
  # As the file is named from the repository's root: README.md, docs/shm.md.
  name=$(basename "$doc")
  [ "$(basename "$(dirname "$doc")")" = docs ] && name=docs/$name
  mkdir -p "$work/$name"
  awk -v out="$work/$name" -v name="$name" '
    /^ *<!-- compiles with tests\/readme\/[A-Za-z0-9_.]+ -->$/ { prologue = $4; sub(/.*\//, "", prologue); next }
    /^ *```(c\+\+|C\+\+|cc|cxx|hpp|h)[ ]*$/ {
      print name " line " NR ": a C++ block must be fenced as ```cpp to be compiled" > "/dev/stderr"; bad = 1; next
    }
    /^ *```cpp$/ {
      n++; file = out "/block" n ".cpp"
      if (prologue == "") { print name " block " n " (line " NR ") has no \"<!-- compiles with ... -->\" line" > "/dev/stderr"; bad = 1 }
      else print "#include \"" prologue "\"" > file
      printf "#line %d \"%s\"\n", NR + 1, name > file
      inside = 1; prologue = ""; next
    }
    /^ *```$/ && inside { inside = 0; close(file); next }
    inside { print > file }
    END { exit bad }
  ' "$doc" || status=1
done

blocks=$(find "$work" -name 'block*.cpp' | sort)
if [ -z "$blocks" ]; then
  echo "no C++ block found in ${files[*]}" >&2
  exit 1
fi
for block in $blocks; do
  if ! "$compiler" -std=c++23 -fsyntax-only -I"$source" "$@" "$block"; then
    where=${block#"$work"/}
    echo "${where%/block*} block $(basename "$block" .cpp | tr -dc 0-9) does not compile as written" >&2
    status=1
  fi
done
[ $status -eq 0 ] && echo "every C++ block compiles ($(echo "$blocks" | wc -l) blocks in ${#files[@]} files)"
exit $status
