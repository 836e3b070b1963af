#!/usr/bin/env bash
# Paired rounds: two builds of one Google Benchmark binary, run alternately
# in one window (old, new, old, new...), so both see the same machine. Prints
# each benchmark's median per build and the median of the round-by-round
# speed ratio new/old (above 1: new is faster). A latency benchmark is read
# by its p50_ns counter, a throughput one by items_per_second, any other by
# its real time.
#
#   bench/paired_rounds.sh OLD_BINARY NEW_BINARY FILTER [ROUNDS=8] [MIN_TIME=0.3]
#
# e.g. bench/paired_rounds.sh /tmp/old/bench/ipc/prime_ipc build/release/bench/ipc/prime_ipc \
#        '^BM_(Latency_Shm/64|Throughput_ShmViews/64|RoundTrip_ShmService/64)/' 8
set -euo pipefail
if (($# < 3)); then
  sed -n '2,12p' "$0" >&2
  exit 2
fi
old=$1 new=$2 filter=$3 rounds=${4:-8} min_time=${5:-0.3}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for i in $(seq "$rounds"); do
  for who in old new; do
    binary=$old
    [ "$who" = new ] && binary=$new
    "$binary" --benchmark_filter="$filter" --benchmark_min_time="$min_time" --benchmark_format=json \
      > "$out/$who-$i.json" 2>/dev/null
  done
done
python3 - "$out" <<'EOF'
import glob, json, re, statistics, sys

runs = {}  # benchmark -> round -> build -> (unit, value)
for path in glob.glob(sys.argv[1] + "/*.json"):
    who, round_ = re.search(r"(old|new)-(\d+)\.json$", path).groups()
    for b in json.load(open(path))["benchmarks"]:
        if "p50_ns" in b:
            value = ("p50 ns", b["p50_ns"])
        elif "items_per_second" in b:
            value = ("M/s", b["items_per_second"] / 1e6)
        else:
            value = (b.get("time_unit", "ns"), b["real_time"])
        runs.setdefault(b["name"], {}).setdefault(int(round_), {})[who] = value
for name, by_round in runs.items():
    pairs = [r for r in by_round.values() if "old" in r and "new" in r]
    if not pairs:
        continue
    unit = pairs[0]["old"][0]
    old = [r["old"][1] for r in pairs]
    new = [r["new"][1] for r in pairs]
    speed = [n / o if unit == "M/s" else o / n for o, n in zip(old, new)]
    print(f"{name:50s} {unit:6s} old {statistics.median(old):11.2f}  new {statistics.median(new):11.2f}  "
          f"new/old speed {statistics.median(speed):.3f} ({min(speed):.2f}-{max(speed):.2f}, {len(pairs)} rounds)")
EOF
