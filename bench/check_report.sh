#!/usr/bin/env bash
# The smoke test of `prime bench --quick`: the command runs every suite and
# writes a report with the main figures, a summary and rendered plots. Speed
# is not checked here; only that the report is whole.
#
#   bench/check_report.sh <path/to/prime> <report folder>
set -euo pipefail
prime="$1"
out="$2"
rm -rf "$out"
"$prime" bench --quick --out "$out"

fail() { echo "check_report: $*" >&2; exit 1; }
csv="$out/figures.csv"
[[ -s "$csv" ]] || fail "no figures.csv"
[[ "$(head -1 "$csv")" == "who,scenario,payload,statistic,value,unit" ]] || fail "figures.csv has no header"
for row in "Floor,latency,64,p50," "Shm,latency,64,p50," "Shm,latency,64,p99.9," "Shm,latency,1048576,max," \
           "Shm,throughput,64,rate," "SpscFloor256,throughput,64,rate," "ShmService,round-trip,64,p50," "FutexWake,latency-sleeping,64,p50," \
           "For,table1-1lane,100,per hop," "Liberty,table1-1lane,100,per hop," \
           "Shm,fanout-throughput-1,64,rate," "Shm,fanout-publish-4,64,publish," \
           "ShmBatch,publisher-alone,64,rate," "ShmRecorder,record-flat,64,rate," "ShmRecorder,record-paced-100000-64,64,lost," \
           "ShmPlay,play-timing,0,p99," "ShmHandWired,sensor-to-command-split,0,p50," \
           "Components,sensor-to-command-split,0,p50," "Components,sensor-to-command-one,0,p50,"; do
  grep -q "^$row" "$csv" || fail "figures.csv lacks $row"
done
if command -v redis-server >/dev/null; then
  grep -q "^Optimus,hop,0,mean," "$csv" || fail "figures.csv lacks the Optimus hop"
fi
# The 1 kHz loop: measured where cyclictest and stress-ng are installed (cyclictest
# only where real-time priority is allowed), else listed as skipped, never silently.
if command -v cyclictest >/dev/null && command -v stress-ng >/dev/null; then
  for row in "Shm,loop-lateness-idle,0,p99," "Shm,loop-lateness-load,0,p99.9," "Shm,loop-e2e-load,0,p99.9," \
             "Iceoryx,loop-e2e-load,0,p99.9," "Shm,loop-idle,0,priority,"; do
    grep -q "^$row" "$csv" || fail "figures.csv lacks $row"
  done
  grep -q "^Cyclictest,loop-lateness-idle,0,p99," "$csv" || grep -q "^- loop BM_Loop/load:0 Cyclictest: " "$out/summary.md" ||
    fail "cyclictest was neither measured nor listed as skipped"
  grep -q "^## 1 kHz loop" "$out/summary.md" || fail "summary.md has no loop section"
else
  grep -q "^- loop: .* is not installed" "$out/summary.md" || fail "the loop suite was neither run nor listed as skipped"
fi
grep -q "^## Components: sensor to command" "$out/summary.md" || fail "summary.md has no components section"
grep -q "^## Headline" "$out/summary.md" || fail "summary.md has no headline"
grep -q "| Shm one-way latency, 64 B, p50 |" "$out/summary.md" || fail "the headline lacks Shm's latency"
grep -q "Measured .* CPUs" "$out/summary.md" || fail "summary.md does not say which machine"
if grep -E "exited with status|ran past|reported nothing" "$out/summary.md"; then fail "a benchmark crashed or hung"; fi
for plot in latency latency-distribution-64 throughput service table1; do
  [[ -s "$out/plots/$plot.svg" && -s "$out/plots/$plot.png" ]] || fail "plot $plot was not rendered"
done
echo "check_report: the quick report is whole: $(($(wc -l < "$csv") - 1)) figures"
