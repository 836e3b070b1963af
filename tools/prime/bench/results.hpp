#pragma once

// What `prime bench` measured: one Figure per number (the report's CSV rows),
// and what could not run, with the reason.

#include <algorithm>
#include <cstdint>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace prime::tool::bench {

struct Figure {
  std::string who;        // a medium of Prime (Shm, ShmService, Radiant...) or a peer (Floor, Iceoryx, FastDdsShm...)
  std::string scenario;   // latency, latency-sleeping, throughput, round-trip, fan-out-4, table1-1lane, hop...
  std::int64_t payload;   // bytes (0: none)
  std::string statistic;  // mean, p50, p90, p99, p99.9, max, rate, per hop, publish, cpu per message
  double value;
  std::string unit;  // ns, msgs/s, calls/s
};

struct Skipped {
  std::string suite;
  std::string benchmark;  // empty: the whole suite
  std::string reason;
};

struct Results {
  std::vector<Figure> figures;
  std::vector<Skipped> skipped;
  // What the report must say of how a benchmark ran (a real-time priority
  // the machine refused, say), each once.
  std::vector<std::string> notes;

  [[nodiscard]] std::optional<double> find(const std::string& who, const std::string& scenario, std::int64_t payload,
                                           const std::string& statistic) const {
    for (const auto& f : figures)
      if (f.who == who && f.scenario == scenario && f.payload == payload && f.statistic == statistic) return f.value;
    return std::nullopt;
  }
  // Who has figures for `scenario`, in the order first seen.
  [[nodiscard]] std::vector<std::string> who_in(const std::string& scenario) const {
    std::vector<std::string> all;
    for (const auto& f : figures)
      if (f.scenario == scenario && std::find(all.begin(), all.end(), f.who) == all.end()) all.push_back(f.who);
    return all;
  }
  // The payloads measured for `scenario`, rising.
  [[nodiscard]] std::vector<std::int64_t> payloads_in(const std::string& scenario) const {
    std::set<std::int64_t> all;
    for (const auto& f : figures)
      if (f.scenario == scenario) all.insert(f.payload);
    return {all.begin(), all.end()};
  }
};

// A figure or ratio worked out from Results: from the medians, or from one
// round's figures alone.
using Measure = std::function<std::optional<double>(const Results&)>;

// The lowest and highest a measure came to in the rounds taken one by one:
// how far the machine's state moved it within a run. None with fewer than
// two rounds that give it.
struct Range {
  double low;
  double high;
  // Rounds this far apart (the highest over 1.25x the lowest) say the machine
  // changed state during the run: a comparison from its medians then holds
  // for one state only, and the report shows the range beside it.
  [[nodiscard]] bool unsteady() const { return high > 1.25 * low; }
};
inline std::optional<Range> range_over(const std::vector<Results>& rounds, const Measure& measure) {
  std::optional<Range> range;
  int seen = 0;
  for (const auto& round : rounds)
    if (const auto v = measure(round)) {
      ++seen;
      range = range ? Range{std::min(range->low, *v), std::max(range->high, *v)} : Range{*v, *v};
    }
  if (seen < 2) return std::nullopt;
  return range;
}

// Roles in the comparisons: Prime's own media, the floors a medium cannot
// beat, and the peers a user would pick instead.
// The SPSC rings (SpscFloor, and those that carry a header with each
// payload: SpscInline, SpscRecords, SpscRecordsHeaders, SpscShmLayout) are
// floors: what the hardware moves for their layout, nothing else done; so is
// cyclictest, the least a periodic loop's wake-up can be late; and
// FileWrite, write() of 1 MiB blocks into a file, what a recorder writes
// at most.
inline bool is_floor(const std::string& who) {
  return who == "Floor" || who == "FutexWake" || who.starts_with("Spsc") || who == "Cyclictest" || who == "FileWrite";
}
inline bool is_prime(const std::string& who) {
  return who.starts_with("Shm") || who == "Optimus" || who == "Radiant" || who == "Liberty" || who.starts_with("Sources") ||
         who == "Components";
}
inline bool is_peer(const std::string& who) { return !is_floor(who) && !is_prime(who); }

// The throughput floor: of the SPSC rings 4096 (SpscFloor) and 256 slots
// deep (SpscFloor256), the one that moves more here, as the floor is the
// most this machine can move, and which depth does differs by CPU
// (measured: 4096 1.9x faster than 256 on a Xeon, 256 3x faster than 4096
// on an AMD EPYC). SpscFloor when neither was measured.
inline std::string fastest_spsc_floor(const Results& r) {
  const auto deep = r.find("SpscFloor", "throughput", 64, "rate");
  const auto as_deep = r.find("SpscFloor256", "throughput", 64, "rate");
  return as_deep && (!deep || *as_deep > *deep) ? "SpscFloor256" : "SpscFloor";
}

}  // namespace prime::tool::bench
