#!/usr/bin/env bash
# The paper's Table 1 as a Markdown table, from one run of prime_table1.
#
#   bench/table1.sh [path/to/prime_table1] [more --benchmark_* flags]
#
# Build first:
#   cmake -S . -B build/release -DCMAKE_BUILD_TYPE=Release
#   cmake --build build/release -j2 --target prime_table1
#
# Each benchmark runs 5 times for 0.2 s; the table shows the medians. The
# benchmark's own progress goes to stderr, the table to stdout.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
binary="$here/../build/release/bench/prime_table1"
if [[ $# -gt 0 && "$1" != --* ]]; then
  binary="$1"
  shift
fi
if [[ ! -x "$binary" ]]; then
  echo "table1.sh: no benchmark binary at $binary; build the prime_table1 target first" >&2
  exit 1
fi

json="$(mktemp)"
trap 'rm -f "$json"' EXIT
"$binary" --benchmark_min_time=0.2 --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
  --benchmark_out="$json" --benchmark_out_format=json "$@" >&2

python3 - "$json" <<'EOF'
import json
import sys

with open(sys.argv[1]) as f:
    runs = json.load(f)["benchmarks"]

# "BM_Sources/1024/2/real_time" -> ("Sources", 1024, 2): the median of the
# repetitions, or the only run when there was one.
hop = {}
for run in runs:
    if run.get("run_type") == "aggregate" and run.get("aggregate_name") != "median":
        continue
    if "error_occurred" in run or "ns_per_hop" not in run:
        continue
    name, payload, width = run["run_name"].split("/")[:3]
    hop[(name.removeprefix("BM_"), int(payload), int(width))] = run["ns_per_hop"]

cases = sorted({(p, w) for (_, p, w) in hop}, key=lambda c: (c[1], c[0]))

def payload(p):
    return f"{p // 1024} KiB" if p % 1024 == 0 else f"{p} B"

def ns(peer, p, w):
    v = hop.get((peer, p, w))
    return "—" if v is None else f"{v:.2f}" if v < 100 else f"{v:.0f}"

def ratio(a, b):
    return None if a is None or b is None or b == 0 else a / b

def show(r):
    return "—" if r is None else f"{r:.2f}" if r >= 0.01 else f"{r:.1e}"

rows = []
peers = [("For", "FOR"), ("Radiant", "Radiant"), ("Liberty", "Liberty"), ("Sources", "Sources (Liberty chain)"),
         ("SourcesRadiant", "Sources (Radiant chain)"), ("CcrLike", "CCR-like")]
print("ns per hop, and its ratio to FOR from the same run (chains of 100 services; CPU time for FOR, Radiant,")
print("Liberty; wall time for the threaded peers). Last column: Sources throughput / CCR-like throughput.\n")
print("| payload | width | " + " | ".join(label for _, label in peers) + " | Sources/CCR-like (Liberty; Radiant chain) |")
print("|---|---:|" + "---:|" * len(peers) + "---:|")
for p, w in cases:
    g = lambda peer: hop.get((peer, p, w))
    r = (ratio(g("Radiant"), g("For")), ratio(g("Liberty"), g("For")), ratio(g("CcrLike"), g("Sources")),
         ratio(g("CcrLike"), g("SourcesRadiant")))
    rows.append(r)
    cells = [ns("For", p, w)] + [f"{ns(peer, p, w)} ({show(ratio(g(peer), g('For')))}×)" for peer, _ in peers[1:]]
    print(f"| {payload(p)} | {w} | " + " | ".join(cells) + f" | {show(r[2])}×; {show(r[3])}× |")

if any(peer.endswith("_Inlined") for (peer, _, _) in hop):
    print("\nThe service visible to the optimiser (not part of Table 1)\n")
    print("| payload | width | FOR inlined | Radiant inlined | Radiant/FOR |")
    print("|---|---:|---:|---:|---:|")
    for p, w in cases:
        r = ratio(hop.get(("Radiant_Inlined", p, w)), hop.get(("For_Inlined", p, w)))
        print(f"| {payload(p)} | {w} | {ns('For_Inlined', p, w)} | {ns('Radiant_Inlined', p, w)} | {show(r)} |")

def verdict(label, values, ok, worst):
    values = [v for v in values if v is not None]
    if not values:
        return f"- {label}: not measured"
    w = worst(values)
    met = sum(ok(v) for v in values)
    return f"- {label}: {'met' if met == len(values) else 'MISSED'} ({met} of {len(values)} rows meet it; worst {w:.2f})"

print("\nTargets")
print(verdict("Radiant/FOR ≤ 1.05", [r[0] for r in rows], lambda v: v <= 1.05, max))
print(verdict("Liberty/FOR ≤ 5", [r[1] for r in rows], lambda v: v <= 5, max))
print(verdict("Sources (Liberty chain) ≥ 10× CCR-like throughput", [r[2] for r in rows], lambda v: v >= 10, min))
print(verdict("Sources (Radiant chain) ≥ 10× CCR-like throughput", [r[3] for r in rows], lambda v: v >= 10, min))
EOF
