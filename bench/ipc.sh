#!/usr/bin/env bash
# Prime's Shm medium against its peers between two processes, as Markdown
# tables, from one run of prime_ipc: one-way latency per payload, throughput,
# service round trips, and the targets of the Shm and services issues.
#
#   bench/ipc.sh [path/to/prime_ipc] [--ipc_no_pin] [more --benchmark_* flags]
#
# Build first:
#   cmake -S . -B build/release -DCMAKE_BUILD_TYPE=Release
#   cmake --build build/release -j2 --target prime_ipc
#
# Each benchmark runs 5 times for 0.2 s; the tables show the medians. The
# benchmark starts (and stops) its own iox-roudi, so no other RouDi may run.
# Its progress goes to stderr, the tables to stdout.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
binary="$here/../build/release/bench/ipc/prime_ipc"
if [[ $# -gt 0 && "$1" != --* ]]; then
  binary="$1"
  shift
fi
if [[ ! -x "$binary" ]]; then
  echo "ipc.sh: no benchmark binary at $binary; build the prime_ipc target first" >&2
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
    report = json.load(f)
runs, context = report["benchmarks"], report["context"]

# "BM_Latency_Shm/4096/real_time" -> ("Latency", "Shm", 4096): the median of
# the repetitions, or the only run when there was one.
latency, throughput, depth, errors = {}, {}, {}, {}
round_trip, calls = {}, {}
for run in runs:
    kind, peer = run["run_name"].split("/")[0].removeprefix("BM_").split("_", 1)
    payload = int(run["run_name"].split("/")[1])
    if run.get("error_occurred"):
        errors[(kind, peer, payload)] = run.get("error_message", "")
        continue
    if run.get("run_type") == "aggregate" and run.get("aggregate_name") != "median":
        continue
    if kind == "Latency" and "one_way_ns" in run:
        latency[(peer, payload)] = run["one_way_ns"]
    elif kind == "RoundTrip" and "one_way_ns" in run:
        round_trip[(peer, payload)] = 2 * run["one_way_ns"]
    elif kind == "Calls" and "calls/s" in run:
        calls[(peer, payload)] = run["calls/s"]
    elif kind == "Throughput" and "msgs/s" in run:
        throughput[(peer, payload)] = run["msgs/s"]
        if "depth" in run:
            depth[(peer, payload)] = int(run["depth"])

def size(p):
    return f"{p >> 20} MiB" if p % (1 << 20) == 0 else f"{p >> 10} KiB" if p % 1024 == 0 else f"{p} B"

def ns(v):
    if v is None:
        return "–"
    for unit, scale in (("ms", 1e6), ("µs", 1e3)):
        if v >= scale:
            return f"{v / scale:.3g} {unit}"
    return f"{v:.0f} ns"

def rate(v):
    if v is None:
        return "–"
    for unit, scale in (("M/s", 1e6), ("k/s", 1e3)):
        if v >= scale:
            return f"{v / scale:.3g} {unit}"
    return f"{v:.0f}/s"

def ratio(a, b):
    return None if a is None or b is None or b == 0 else a / b

def show(r):
    return "–" if r is None else f"{r:.2f}" if r < 100 else f"{r:.0f}"

# Floor and FutexWake do not depend on the payload: measured once, at 64 B.
floor = latency.get(("Floor", 64))
futex = latency.get(("FutexWake", 64))
busy = ["Shm", "Iceoryx", "UnixSocket", "PosixMqueue"]
sleeping = ["ShmSleeping", "IceoryxWaitSet"]
payloads = sorted({p for (_, p) in latency} | {64})

print(f"**One-way latency** between two processes (round trip / 2; median of the repetitions; "
      f"pinning: {context.get('ipc_pinning', 'unknown')}).\n")
print(f"- Floor, a cache-line ping-pong (busy-waiting, payload-independent): {ns(floor)}")
print(f"- FutexWake, a futex wake each way (sleeping, payload-independent): {ns(futex)}\n")
print("Busy-polling peers, with their ratio to Floor and to Iceoryx; sleeping peers, with their ratio to FutexWake. "
      "Zero-copy peers (Shm, Iceoryx) write a sequence number into an N-byte sample; "
      "UnixSocket and PosixMqueue copy all N bytes through the kernel, each way.\n")
print("| payload | " + " | ".join(busy + sleeping) + " |")
print("|---|" + "---:|" * (len(busy) + len(sleeping)))
for p in payloads:
    iox = latency.get(("Iceoryx", p))
    cells = []
    for peer in busy:
        v = latency.get((peer, p))
        cell = ns(v)
        if v is not None:
            r = [f"{show(ratio(v, floor))}× Floor"]
            if peer != "Iceoryx":
                r.append(f"{show(ratio(v, iox))}× Iceoryx")
            cell += " (" + ", ".join(r) + ")"
        cells.append(cell)
    for peer in sleeping:
        v = latency.get((peer, p))
        cells.append(ns(v) + ("" if v is None else f" ({show(ratio(v, futex))}× FutexWake)"))
    print(f"| {size(p)} | " + " | ".join(cells) + " |")

streams = ["Shm", "Iceoryx", "UnixSocket", "PosixMqueue"]
shallow = [f"{peer} {size(p)}: {d}" for (peer, p), d in sorted(depth.items()) if d != 256]
print("\n**Throughput**, messages per second, one process streaming to the other, lossless "
      "(queues 256 deep, the producer waits when full; UnixSocket: the kernel's socket buffers"
      + (f"; shallower, as the limits allow: {', '.join(shallow)}" if shallow else "") + ").\n")
print("| payload | " + " | ".join(streams) + " |")
print("|---|" + "---:|" * len(streams))
for p in sorted({p for (_, p) in throughput} | {64, 1 << 20}):
    print(f"| {size(p)} | " + " | ".join(rate(throughput.get((peer, p))) for peer in streams) + " |")

# Services: a request and its answer, N bytes each way. Floor and FutexWake
# round trips are twice their one-way figures; a Unix-socket ping-pong of N
# bytes is a request/reply over the socket.
floor_rt = None if floor is None else 2 * floor
futex_rt = None if futex is None else 2 * futex
service_payloads = sorted({p for (peer, p) in round_trip if peer in ("ShmService", "Iceoryx")} | {64})
print(f"\n**Services: round trip**, request and reply of N bytes (Floor's round trip {ns(floor_rt)}, "
      f"two futex wakes {ns(futex_rt)}).\n")
print("| payload | ShmService (busy) | Iceoryx request/response | UnixSocket request/reply | ShmService (sleeping) |")
print("|---|---:|---:|---:|---:|")
for p in service_payloads:
    v = round_trip.get(("ShmService", p))
    iox = round_trip.get(("Iceoryx", p))
    uds = latency.get(("UnixSocket", p))
    uds = None if uds is None else 2 * uds
    cell = ns(v) + ("" if v is None else f" ({show(ratio(v, floor_rt))}× Floor, {show(ratio(v, iox))}× Iceoryx)")
    s = round_trip.get(("ShmServiceSleeping", p))
    sleeping_cell = ns(s) + ("" if s is None else f" ({show(ratio(s, futex_rt))}× two futex wakes)")
    print(f"| {size(p)} | {cell} | {ns(iox)} | {ns(uds)} | {sleeping_cell} |")
linked, routed = round_trip.get(("ShmServicesLinked", 64)), round_trip.get(("ShmServicesRouted", 64))
print(f"\n- Two services, linked (`a | b`: a's output goes straight to b): {ns(linked)}; "
      f"the same two called in turn by the client: {ns(routed)} ({show(ratio(linked, routed))}×).")
print(f"- Calls per second that one service answers: {rate(calls.get(('ShmService', 1)))} for 1 client process, "
      f"{rate(calls.get(('ShmService', 4)))} for 4.")

# "mqueue_skipped_latency_1048576": a payload PosixMqueue's limits rule out.
notes = []
for k, v in context.items():
    if k.startswith("mqueue_skipped_"):
        kind, payload = k.removeprefix("mqueue_skipped_").split("_")
        notes.append((kind, int(payload), v))
notes = [f"{kind} {size(p)}: {why}" for kind, p, why in sorted(notes)]
if notes:
    print("\nPosixMqueue, not measured:\n")
    for n in notes:
        print(f"- {n}")
if errors:
    print("\nFailed:\n")
    for (kind, peer, p), message in sorted(errors.items()):
        print(f"- {kind} {peer} {size(p)}: {message}")

def verdict(label, values, ok, worst):
    values = [v for v in values if v is not None]
    if not values:
        return f"- {label}: not measured"
    w = worst(values)
    met = sum(ok(v) for v in values)
    status = "met" if met == len(values) else "MISSED"
    if len(values) == 1:
        return f"- {label}: {status} ({w:.2f})"
    return f"- {label}: {status} ({met} of {len(values)} payloads meet it; worst {w:.2f})"

shm = [latency.get(("Shm", p)) for p in payloads]
print("\nTargets (issue 3, point 9)\n")
print(verdict("Shm ≤ 2× Floor (busy-waiting; Shm/Floor)", [ratio(v, floor) for v in shm], lambda r: r <= 2, max))
print(verdict("Shm ≤ 0.35× Iceoryx (Shm/Iceoryx)", [ratio(latency.get(("Shm", p)), latency.get(("Iceoryx", p))) for p in payloads],
              lambda r: r <= 0.35, max))
r = ratio(latency.get(("Shm", 4 << 20)), latency.get(("Shm", 64)))
print(verdict("Shm 4 MiB ≤ 1.2× Shm 64 B (zero copy; 4 MiB/64 B)", [r], lambda r: r <= 1.2, max))
print(verdict("ShmSleeping ≤ 1.5× FutexWake (ShmSleeping/FutexWake)", [ratio(latency.get(("ShmSleeping", p)), futex) for p in payloads],
              lambda r: r <= 1.5, max))
t = throughput.get(("Shm", 64))
print(verdict("Shm ≥ 10 M msgs/s at 64 B (in M msgs/s)", [None if t is None else t / 1e6], lambda v: v >= 10, min))

print("\nTargets (services issue)\n")
service_busy = [round_trip.get(("ShmService", p)) for p in service_payloads]
print(verdict("ShmService round trip ≤ 2.5× Floor's", [ratio(v, floor_rt) for v in service_busy], lambda r: r <= 2.5, max))
print(verdict("ShmService ≤ 0.3× Iceoryx request/response",
              [ratio(round_trip.get(("ShmService", p)), round_trip.get(("Iceoryx", p))) for p in service_payloads],
              lambda r: r <= 0.3, max))
print(verdict("ShmService sleeping ≤ 1.5× two futex wakes", [ratio(round_trip.get(("ShmServiceSleeping", 64)), futex_rt)],
              lambda r: r <= 1.5, max))
print(verdict("Linked faster than routed by the client (linked/routed)", [ratio(linked, routed)], lambda r: r < 1, max))
EOF
