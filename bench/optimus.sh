#!/usr/bin/env bash
# Optimus against bare hiredis as a Markdown table, from one run of prime_optimus_bench.
#
#   bench/optimus.sh [path/to/prime_optimus_bench] [more --benchmark_* flags]
#
# Build first:
#   cmake -S . -B build/release -DCMAKE_BUILD_TYPE=Release
#   cmake --build build/release -j2 --target prime_optimus_bench
#
# Each benchmark runs 5 times for 0.5 s; the table shows the medians. The
# binary starts its own redis-server on a free loopback port. Its progress goes
# to stderr, the table to stdout.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
binary="$here/../build/release/bench/optimus/prime_optimus_bench"
if [[ $# -gt 0 && "$1" != --* ]]; then
  binary="$1"
  shift
fi
if [[ ! -x "$binary" ]]; then
  echo "optimus.sh: no benchmark binary at $binary; build the prime_optimus_bench target first" >&2
  exit 1
fi

json="$(mktemp)"
trap 'rm -f "$json"' EXIT
"$binary" --benchmark_min_time=0.5 --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
  --benchmark_out="$json" --benchmark_out_format=json "$@" >&2

python3 - "$json" <<'PY'
import json
import sys

with open(sys.argv[1]) as f:
    runs = json.load(f)["benchmarks"]

# "BM_Optimus_Hop/real_time" -> median µs per iteration and items per second.
us, rate = {}, {}
for run in runs:
    if run.get("run_type") == "aggregate" and run.get("aggregate_name") != "median":
        continue
    if "error_occurred" in run:
        continue
    name = run["run_name"].split("/")[0].removeprefix("BM_")
    scale = {"ns": 1e-3, "us": 1.0, "ms": 1e3}[run.get("time_unit", "ns")]
    us[name] = run["real_time"] * scale
    rate[name] = run.get("items_per_second")

def t(name):
    return "—" if name not in us else f"{us[name]:.1f} µs"

def ratio(a, b, table):
    return None if a not in table or b not in table or not table[b] else table[a] / table[b]

def show(r):
    return "—" if r is None else f"{r:.2f}×"

def per_s(name):
    v = rate.get(name)
    return "—" if v is None else f"{v / 1000:.0f} k/s"

print("Optimus against bare hiredis on one redis-server (loopback TCP), medians of 5 runs from one process.\n")
print("| what | Optimus | peer | ratio |")
print("|---|---:|---:|---:|")
hop = ratio("Optimus_Hop", "Hiredis_RequestReply", us)
print(f"| one hop vs a hand-written hiredis request/reply | {t('Optimus_Hop')} | {t('Hiredis_RequestReply')} | {show(hop)} |")
print(f"| one hop vs one PING round trip (the floor) | {t('Optimus_Hop')} | {t('Hiredis_Ping')} | {show(ratio('Optimus_Hop', 'Hiredis_Ping', us))} |")
linked = ratio("Optimus_Linked2", "Optimus_CallerRouted2", us)
print(f"| 2 services linked vs the same 2 routed by the caller | {t('Optimus_Linked2')} | {t('Optimus_CallerRouted2')} | {show(linked)} |")
pipelined = ratio("Optimus_PublishPipelined", "Optimus_Publish", rate)
print(f"| source: publish in batches of 64 vs one at a time (msgs/s) | {per_s('Optimus_PublishPipelined')} | {per_s('Optimus_Publish')} | {show(pipelined)} |")
print(f"| source: batches of 64 published and read back (msgs/s) | {per_s('Optimus_SourceThroughput')} | | |")

print("\nTargets")
print(f"- Optimus hop / hiredis request-reply ≤ 1.3: " + ("not measured" if hop is None else f"{'met' if hop <= 1.3 else 'MISSED'} ({hop:.2f})"))
print(f"- linked faster than caller-routed: " + ("not measured" if linked is None else f"{'met' if linked < 1 else 'MISSED'} ({linked:.2f})"))
PY
