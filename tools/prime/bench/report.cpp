#include "report.hpp"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <sstream>
#include <tuple>
#include <utility>

namespace prime::tool::bench {

namespace {

std::string number(double v, const char* format = "%.3g") {
  char text[32];
  std::snprintf(text, sizeof text, format, v);
  return text;
}

std::string ratio_text(std::optional<double> r) { return r ? number(*r) + "×" : "–"; }

// Floors first, then Prime's media, then the peers, each group in the order seen.
std::vector<std::string> ordered(std::vector<std::string> who) {
  std::stable_sort(who.begin(), who.end(), [](const std::string& a, const std::string& b) {
    auto rank = [](const std::string& w) { return is_floor(w) ? 0 : is_prime(w) ? 1 : 2; };
    return rank(a) < rank(b);
  });
  return who;
}

std::optional<double> divide(std::optional<double> a, std::optional<double> b) {
  if (!a || !b || *b == 0) return std::nullopt;
  return *a / *b;
}

// The figure a table shows and a ratio compares: p50 where there is one, else the mean.
std::optional<double> central(const Results& r, const std::string& who, const std::string& scenario, std::int64_t payload) {
  if (auto p50 = r.find(who, scenario, payload, "p50")) return p50;
  if (auto rate = r.find(who, scenario, payload, "rate")) return rate;
  if (auto per_hop = r.find(who, scenario, payload, "per hop")) return per_hop;
  return r.find(who, scenario, payload, "mean");
}

// The best peer's figure for `scenario` at `payload`: the least time, or the highest rate.
std::optional<std::pair<std::string, double>> best_peer(const Results& r, const std::string& scenario, std::int64_t payload,
                                                        bool higher_is_better) {
  std::optional<std::pair<std::string, double>> best;
  for (const auto& who : r.who_in(scenario)) {
    if (!is_peer(who)) continue;
    const auto v = central(r, who, scenario, payload);
    if (v && (!best || (higher_is_better ? *v > best->second : *v < best->second))) best = {{who, *v}};
  }
  return best;
}

// A Markdown table of `scenario`: a row per payload, a column per who
// (p50 / p99 for latencies, the rate for throughputs), and for each of
// Prime's media its ratio to `floor` and to the best peer.
std::string scenario_table(const Results& r, const std::string& scenario, const std::string& floor, bool rates) {
  const auto who = ordered(r.who_in(scenario));
  if (who.empty()) return "No figures.\n";
  std::ostringstream out;
  out << "| payload |";
  for (const auto& w : who) out << ' ' << w << " |";
  for (const auto& w : who)
    if (is_prime(w)) out << ' ' << w << ": ×" << (floor.empty() ? "" : floor + ", ×") << "best peer |";
  out << "\n|---|";
  for (std::size_t i = 0; i < who.size(); ++i) out << "---:|";
  for (const auto& w : who)
    if (is_prime(w)) out << "---:|";
  out << '\n';
  for (const auto payload : r.payloads_in(scenario)) {
    out << "| " << size_text(payload) << " |";
    for (const auto& w : who) {
      if (rates) {
        const auto v = r.find(w, scenario, payload, "rate");
        out << ' ' << (v ? rate_text(*v) : "–") << " |";
      } else {
        const auto p50 = r.find(w, scenario, payload, "p50");
        const auto p99 = r.find(w, scenario, payload, "p99");
        const auto mean = r.find(w, scenario, payload, "mean");
        out << ' ' << (p50 ? time_text(*p50) : mean ? time_text(*mean) : "–");
        if (p99) out << " / " << time_text(*p99);
        out << " |";
      }
    }
    for (const auto& w : who) {
      if (!is_prime(w)) continue;
      const auto mine = central(r, w, scenario, payload);
      const auto best = best_peer(r, scenario, payload, rates);
      out << ' ';
      if (!floor.empty()) out << ratio_text(divide(mine, central(r, floor, scenario, payload))) << ", ";
      out << ratio_text(divide(mine, best ? std::optional<double>{best->second} : std::nullopt));
      if (best) out << " (" << best->first << ')';
      out << " |";
    }
    out << '\n';
  }
  return out.str();
}

// The distributions behind a scenario's table: every percentile, per who and payload.
std::string distribution_table(const Results& r, const std::string& scenario) {
  const auto who = ordered(r.who_in(scenario));
  std::ostringstream out;
  out << "| who | payload | mean | p50 | p90 | p99 | p99.9 | max |\n|---|---|---:|---:|---:|---:|---:|---:|\n";
  for (const auto& w : who)
    for (const auto payload : r.payloads_in(scenario)) {
      if (!r.find(w, scenario, payload, "p50")) continue;
      out << "| " << w << " | " << size_text(payload) << " |";
      for (const char* s : {"mean", "p50", "p90", "p99", "p99.9", "max"}) {
        const auto v = r.find(w, scenario, payload, s);
        out << ' ' << (v ? time_text(*v) : "–") << " |";
      }
      out << '\n';
    }
  return out.str();
}

// Fan-out, competing load and sleeping subscribers: one row per scenario.
std::string scenarios_table(const Results& r) {
  std::ostringstream out;
  bool any = false;
  out << "| scenario | who | p50 | p99 | p99.9 | max | publish | CPU per message |\n"
         "|---|---|---:|---:|---:|---:|---:|---:|\n";
  std::vector<std::string> scenarios;
  for (const auto& f : r.figures)
    if ((f.scenario.starts_with("fan-out") || f.scenario.starts_with("sleeping-") || f.scenario == "latency-loaded") &&
        std::find(scenarios.begin(), scenarios.end(), f.scenario) == scenarios.end())
      scenarios.push_back(f.scenario);
  for (const auto& scenario : scenarios)
    for (const auto& w : r.who_in(scenario))
      for (const auto payload : r.payloads_in(scenario)) {
        any = true;
        out << "| " << scenario << " | " << w << " |";
        for (const char* stat : {"p50", "p99", "p99.9", "max", "publish", "cpu per message"}) {
          const auto v = r.find(w, scenario, payload, stat);
          out << ' ' << (v ? time_text(*v) : "–") << " |";
        }
        out << '\n';
      }
  if (!any) return "No figures.\n";
  // The plain busy latency beside the loaded one, from the same run.
  if (const auto loaded = r.find("Shm", "latency-loaded", 64, "p99"))
    if (const auto plain = r.find("Shm", "latency", 64, "p99"))
      out << "\nShm at 64 B under a competing busy process: p99 " << time_text(*loaded) << " against " << time_text(*plain)
          << " unloaded (" << ratio_text(divide(loaded, plain)) << ").\n";
  return out.str();
}

// Fan-out at 64 B: the lossless rate and the publisher's own cost per message
// against the number of reader processes, and what each added reader costs
// the publisher, beside one cache-line transfer (the floor's one-way latency).
std::string fan_out_throughput_table(const Results& r) {
  std::ostringstream out;
  out << "| readers | lossless rate | × 1 reader | publisher's time per message (drop_oldest) | added per extra reader |\n"
         "|---:|---:|---:|---:|---:|\n";
  const auto rate_1 = r.find("Shm", "fanout-throughput-1", 64, "rate");
  const auto publish_1 = r.find("Shm", "fanout-publish-1", 64, "publish");
  bool any = false;
  for (const int n : {1, 2, 4}) {
    const auto rate = r.find("Shm", "fanout-throughput-" + std::to_string(n), 64, "rate");
    const auto publish = r.find("Shm", "fanout-publish-" + std::to_string(n), 64, "publish");
    if (!rate && !publish) continue;
    any = true;
    out << "| " << n << " | " << (rate ? rate_text(*rate) : "–") << " | " << ratio_text(divide(rate, rate_1)) << " | "
        << (publish ? time_text(*publish) : "–") << " | ";
    if (n > 1 && publish && publish_1) out << time_text((*publish - *publish_1) / (n - 1));
    else out << "–";
    out << " |\n";
  }
  if (!any) return "No figures.\n";
  if (const auto line = r.find("Floor", "latency", 64, "p50"))
    out << "\nOne cache-line transfer between the two CPUs (the floor's one-way latency at 64 B, p50, same run): "
        << time_text(*line) << ". The readers share the second CPU, so with more than one they take turns on it.\n";
  return out.str();
}

// The 1 kHz loop (prime_ipc's loop suite), idle and under load: Prime's
// wake-up lateness beside cyclictest's and the goal's ratio, end-to-end
// latency beside iceoryx's; then how each run was scheduled.
std::string loop_tables(const Results& r) {
  const std::pair<const char*, const char*> kMachine[] = {{"idle", "idle"}, {"load", "under load (stress-ng)"}};
  bool any = false;
  for (const auto& [load, text] : kMachine) any = any || !r.who_in("loop-lateness-" + std::string{load}).empty();
  if (!any) return "No figures.\n";
  // "p50 / p99 / p99.9 / max" of who in scenario.
  auto spread = [&](const std::string& who, const std::string& scenario) {
    std::string text;
    bool found = false;
    for (const char* statistic : {"p50", "p99", "p99.9", "max"}) {
      const auto v = r.find(who, scenario, 0, statistic);
      found = found || v.has_value();
      text += (text.empty() ? "" : " / ") + (v ? time_text(*v) : std::string{"–"});
    }
    return found ? text : std::string{"–"};
  };
  std::ostringstream out;
  out << "| machine | Prime lateness | cyclictest lateness | Prime / cyclictest, p99 | hand-written loop lateness "
         "(iceoryx's) | Prime end to end | iceoryx end to end | Prime / iceoryx, p99.9 |\n"
         "|---|---:|---:|---:|---:|---:|---:|---:|\n";
  std::vector<std::string> verdicts;
  for (const auto& [load, text] : kMachine) {
    const std::string lateness = "loop-lateness-" + std::string{load}, e2e = "loop-e2e-" + std::string{load};
    const auto ratio = divide(r.find("Shm", lateness, 0, "p99"), r.find("Cyclictest", lateness, 0, "p99"));
    out << "| " << text << " | " << spread("Shm", lateness) << " | " << spread("Cyclictest", lateness) << " | "
        << ratio_text(ratio) << " | " << spread("Iceoryx", lateness) << " | " << spread("Shm", e2e) << " | "
        << spread("Iceoryx", e2e) << " | "
        << ratio_text(divide(r.find("Shm", e2e, 0, "p99.9"), r.find("Iceoryx", e2e, 0, "p99.9"))) << " |\n";
    if (ratio) verdicts.push_back(std::string{text} + " " + ratio_text(ratio) + (*ratio <= 1.2 ? " (met)" : " (NOT met)"));
  }
  out << "\nEach cell: p50 / p99 / p99.9 / max. Goal: Prime's lateness p99 at most 1.2× cyclictest's: ";
  for (std::size_t i = 0; i < verdicts.size(); ++i) out << (i ? "; " : "") << verdicts[i];
  if (verdicts.empty()) out << "cyclictest was not measured (see Skipped), so no ratio";
  out << ".\n\n";

  out << "| run | machine | SCHED_FIFO priority | ticks | lost | machine's CPU time busy |\n|---|---|---:|---:|---:|---:|\n";
  std::vector<std::string> refused;
  for (const auto& [load, text] : kMachine)
    for (const auto& who : ordered(r.who_in("loop-" + std::string{load}))) {
      const std::string scenario = "loop-" + std::string{load};
      const auto priority = r.find(who, scenario, 0, "priority");
      const auto ticks = r.find(who, scenario, 0, "ticks");
      const auto lost = r.find(who, scenario, 0, "lost");
      const auto busy = r.find(who, scenario, 0, "busy");
      out << "| " << who << " | " << text << " | "
          << (priority ? (*priority > 0 ? number(*priority, "%.0f") : std::string{"normal (refused)"}) : "–") << " | "
          << (ticks ? number(*ticks, "%.0f") : "–") << " | " << (lost ? number(*lost, "%.0f") : "–") << " | "
          << (busy ? number(*busy * 100, "%.0f") + " %" : "–") << " |\n";
      if (priority && *priority == 0) refused.push_back(who + " " + text);
    }
  if (!refused.empty()) {
    out << "\n**The machine refused real-time priority** for ";
    for (std::size_t i = 0; i < refused.size(); ++i) out << (i ? ", " : "") << refused[i];
    out << ": those ran at normal priority (why: Notes, below).\n";
  }
  return out.str();
}

std::string table1_table(const Results& r) {
  std::vector<std::string> scenarios;
  for (const auto& f : r.figures)
    if (f.scenario.starts_with("table1-") && std::find(scenarios.begin(), scenarios.end(), f.scenario) == scenarios.end())
      scenarios.push_back(f.scenario);
  if (scenarios.empty()) return "No figures.\n";
  std::vector<std::string> who;
  for (const auto& s : scenarios)
    for (const auto& w : r.who_in(s))
      if (std::find(who.begin(), who.end(), w) == who.end()) who.push_back(w);
  std::ostringstream out;
  out << "ns per hop (chains of 100 services); Radiant and Liberty as a ratio to FOR, Sources to the CCR-like peer "
         "(as throughput: FOR's time / theirs).\n\n| payload | lanes |";
  for (const auto& w : who) out << ' ' << w << " |";
  out << " Radiant/FOR | Liberty/FOR | Sources throughput / CCR-like |\n|---|---|";
  for (std::size_t i = 0; i < who.size() + 3; ++i) out << "---:|";
  out << '\n';
  for (const auto& s : scenarios)
    for (const auto payload : r.payloads_in(s)) {
      out << "| " << size_text(payload) << " | " << s.substr(7, s.size() - 11) << " |";
      for (const auto& w : who) {
        const auto v = r.find(w, s, payload, "per hop");
        out << ' ' << (v ? number(*v, "%.1f") : "–") << " |";
      }
      const auto for_ = r.find("For", s, payload, "per hop");
      out << ' ' << ratio_text(divide(r.find("Radiant", s, payload, "per hop"), for_)) << " | "
          << ratio_text(divide(r.find("Liberty", s, payload, "per hop"), for_)) << " | "
          << ratio_text(divide(r.find("CcrLike", s, payload, "per hop"), r.find("Sources", s, payload, "per hop"))) << " |\n";
    }
  return out.str();
}

std::string optimus_table(const Results& r) {
  std::ostringstream out;
  bool any = false;
  out << "| who | what | time | rate |\n|---|---|---:|---:|\n";
  for (const auto& who : {"Optimus", "hiredis", "redis-benchmark"})
    for (const auto& f : r.figures) {
      if (f.who != who || f.statistic != "mean") continue;
      any = true;
      const auto rate = r.find(f.who, f.scenario, f.payload, "rate");
      out << "| " << f.who << " | " << f.scenario << (f.payload ? " (" + std::to_string(f.payload) + ")" : "") << " | "
          << time_text(f.value) << " | " << (rate ? rate_text(*rate) : "–") << " |\n";
    }
  if (!any) return "No figures.\n";
  const auto hop = r.find("Optimus", "hop", 0, "mean");
  out << "\nOne Optimus hop is " << ratio_text(divide(hop, r.find("hiredis", "request-reply", 0, "mean")))
      << " a hand-written hiredis request/reply and " << ratio_text(divide(hop, r.find("hiredis", "ping", 0, "mean")))
      << " a PING round trip.";
  if (const auto batched = r.find("Optimus", "publish-pipelined", 64, "rate"))
    out << " Publishing in batches of 64 appends " << rate_text(*batched) << ", "
        << ratio_text(divide(batched, r.find("redis-benchmark", "xadd-pipelined", 64, "rate")))
        << " what `redis-benchmark -P 64` achieves for XADD (untrimmed) on the same server with its 50 clients, and "
        << ratio_text(divide(batched, r.find("redis-benchmark", "xadd-pipelined-one-client", 64, "rate")))
        << " what it achieves with one (`-c 1`), which, as publish_all does, reads a batch's replies before it "
           "sends the next.";
  if (const auto streamed = r.find("Optimus", "publish-streamed", 64, "rate"))
    out << " Streamed (StreamingPublisher: one batch in flight while the next is sent) it appends "
        << rate_text(*streamed) << ", "
        << ratio_text(divide(streamed, r.find("redis-benchmark", "xadd-pipelined", 64, "rate")))
        << " the 50 clients' rate.";
  out << '\n';
  return out.str();
}

// Components (the system suite): sensor to command per placement, and the
// layer's cost against the same pipeline wired by hand in the same run.
std::string components_table(const Results& r) {
  const auto hand = r.find("ShmHandWired", "sensor-to-command-split", 0, "p50");
  if (!hand && !r.find("Components", "sensor-to-command-split", 0, "p50")) return "No figures.\n";
  std::ostringstream out;
  out << "| placement | links | p50 | p99 | against the hand-wired pipeline (p50) |\n|---|---|---:|---:|---|\n";
  const auto row = [&](const std::string& who, const std::string& placement, const std::string& what, const std::string& links) {
    const auto p50 = r.find(who, "sensor-to-command-" + placement, 0, "p50");
    if (!p50) return;
    const auto p99 = r.find(who, "sensor-to-command-" + placement, 0, "p99");
    out << "| " << what << " | " << links << " | " << time_text(*p50) << " | " << (p99 ? time_text(*p99) : "–") << " | "
        << (who == "ShmHandWired" ? "1×" : ratio_text(divide(p50, hand))) << " |\n";
  };
  row("ShmHandWired", "split", "hand-wired (no components), planner in its own process", "Shm");
  row("Components", "split", "components, `split`: planner in its own process", "Shm");
  row("Components", "one", "components, `one`: all in one process", "in-process");
  row("Components", "machines", "components, `machines`: planner on another \"machine\"", "Optimus (Redis on loopback)");
  return out.str();
}

// The paper's two tests: availability per request period and extra
// clients, and response times with their outliers, per payload.
// prime record and prime play (the record suite), against the MCAP
// project's published figures for its own writer.
std::string recording_table(const Results& r) {
  const auto kib = std::int64_t{64}, mib = std::int64_t{1} << 20;
  if (!r.find("ShmRecorder", "record-flat", kib, "rate") && !r.find("ShmPlay", "play-timing", 0, "p99")) return "No figures.\n";
  std::ostringstream out;
  auto figure = [&](const std::string& who, const std::string& scenario, std::int64_t payload, const std::string& statistic) {
    return r.find(who, scenario, payload, statistic);
  };
  auto count = [](std::optional<double> v) { return v ? number(*v, "%.0f") : std::string{"–"}; };
  out << "| what | figure |\n|---|---|\n";
  for (const auto payload : {kib, mib}) {
    const auto rate = figure("ShmRecorder", "record-flat", payload, "rate");
    const auto bytes = figure("ShmRecorder", "record-flat", payload, "bytes");
    const auto with = figure("Shm", "publish-flat-recorded", payload, "rate");
    const auto alone = figure("Shm", "publish-flat-alone", payload, "rate");
    out << "| recording " << size_text(payload) << " samples, a publisher flat out on another core | "
        << (rate ? rate_text(*rate) : "–") << " ("
        << (!bytes ? std::string{"–"} : *bytes >= 1e9 ? number(*bytes / 1e9) + " GB/s" : number(*bytes / 1e6) + " MB/s")
        << (payload == mib ? ", " + ratio_text(divide(bytes, figure("FileWrite", "record-flat", mib, "bytes"))) +
                                 " of write() into the same folder alone"
                           : std::string{})
        << "); the publisher " << (with ? rate_text(*with) : "–") << ", " << ratio_text(divide(with, alone))
        << " its rate alone";
    // What any reader of every sample costs it: a plain subscriber on the same CPU instead.
    if (const auto read = figure("Shm", "publish-flat-read", payload, "rate"))
      out << " (beside a plain subscriber instead, " << ratio_text(divide(read, alone)) << ")";
    out << " |\n";
  }
  for (const auto& [payload, paced, what] :
       {std::tuple{kib, std::string{"100000-64"}, "64 B at 100 kHz, a ring 64 deep"},
        std::tuple{kib, std::string{"100000-1024"}, "64 B at 100 kHz, a ring 1024 deep"},
        std::tuple{mib, std::string{"1000-64"}, "1 MiB at 1 kHz (1 GB/s), a ring 64 deep"}}) {
    const auto scenario = "record-paced-" + paced;
    const auto with = figure("Shm", "publish-paced-recorded-" + paced, payload, "publish");
    const auto alone = figure("Shm", "publish-paced-alone-" + paced, payload, "publish");
    out << "| recording " << what << " | " << count(figure("ShmRecorder", scenario, payload, "recorded")) << " recorded, "
        << count(figure("ShmRecorder", scenario, payload, "lost")) << " lost, "
        << count(figure("ShmRecorder", scenario, payload, "missing")) << " unaccounted; a publish "
        << (with ? time_text(*with) : "–");
    if (alone) out << " (" << time_text(*alone) << " with no recorder: " << ratio_text(divide(alone, with)) << ")";
    const auto with_p50 = figure("Shm", "publish-paced-recorded-" + paced, payload, "publish-p50");
    const auto alone_p50 = figure("Shm", "publish-paced-alone-" + paced, payload, "publish-p50");
    if (with_p50 && alone_p50)
      out << "; median " << time_text(*with_p50) << " against " << time_text(*alone_p50) << " ("
          << ratio_text(divide(alone_p50, with_p50)) << ")";
    out << " |\n";
  }
  const auto p50 = figure("ShmPlay", "play-timing", 0, "p50"), p99 = figure("ShmPlay", "play-timing", 0, "p99"),
             worst = figure("ShmPlay", "play-timing", 0, "max");
  out << "| prime play at ×1, 1 kHz for 2 s: each sample's arrival against its recorded offset | p50 "
      << (p50 ? time_text(*p50) : "–") << ", p99 " << (p99 ? time_text(*p99) : "–") << ", max "
      << (worst ? time_text(*worst) : "–") << " |\n";
  // The MCAP project's published benchmark of its own writer, chunked and
  // indexed to a ramdisk, on another machine: about 2.2 GB/s at 1 MiB and
  // 0.4 M msgs/s at 100 B.
  const auto big = figure("ShmRecorder", "record-flat", mib, "bytes");
  const auto small = figure("ShmRecorder", "record-flat", kib, "rate");
  out << "\nThe MCAP project publishes about 2.2 GB/s at 1 MiB and 0.4 M msgs/s at 100 B for its own writer, chunked "
         "and indexed into a ramdisk on another machine, with no reader of shared memory in front of it: this "
         "recorder, reading each sample out of a live topic and writing it into tmpfs, came to "
      << ratio_text(divide(big, 2.2e9)) << " the first and " << ratio_text(divide(small, 0.4e6)) << " the second.\n";
  return out.str();
}

std::string availability_tables(const Results& r) {
  std::vector<std::string> availability, response;
  for (const auto& f : r.figures) {
    auto& list = f.scenario.starts_with("availability-") ? availability : response;
    if ((f.scenario.starts_with("availability-") || f.scenario.starts_with("response-")) &&
        std::find(list.begin(), list.end(), f.scenario) == list.end())
      list.push_back(f.scenario);
  }
  if (availability.empty() && response.empty()) return "No figures.\n";
  std::ostringstream out;
  if (!availability.empty()) {
    out << "Availability: requests executed / requests sent, sent asynchronously every period.\n\n"
           "| who | configuration | payload | availability | sent |\n|---|---|---:|---:|---:|\n";
    for (const auto& scenario : availability)
      for (const auto& who : r.who_in(scenario))
        for (const auto chars : r.payloads_in(scenario)) {
          const auto a = r.find(who, scenario, chars, "availability");
          const auto sent = r.find(who, scenario, chars, "sent");
          if (!a) continue;
          out << "| " << who << " | " << scenario.substr(13) << " | " << chars << " chars | " << number(*a * 100, "%.1f")
              << " % | " << (sent ? number(*sent, "%.0f") : "–") << " |\n";
        }
    out << '\n';
  }
  if (!response.empty()) {
    out << "Response time of synchronous calls; outliers (above 10× the median) are counted, not dropped.\n\n"
           "| who | configuration | payload | mean | p50 | p99 | max | outliers |\n|---|---|---:|---:|---:|---:|---:|---:|\n";
    for (const auto& scenario : response)
      for (const auto& who : r.who_in(scenario))
        for (const auto chars : r.payloads_in(scenario)) {
          out << "| " << who << " | " << scenario.substr(9) << " | " << chars << " chars |";
          for (const char* stat : {"mean", "p50", "p99", "max"}) {
            const auto v = r.find(who, scenario, chars, stat);
            out << ' ' << (v ? time_text(*v) : "–") << " |";
          }
          const auto n = r.find(who, scenario, chars, "outliers");
          const auto share = r.find(who, scenario, chars, "outlier share");
          out << ' ' << (n ? number(*n, "%.0f") : "–") << (share ? " (" + number(*share * 100, "%.1f") + " %)" : "") << " |\n";
        }
  }
  return out.str();
}

// A Table 1 row: its scenario (table1-<width>lane) and payload.
struct Table1Row {
  std::string scenario;
  std::int64_t payload;

  // "10 KiB × 2"
  [[nodiscard]] std::string text() const {
    return size_text(payload) + " × " + scenario.substr(std::string{"table1-"}.size(), 1);
  }
};
using RowRatio = std::function<std::optional<double>(const Results&, const Table1Row&)>;

// The Table 1 row of `who` where `ratio` is worst: the largest (`largest`),
// else the least.
std::optional<Table1Row> worst_table1_row(const Results& r, const std::string& who, const RowRatio& ratio, bool largest) {
  std::optional<std::pair<Table1Row, double>> worst;
  for (const auto& f : r.figures)
    if (f.who == who && f.scenario.starts_with("table1-")) {
      const Table1Row row{f.scenario, f.payload};
      if (const auto v = ratio(r, row); v && (!worst || (largest ? *v > worst->second : *v < worst->second)))
        worst = {{row, *v}};
    }
  if (!worst) return std::nullopt;
  return worst->first;
}

// `who`'s time per hop over FOR's.
RowRatio over_for(std::string who) {
  return [who](const Results& r, const Table1Row& row) {
    return divide(r.find(who, row.scenario, row.payload, "per hop"), r.find("For", row.scenario, row.payload, "per hop"));
  };
}
// Sources' throughput over the CCR-like peer's: its time per hop over Sources'.
std::optional<double> sources_over_ccr(const Results& r, const Table1Row& row) {
  return divide(r.find("CcrLike", row.scenario, row.payload, "per hop"), r.find("Sources", row.scenario, row.payload, "per hop"));
}

// The headline: each of Prime's figures and its ratios, every ratio from
// the medians and, where the rounds one by one put it far apart (Range::
// unsteady), with their range beside it.
std::string headline(const Results& r, const std::vector<Results>& rounds) {
  std::ostringstream out;
  out << "| what | Prime | ratios |\n|---|---:|---|\n";
  auto ratio_cell = [&](const Measure& ratio) {
    auto text = ratio_text(ratio(r));
    if (const auto range = range_over(rounds, ratio); range && range->unsteady())
      text += " (" + number(range->low) + "–" + number(range->high) + "× round by round)";
    return text;
  };
  auto row = [&](const std::string& what, const Measure& mine, bool is_rate,
                 const std::vector<std::pair<std::string, Measure>>& against) {
    const auto value = mine(r);
    if (!value) return;
    out << "| " << what << " | " << (is_rate ? rate_text(*value) : time_text(*value)) << " |";
    bool first = true;
    for (const auto& [name, other] : against) {
      if (!other(r)) continue;
      out << (first ? " " : " · ") << ratio_cell([&](const Results& in) { return divide(mine(in), other(in)); }) << ' '
          << name;
      first = false;
    }
    out << " |\n";
  };
  auto ratio_row = [&](const std::string& what, const Measure& ratio) {
    if (ratio(r)) out << "| " << what << " | | " << ratio_cell(ratio) << " |\n";
  };
  auto at = [](std::string who, std::string scenario, std::int64_t payload, std::string statistic) -> Measure {
    return [=](const Results& in) { return in.find(who, scenario, payload, statistic); };
  };
  auto p50 = [&](const std::string& who, const std::string& scenario, std::int64_t payload) {
    return at(who, scenario, payload, "p50");
  };
  auto rate = [&](const std::string& who, const std::string& scenario, std::int64_t payload) {
    return at(who, scenario, payload, "rate");
  };
  // The better of a DDS's two configurations (<dds>Shm, <dds>Loan).
  auto best_of = [](std::string dds, std::string scenario, std::int64_t payload, bool is_rate) -> Measure {
    return [=](const Results& in) {
      std::optional<double> best;
      for (const auto* config : {"Shm", "Loan"}) {
        const auto v = in.find(dds + config, scenario, payload, is_rate ? "rate" : "p50");
        if (v && (!best || (is_rate ? *v > *best : *v < *best))) best = v;
      }
      return best;
    };
  };
  // The throughput floors: the machine's (the faster depth in the medians,
  // and that same ring in every round), and a ring as deep as the topics,
  // when that is not the same one.
  const auto fastest = fastest_spsc_floor(r);
  const std::pair<std::string, Measure> spsc{
      "SPSC ring floor (" + std::string{fastest == "SpscFloor" ? "4096" : "256"} + " deep)", rate(fastest, "throughput", 64)};
  const std::pair<std::string, Measure> spsc_as_deep{
      "SPSC ring as deep as the topic (256)",
      fastest == "SpscFloor256" ? Measure{[](const Results&) { return std::optional<double>{}; }}
                                : rate("SpscFloor256", "throughput", 64)};
  for (const std::int64_t payload : {std::int64_t{64}, std::int64_t{1} << 20})
    row("Shm one-way latency, " + size_text(payload) + ", p50", p50("Shm", "latency", payload), false,
        {{"cache-line floor", p50("Floor", "latency", payload)},
         {"iceoryx", p50("Iceoryx", "latency", payload)},
         {"Fast DDS (best of SHM, loans)", best_of("FastDds", "latency", payload, false)},
         {"Cyclone DDS (best of SHM, loans)", best_of("CycloneDds", "latency", payload, false)}});
  row("Shm one-way latency, sleeping reader, 64 B, p50", p50("Shm", "latency-sleeping", 64), false,
      {{"futex wake floor", p50("FutexWake", "latency-sleeping", 64)},
       {"iceoryx (WaitSet)", p50("IceoryxWaitSet", "latency-sleeping", 64)}});
  row("Shm lossless throughput, 64 B (sensor's stamp)", rate("Shm", "throughput", 64), true,
      {spsc, spsc_as_deep, {"iceoryx", rate("Iceoryx", "throughput", 64)},
       {"Fast DDS", best_of("FastDds", "throughput", 64, true)}});
  row("Shm lossless throughput, publisher's PublishFence::light, 64 B", rate("ShmLight", "throughput", 64), true,
      {spsc, {"Shm with full fences", rate("Shm", "throughput", 64)}});
  row("Shm lossless throughput, publisher reading the clock for each stamp (publish()'s default), 64 B",
      rate("ShmClock", "throughput", 64), true, {{"with the sensor's stamp", rate("Shm", "throughput", 64)}});
  row("Shm lossless throughput in batches (loan_some / read_some), 64 B", rate("ShmBatch", "throughput", 64), true,
      {spsc, spsc_as_deep, {"Shm one at a time", rate("Shm", "throughput", 64)}});
  row("Shm lossless throughput in batches read as Views (loan_some / BatchReader), 64 B",
      rate("ShmViews", "throughput", 64), true,
      {spsc, spsc_as_deep, {"read_some", rate("ShmBatch", "throughput", 64)},
       {"an SPSC ring of Shm's layout", rate("SpscShmLayout", "throughput", 64)}});
  // What a ring moves once each 64-byte payload carries a header, as a
  // medium's must: the floor for each way of laying it out.
  for (const auto& [who, what] : {std::pair{"SpscInline", "the header inline (128-byte slots)"},
                                  std::pair{"SpscRecords", "the header in 32-byte records beside the payload slots"},
                                  std::pair{"SpscRecordsHeaders", "those records and a chunk header written per message"},
                                  std::pair{"SpscShmLayout", "Shm's layout (ring entry, info, chunk)"}})
    row(std::string{"SPSC ring, 256 deep, read in batches, 64 B with "} + what + ", nothing else done",
        rate(who, "throughput", 64), true, {spsc});
  row("Shm publisher alone, in batches (one process, nobody reading: its own bookkeeping), 64 B",
      rate("ShmBatch", "publisher-alone", 64), true,
      {spsc, {"Views across processes", rate("ShmViews", "throughput", 64)}});
  row("Shm publisher alone, one at a time, 64 B", rate("Shm", "publisher-alone", 64), true,
      {spsc, {"Shm across processes", rate("Shm", "throughput", 64)}});
  row("Shm whole path alone, one at a time (loan, publish, take, release in one thread), 64 B",
      rate("Shm", "path-alone", 64), true,
      {{"publisher alone", rate("Shm", "publisher-alone", 64)}, {"Shm across processes", rate("Shm", "throughput", 64)}});
  row("Shm publish to 4 reader processes, 64 B (publisher's time per message)", at("Shm", "fanout-publish-4", 64, "publish"),
      false, {{"1 reader", at("Shm", "fanout-publish-1", 64, "publish")}, {"cache-line floor", p50("Floor", "latency", 64)}});
  row("Shm service round trip, 64 B, p50", p50("ShmService", "round-trip", 64), false,
      {{"iceoryx request/response", p50("Iceoryx", "round-trip", 64)}, {"Unix socket", p50("UnixSocket", "round-trip", 64)}});
  for (const auto& [load, text] : {std::pair{"idle", "idle"}, std::pair{"load", "under load"}})
    row(std::string{"1 kHz loop (prime::every) wake-up lateness, p99, "} + text,
        at("Shm", std::string{"loop-lateness-"} + load, 0, "p99"), false,
        {{"cyclictest (goal: at most 1.2×)", at("Cyclictest", std::string{"loop-lateness-"} + load, 0, "p99")},
         {"a hand-written clock_nanosleep loop", at("Iceoryx", std::string{"loop-lateness-"} + load, 0, "p99")}});
  row("1 kHz loop, Shm end to end (publish to the subscriber holding it), p99.9, under load",
      at("Shm", "loop-e2e-load", 0, "p99.9"), false, {{"iceoryx", at("Iceoryx", "loop-e2e-load", 0, "p99.9")}});
  // Each Table 1 comparison at its worst row in the medians, and that row's range.
  auto table1_row = [&](const std::string& what, const std::string& who, const RowRatio& ratio, bool largest) {
    if (const auto row = worst_table1_row(r, who, ratio, largest))
      ratio_row(what + " (worst Table 1 row: " + row->text() + ")",
                [&, row = *row](const Results& in) { return ratio(in, row); });
  };
  table1_row("Radiant vs FOR", "Radiant", over_for("Radiant"), true);
  table1_row("Liberty vs FOR", "Liberty", over_for("Liberty"), true);
  table1_row("Sources throughput vs CCR-like", "Sources", sources_over_ccr, false);
  row("Optimus hop", at("Optimus", "hop", 0, "mean"), false,
      {{"hiredis request/reply", at("hiredis", "request-reply", 0, "mean")}, {"PING", at("hiredis", "ping", 0, "mean")}});
  row("Optimus streaming, batches of 64 (StreamingPublisher: one in flight while the next is sent)",
      rate("Optimus", "publish-streamed", 64), true,
      {{"redis-benchmark XADD -P 64", rate("redis-benchmark", "xadd-pipelined", 64)},
       {"Optimus publish_all", rate("Optimus", "publish-pipelined", 64)}});
  row("Optimus publishing, batches of 64 (publish_all)", rate("Optimus", "publish-pipelined", 64), true,
      {{"redis-benchmark XADD -P 64", rate("redis-benchmark", "xadd-pipelined", 64)},
       {"redis-benchmark XADD -P 64 -c 1 (one batch in flight)",
        rate("redis-benchmark", "xadd-pipelined-one-client", 64)}});
  return out.str();
}

}  // namespace

std::string time_text(double ns) {
  if (ns >= 1e6) return number(ns / 1e6) + " ms";
  if (ns >= 1e3) return number(ns / 1e3) + " µs";
  return number(ns, "%.0f") + " ns";
}

std::string rate_text(double per_second) {
  if (per_second >= 1e6) return number(per_second / 1e6) + " M/s";
  if (per_second >= 1e3) return number(per_second / 1e3) + " k/s";
  return number(per_second) + " /s";
}

std::string size_text(std::int64_t bytes) {
  if (bytes >= (1 << 20) && bytes % (1 << 20) == 0) return std::to_string(bytes >> 20) + " MiB";
  if (bytes >= 1024 && bytes % 1024 == 0) return std::to_string(bytes >> 10) + " KiB";
  return std::to_string(bytes) + " B";
}

Written write_report(const std::filesystem::path& dir, const Results& results, const std::vector<Results>& rounds,
                     const Machine& machine, const RunInfo& info) {
  std::filesystem::create_directories(dir);
  {
    std::ofstream csv{dir / "figures.csv"};
    csv << "who,scenario,payload,statistic,value,unit\n";
    for (const auto& f : results.figures)
      csv << f.who << ',' << f.scenario << ',' << f.payload << ',' << f.statistic << ',' << number(f.value, "%.6g") << ','
          << f.unit << '\n';
  }
  if (rounds.size() > 1) {
    std::ofstream csv{dir / "rounds.csv"};
    csv << "round,who,scenario,payload,statistic,value,unit\n";
    for (std::size_t i = 0; i < rounds.size(); ++i)
      for (const auto& f : rounds[i].figures)
        csv << i + 1 << ',' << f.who << ',' << f.scenario << ',' << f.payload << ',' << f.statistic << ','
            << number(f.value, "%.6g") << ',' << f.unit << '\n';
  }
  Written written;
  written.plots = write_plots(dir, results, written.plot_problem);
  written.headline = headline(results, rounds);

  std::ofstream md{dir / "summary.md"};
  const auto minutes = info.took.count() / 60, seconds = info.took.count() % 60;
  md << "# Prime: what each hop costs\n\n"
     << "Measured " << machine.date << " on " << machine.cpu << " (" << machine.cpus << " CPUs, " << machine.memory
     << "), " << machine.kernel << ". " << (info.quick ? "Quick run" : "Full run") << ": " << info.benchmarks
     << " benchmarks in " << minutes << " min " << seconds << " s" << (info.interrupted ? ", INTERRUPTED (partial)" : "")
     << ". Reproduce with `" << (info.suites.empty() ? "" : "PRIME_BENCH_SUITES=" + info.suites + " ") << "prime bench"
     << (info.quick ? " --quick" : "") << "`.\n\n"
     << (info.quick ? "Each figure is from one short run (noisy: use the full run for numbers to quote). "
                    : "Each figure is the median of 3 runs, taken in three rounds over every benchmark, so that a "
                      "figure and the floor or peer it is compared with were measured across the same stretch of the "
                      "machine's load (the availability tests, of fixed length, run once, in the first round). ")
     << "Latency is one way (half a round trip); its percentiles come from every round trip's own timing. "
        "Every ratio compares figures of this one run: the machine is shared and noisy, so compare ratios, not "
        "absolute times, between runs. "
     << (info.quick ? ""
                    : "Where the three rounds, each taken alone, put a headline ratio far apart (the highest over "
                      "1.25× the lowest), the machine changed state during the run; the ratio then holds for one "
                      "state only, and its range round by round stands beside it (each round's figures are in "
                      "rounds.csv). ")
     << "Cells: p50 / p99.\n\n"
     << "## Headline\n\n" << written.headline << '\n';
  auto image = [&](const std::string& name, const std::string& alt) {
    if (std::find(written.plots.begin(), written.plots.end(), name) != written.plots.end())
      md << "![" << alt << "](plots/" << name << ".svg)\n\n";
  };
  md << "## One-way latency, busy readers\n\n";
  image("latency", "one-way latency against payload");
  md << scenario_table(results, "latency", "Floor", false) << '\n';
  image("latency-distribution-64", "latency percentiles at 64 B");
  image("latency-distribution-1MiB", "latency percentiles at 1 MiB");
  md << distribution_table(results, "latency") << '\n';
  md << "## One-way latency, sleeping readers\n\nThe floor is one futex wake between the two processes.\n\n"
     << scenario_table(results, "latency-sleeping", "FutexWake", false) << '\n'
     << distribution_table(results, "latency-sleeping") << '\n';
  md << "## Throughput, lossless\n\n";
  image("throughput", "throughput against payload");
  md << "The floor is a plain single-producer/single-consumer ring of 64-byte slots in shared memory between the same "
        "two processes, each slot carrying its message's sequence (the consumer polls the slot it reads next) and the "
        "consumer handing slots back 32 at a time.\n\n"
     << scenario_table(results, "throughput", fastest_spsc_floor(results), true) << '\n'
     << "SpscFloor is 4096 slots deep; SpscFloor256 is the same ring 256 slots deep, as deep as Shm's topics and the "
        "iceoryx, Fast DDS and POSIX queue peers' queues in these benchmarks. Which depth moves more differs by CPU "
        "(4096 on some, 256 on others), so the floor, the most this machine moves, is the faster of the two in this "
        "run: " << fastest_spsc_floor(results) << " here, the one the ratios above are to.\n\n"
     << "The floor's message is 64 bytes with its sequence inside: one cache line. A medium's 64-byte payload "
        "travels with a header (sequence, size, stamp), so the same ring, 256 deep, also runs with the header laid "
        "out four ways, read in batches as Shm's batch readers read (the entries of up to 32 messages out, then "
        "each message), nothing else done: SpscInline, 128-byte slots with the header on the line before the "
        "payload; SpscRecords, 32-byte records (sequence, size, stamp) in an array beside the payload slots; "
        "SpscRecordsHeaders, the same and a 32-byte header (holders, sequence, size, stamp) written for each "
        "message on a line of its own, as Shm's publisher wrote one in each chunk until layout 12; SpscShmLayout, "
        "Shm's own segment layout (ring entries naming chunks, sizes and stamps beside them, chunks of a header "
        "block and a payload block, taken in turn), written as a publish writes it: payload, size and stamp, "
        "ring entry.\n\n"
     << "The headline's \"publisher alone\" rows run Shm's publishing side by itself, in one process, on the same "
        "topic with nobody reading: no cache line crosses cores, so their rate is the publisher's own bookkeeping, "
        "the most it could send to another process.\n\n";
  md << "## Service round trip\n\n";
  image("service", "service round trip against payload");
  md << scenario_table(results, "round-trip", "", false) << '\n' << distribution_table(results, "round-trip") << '\n';
  md << "## Fan-out, competing load, sleeping subscribers\n\n";
  image("fan-out", "fan-out");
  image("sleeping", "sleeping subscribers");
  md << scenarios_table(results) << '\n';
  md << "### Fan-out throughput\n\n" << fan_out_throughput_table(results) << '\n';
  md << "## 1 kHz loop: wake-up lateness and end to end\n\n"
     << "A 1 kHz `prime::every` loop on a Shm core publishes a small stamped sample each tick to a subscriber in "
        "another process, both at one SCHED_FIFO priority (80, or PRIME_LOOP_PRIORITY; the table of runs says what "
        "each got), the loop on the first CPU and the subscriber on the second; the same loop written by hand for "
        "iceoryx (a thread sleeping in `clock_nanosleep(TIMER_ABSTIME)`, a subscriber asleep in a WaitSet); and "
        "cyclictest, the floor, at the same period and priority on the loop's CPU. The three take turns in slices "
        "of 1000 ticks (1 s), round after round, and each one's figures pool its slices: all three are measured "
        "across the same stretch of the machine's state. Once idle (no load of the run's own: the last table says "
        "how busy others kept the machine) and once under load (stress-ng, one CPU hog per CPU, for the run only). "
        "Lateness: from a tick's time to the loop's code running, as cyclictest measures it. End to end: from the "
        "stamp, the clock read once the sample is written into its loan, just before it is published, to the "
        "subscriber holding it. Every run locks its memory and holds /dev/cpu_dma_latency at 0, as cyclictest "
        "does; the first 100 ticks of each slice are not counted; a tick a late one let pass is skipped, not run.\n\n";
  image("loop-lateness", "1 kHz loop lateness percentiles");
  image("loop-e2e", "1 kHz loop end-to-end percentiles");
  md << loop_tables(results) << '\n';
  md << "## Table 1: chains in one process\n\n";
  image("table1", "Table 1");
  md << table1_table(results) << '\n';
  md << "## Optimus (Redis)\n\n";
  image("optimus", "Optimus against hiredis");
  md << optimus_table(results) << '\n';
  md << "## Services under load (after the communication-architecture paper)\n\n" << availability_tables(results) << '\n';
  md << "## Recording and replay\n\n"
     << "`prime record` (its own process: a reading thread, a writing thread below it) on the CPUs the publisher "
        "does not use, the publisher pinned to the first, into an uncompressed file on tmpfs (/dev/shm). Flat out, "
        "the publisher publishes as fast as it can and the recorder takes what it can read; paced, it publishes "
        "each sample at its time, and every sample from the first the recorder read on is recorded, counted lost "
        "(overwritten in the ring before it was read) or unaccounted (none, or the accounting is wrong). `prime "
        "play` plays a recording of 2 s at 1 kHz into a topic read by a busy reader. The floor for 1 MiB samples is "
        "write() of 1 MiB blocks into the same folder from the recorder's CPUs, nothing else done (what `dd bs=1M` "
        "does).\n\n"
     << recording_table(results) << '\n';
  md << "## Components: sensor to command, per placement\n\n"
     << "A sensor publishes a stamped reading; a planner makes a command of each as it arrives and calls the driver's "
        "service; the time is the driver's clock less the reading's stamp, one reading in flight. The benchmark's "
        "process hosts the sensor and the driver; the planner is where the placement puts it. The hand-wired row is "
        "the same pipeline written with `shm::Core` directly (the robot demo before components), in the same run.\n\n"
     << components_table(results) << '\n';
  if (!results.notes.empty()) {
    md << "## Notes\n\n";
    for (const auto& note : results.notes) md << "- " << note << '\n';
    md << '\n';
  }
  md << "## Skipped\n\n";
  if (results.skipped.empty() && written.plot_problem.empty()) md << "Nothing.\n";
  for (const auto& s : results.skipped)
    md << "- " << s.suite << (s.benchmark.empty() ? "" : " " + s.benchmark) << ": " << s.reason << '\n';
  if (!written.plot_problem.empty()) md << "- plots: " << written.plot_problem << '\n';
  return written;
}

}  // namespace prime::tool::bench
