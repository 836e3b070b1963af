#include "suites.hpp"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstdlib>
#include <map>

namespace prime::tool::bench {

namespace {

// "BM_Latency_Shm/64/real_time" -> {"BM_Latency_Shm", "64", "real_time"}
std::vector<std::string> name_parts(const Json& run) {
  const auto& object = run.object();
  const auto it = object.find("run_name");
  const std::string name = it != object.end() && std::holds_alternative<std::string>(it->second.value)
                               ? std::get<std::string>(it->second.value)
                               : "";
  std::vector<std::string> parts;
  std::size_t from = 0;
  while (true) {
    const auto slash = name.find('/', from);
    parts.push_back(name.substr(from, slash - from));
    if (slash == std::string::npos) break;
    from = slash + 1;
  }
  if (!parts.empty() && parts[0].starts_with("BM_")) parts[0].erase(0, 3);
  return parts;
}

std::int64_t integer(const std::string& text) {
  if (text.empty() || !std::isdigit(static_cast<unsigned char>(text[0]))) return 0;
  return std::strtoll(text.c_str(), nullptr, 10);
}

// The run's time per iteration, in nanoseconds.
std::optional<double> real_time_ns(const Json& run) {
  const double* t = number(run, "real_time");
  if (!t) return std::nullopt;
  const auto& object = run.object();
  const auto unit = object.find("time_unit");
  const std::string u = unit != object.end() && std::holds_alternative<std::string>(unit->second.value)
                            ? std::get<std::string>(unit->second.value)
                            : "ns";
  const double scale = u == "us" ? 1e3 : u == "ms" ? 1e6 : u == "s" ? 1e9 : 1.0;
  return *t * scale;
}

// Counters named <statistic>_ns (one_way_ns and last_ns are means), and
// rates, as the harness of prime_ipc reports them; `scale` multiplies times
// (2 turns a one-way time into a round trip).
void add_counters(const Json& run, const std::string& who, const std::string& scenario, std::int64_t payload,
                  double scale, Results& out) {
  static const std::map<std::string, std::string> kTimes{
      {"one_way_ns", "mean"}, {"last_ns", "mean"}, {"p50_ns", "p50"},       {"p90_ns", "p90"},
      {"p99_ns", "p99"},      {"p999_ns", "p99.9"}, {"max_ns", "max"},      {"publish_ns", "publish"},
  };
  for (const auto& [key, statistic] : kTimes)
    if (const double* v = number(run, key)) out.figures.push_back({who, scenario, payload, statistic, *v * scale, "ns"});
  if (const double* v = number(run, "cpu_ns_per_msg"))
    out.figures.push_back({who, scenario, payload, "cpu per message", *v, "ns"});
  if (const double* v = number(run, "msgs/s")) out.figures.push_back({who, scenario, payload, "rate", *v, "msgs/s"});
  if (const double* v = number(run, "calls/s")) out.figures.push_back({who, scenario, payload, "rate", *v, "calls/s"});
}

// prime_ipc: BM_<Kind>_<Who>/<argument>.
void read_ipc(const Json& run, Results& out) {
  const auto parts = name_parts(run);
  const auto underscore = parts[0].find('_');
  if (underscore == std::string::npos || parts.size() < 2) return;
  const std::string kind = parts[0].substr(0, underscore);
  std::string who = parts[0].substr(underscore + 1);
  const auto argument = integer(parts[1]);
  std::string suffix;
  if (who.ends_with("Sleeping")) {  // ShmSleeping, ShmServiceSleeping: the same medium, its reader asleep
    who.erase(who.size() - 8);
    suffix = "-sleeping";
  }
  if (who == "FutexWake" || who == "IceoryxWaitSet") suffix = "-sleeping";  // their readers sleep too
  if (kind == "Latency") add_counters(run, who, "latency" + suffix, argument, 1, out);
  else if (kind == "Loaded") add_counters(run, who, "latency-loaded", argument, 1, out);
  else if (kind == "Throughput") add_counters(run, who, "throughput", argument, 1, out);
  else if (kind == "RoundTrip") add_counters(run, who, "round-trip" + suffix, argument, 2, out);
  else if (kind == "Calls") add_counters(run, who, "calls-" + parts[1] + "-clients", 64, 1, out);
  else if (kind == "FanOut") add_counters(run, who, "fan-out-" + parts[1], 64, 1, out);
  else if (kind == "FanOutThroughput") add_counters(run, who, "fanout-throughput-" + parts[1], 64, 1, out);
  else if (kind == "FanOutPublish") add_counters(run, who, "fanout-publish-" + parts[1], 64, 1, out);
  else if (kind == "Sleeping") add_counters(run, who, "sleeping-" + parts[1] + "hz", 64, 1, out);
  else if (kind == "PublisherAlone") add_counters(run, who, "publisher-alone", argument, 1, out);
  else if (kind == "PathAlone") add_counters(run, who, "path-alone", argument, 1, out);
}

// prime_table1: BM_<Who>/<payload>/<lanes>, ns_per_hop.
void read_table1(const Json& run, Results& out) {
  const auto parts = name_parts(run);
  if (parts.size() < 3) return;
  if (const double* v = number(run, "ns_per_hop"))
    out.figures.push_back({parts[0], "table1-" + parts[2] + "lane", integer(parts[1]), "per hop", *v, "ns"});
}

// prime_optimus_bench: BM_<Optimus|Hiredis|RedisBenchmark>_<What>[/<batch>].
void read_optimus(const Json& run, Results& out) {
  const auto parts = name_parts(run);
  const auto underscore = parts[0].find('_');
  if (underscore == std::string::npos) return;
  std::string who = parts[0].substr(0, underscore);
  if (who == "Hiredis") who = "hiredis";
  if (who == "RedisBenchmark") who = "redis-benchmark";
  std::string scenario;
  for (const char c : parts[0].substr(underscore + 1)) {  // RequestReply -> request-reply
    if (std::isupper(static_cast<unsigned char>(c)) && !scenario.empty()) scenario += '-';
    scenario += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  }
  const auto payload = parts.size() > 1 ? integer(parts[1]) : 0;
  const double* rate = number(run, "items_per_second");
  // redis-benchmark's iterations are whole runs of it: its time per request is its rate's inverse.
  if (who == "redis-benchmark" && rate && *rate > 0)
    out.figures.push_back({who, scenario, payload, "mean", 1e9 / *rate, "ns"});
  else if (const auto t = real_time_ns(run))
    out.figures.push_back({who, scenario, payload, "mean", *t, "ns"});
  if (rate) out.figures.push_back({who, scenario, payload, "rate", *rate, "msgs/s"});
}

// prime_availability: BM_Availability_<Medium>/<period ms>/<chars>/<extra clients>
// and BM_Response_<Medium>/<chars>/<extra clients>.
void read_availability(const Json& run, Results& out) {
  const auto parts = name_parts(run);
  const auto underscore = parts[0].find('_');
  if (underscore == std::string::npos) return;
  const std::string kind = parts[0].substr(0, underscore);
  std::string who = parts[0].substr(underscore + 1);
  if (who == "Shm") who = "ShmService";
  if (kind == "Availability" && parts.size() >= 4) {
    const std::string scenario = "availability-" + parts[1] + "ms-" + parts[3] + "clients";
    if (const double* v = number(run, "availability"))
      out.figures.push_back({who, scenario, integer(parts[2]), "availability", *v, "fraction"});
    if (const double* v = number(run, "sent")) out.figures.push_back({who, scenario, integer(parts[2]), "sent", *v, "requests"});
  } else if (kind == "Response" && parts.size() >= 3) {
    const std::string scenario = "response-" + parts[2] + "clients";
    static const std::map<std::string, std::string> kTimes{
        {"mean_ns", "mean"}, {"p50_ns", "p50"}, {"p99_ns", "p99"}, {"max_ns", "max"}};
    for (const auto& [key, statistic] : kTimes)
      if (const double* v = number(run, key)) out.figures.push_back({who, scenario, integer(parts[1]), statistic, *v, "ns"});
    if (const double* v = number(run, "outliers"))
      out.figures.push_back({who, scenario, integer(parts[1]), "outliers", *v, "samples"});
    if (const double* v = number(run, "outlier_share"))
      out.figures.push_back({who, scenario, integer(parts[1]), "outlier share", *v, "fraction"});
  }
}

// prime_ipc's loop suite: BM_Loop/load:<0|1>, whose counters are, for
// <who> of shm, iceoryx and cyclictest, <who>_lateness_<p50|p99|p999|max>_ns,
// <who>_e2e_..._ns (not cyclictest), <who>_ticks, _lost, _busy and
// _priority (0: the machine refused a real-time one); its label says how
// each ran, "<Who>: ..." joined by " | ". One that did not run is listed as
// skipped, one that ran at normal priority in the notes, each with why.
void read_loop(const Json& run, Results& out) {
  const auto parts = name_parts(run);
  if (parts.size() < 2 || parts[0] != "Loop") return;
  const std::string load = parts[1] == "load:1" ? "load" : "idle";
  static const std::pair<const char*, const char*> kWho[] = {
      {"shm", "Shm"}, {"iceoryx", "Iceoryx"}, {"cyclictest", "Cyclictest"}};
  static const std::pair<const char*, const char*> kStatistics[] = {
      {"p50", "p50"}, {"p99", "p99"}, {"p999", "p99.9"}, {"max", "max"}};
  static const std::pair<const char*, const char*> kRun[] = {
      {"ticks", "ticks"}, {"lost", "samples"}, {"busy", "fraction"}, {"priority", "SCHED_FIFO"}};
  for (const auto& [prefix, who] : kWho) {
    for (const std::string kind : {"lateness", "e2e"})
      for (const auto& [key, statistic] : kStatistics)
        if (const double* v = number(run, std::string{prefix} + "_" + kind + "_" + key + "_ns"))
          out.figures.push_back({who, "loop-" + kind + "-" + load, 0, statistic, *v, "ns"});
    for (const auto& [statistic, unit] : kRun)
      if (const double* v = number(run, std::string{prefix} + "_" + statistic))
        out.figures.push_back({who, "loop-" + load, 0, statistic, *v, unit});
  }
  const auto& object = run.object();
  const auto label = object.find("label");
  if (label == object.end() || !std::holds_alternative<std::string>(label->second.value)) return;
  const std::string& text = std::get<std::string>(label->second.value);
  for (std::size_t from = 0; from < text.size();) {
    const auto bar = std::min(text.find(" | ", from), text.size());
    const std::string part = text.substr(from, bar - from);
    from = bar + 3;
    const auto colon = part.find(": ");
    if (colon == std::string::npos) continue;
    const std::string who = part.substr(0, colon), how = part.substr(colon + 2);
    if (how.starts_with("not run: ")) {
      out.skipped.push_back({"loop", "BM_Loop/" + parts[1] + " " + who, how.substr(9)});
      continue;
    }
    std::string prefix = who;
    std::transform(prefix.begin(), prefix.end(), prefix.begin(), [](unsigned char c) { return std::tolower(c); });
    if (const double* priority = number(run, prefix + "_priority"); priority && *priority == 0)
      out.notes.push_back(who + ", " + (load == "load" ? "under load" : "idle") + ": ran at " + how);
  }
}

// prime_record_bench: BM_WriteFloor, BM_RecordFlat/<bytes>, BM_PublisherAlone/<bytes>, BM_PublisherBesideReader/<bytes>,
// BM_RecordPaced/<bytes>/<hz>/<capacity>, BM_PublishPacedAlone/<bytes>/<hz>/<capacity>,
// BM_PlayTiming (record_bench.cpp says what each counts).
void read_record(const Json& run, Results& out) {
  const auto parts = name_parts(run);
  const auto& kind = parts[0];
  const auto payload = parts.size() > 1 ? integer(parts[1]) : 0;
  auto add = [&](const std::string& who, const std::string& scenario, const char* counter, const std::string& statistic,
                 const std::string& unit) {
    if (const double* v = number(run, counter)) out.figures.push_back({who, scenario, payload, statistic, *v, unit});
  };
  const auto paced = parts.size() > 3 ? parts[2] + "-" + parts[3] : std::string{};
  if (kind == "WriteFloor") {
    if (const double* v = number(run, "written_bytes_per_s")) out.figures.push_back({"FileWrite", "record-flat", 1 << 20, "bytes", *v, "B/s"});
  } else if (kind == "RecordFlat") {
    add("ShmRecorder", "record-flat", "recorded_per_s", "rate", "msgs/s");
    add("ShmRecorder", "record-flat", "recorded_bytes_per_s", "bytes", "B/s");
    add("ShmRecorder", "record-flat", "lost", "lost", "msgs");
    add("Shm", "publish-flat-recorded", "published_per_s", "rate", "msgs/s");
  } else if (kind == "PublisherAlone") {
    add("Shm", "publish-flat-alone", "published_per_s", "rate", "msgs/s");
  } else if (kind == "PublisherBesideReader") {
    add("Shm", "publish-flat-read", "published_per_s", "rate", "msgs/s");
  } else if (kind == "RecordPaced") {
    add("ShmRecorder", "record-paced-" + paced, "recorded", "recorded", "msgs");
    add("ShmRecorder", "record-paced-" + paced, "lost", "lost", "msgs");
    add("ShmRecorder", "record-paced-" + paced, "missing", "missing", "msgs");
    add("Shm", "publish-paced-recorded-" + paced, "publish_ns", "publish", "ns");
    add("Shm", "publish-paced-recorded-" + paced, "publish_p50_ns", "publish-p50", "ns");
  } else if (kind == "PublishPacedAlone") {
    add("Shm", "publish-paced-alone-" + paced, "publish_ns", "publish", "ns");
    add("Shm", "publish-paced-alone-" + paced, "publish_p50_ns", "publish-p50", "ns");
  } else if (kind == "PlayTiming") {
    add("ShmPlay", "play-timing", "timing_error_p50_ns", "p50", "ns");
    add("ShmPlay", "play-timing", "timing_error_p99_ns", "p99", "ns");
    add("ShmPlay", "play-timing", "timing_error_max_ns", "max", "ns");
  }
}

}  // namespace

const double* number(const Json& object, const std::string& key) {
  if (!object.is_object()) return nullptr;
  const auto it = object.object().find(key);
  if (it == object.object().end() || !std::holds_alternative<double>(it->second.value)) return nullptr;
  return &std::get<double>(it->second.value);
}

// prime_system_bench: BM_SensorToCommand_<HandWired|One|Split|Machines>:
// ShmHandWired, or Components in scenario sensor-to-command-<placement>.
void read_system(const Json& run, Results& out) {
  const auto parts = name_parts(run);
  const std::string prefix = "SensorToCommand_";
  if (parts.empty() || !parts[0].starts_with(prefix)) return;
  std::string placement = parts[0].substr(prefix.size());
  const bool hand = placement == "HandWired";
  const std::string who = hand ? "ShmHandWired" : "Components";
  std::transform(placement.begin(), placement.end(), placement.begin(), [](unsigned char c) { return std::tolower(c); });
  const std::string scenario = "sensor-to-command-" + (hand ? std::string{"split"} : placement);
  if (const double* v = number(run, "p50_ns")) out.figures.push_back({who, scenario, 0, "p50", *v, "ns"});
  if (const double* v = number(run, "p99_ns")) out.figures.push_back({who, scenario, 0, "p99", *v, "ns"});
}

std::vector<Suite> suites() {
  return {
      {.name = "ipc",
       .title = "two processes: Shm, its services and their peers",
       .binary = "ipc/prime_ipc",
       .quick_filter = "^BM_(Latency|Throughput|RoundTrip|PublisherAlone|PathAlone)_[A-Za-z]+[0-9]*/(64|1048576)/"
                       "|^BM_Calls_ShmService/1/|^BM_FanOut(Throughput|Publish)?_Shm/[14]/|^BM_Loaded_|^BM_Sleeping_Shm/1000/",
       .full_filter = "-^BM_Loop/",  // the loop suite's, below
       .quick_min_time = 0.05,
       .full_min_time = 0.2,
       .full_repetitions = 3,
       .expected = {{"_FastDds", "prime_ipc was built without Fast DDS (install libfastrtps-dev and rebuild)"},
                    {"_CycloneDds", "prime_ipc was built without Cyclone DDS (install cyclonedds-dev and rebuild)"},
                    {"_Iceoryx", "prime_ipc was built without iceoryx"}},
       .not_measured = {{"BM_Throughput_CycloneDds*",
                         "not measured: Cyclone DDS 0.10's shared-memory path cannot stream losslessly (it takes "
                         "KEEP_LAST endpoints only, and its writer never waits for a reader whose iceoryx queue or "
                         "history is full: they drop their oldest samples)"}},
       .read = read_ipc},
      {.name = "table1",
       .title = "one process: the paper's Table 1 (FOR, Radiant, Liberty, Sources, a CCR-like peer)",
       .binary = "prime_table1",
       .quick_filter = "/(100|10240)/",
       .quick_min_time = 0.02,
       .full_min_time = 0.2,
       .full_repetitions = 3,
       .read = read_table1},
      {.name = "optimus",
       .title = "Redis: Optimus against bare hiredis",
       .binary = "optimus/prime_optimus_bench",
       .quick_filter = ".",
       .quick_min_time = 0.05,
       .full_min_time = 0.5,
       .full_repetitions = 3,
       .needs = {"redis-server"},
       .read = read_optimus},
      {.name = "availability",
       .title = "services after the paper: availability under load, response times with their outliers",
       .binary = "availability/prime_availability",
       .quick_filter = "^BM_Availability_[A-Za-z]+/10/(10|20000)/|^BM_Response_[A-Za-z]+/(10|20000)/",
       .quick_min_time = 0.01,  // each runs once, for a fixed number of requests
       .full_min_time = 0.01,
       .full_repetitions = 1,
       .quick_env = {{"PRIME_AVAILABILITY_REQUESTS", "40"}},
       .read = read_availability},
      // Two benchmarks (idle, under load), each running the three loops in
      // turn for 10 s of ticks apiece (0.5 s quick), once: the load keeps
      // stress-ng on every CPU for that long, and the machine may be shared.
      {.name = "loop",
       .title = "a 1 kHz loop publishing to another process, idle and under stress-ng, beside cyclictest",
       .binary = "ipc/prime_ipc",
       .quick_filter = "^BM_Loop/",
       .full_filter = "^BM_Loop/",
       .quick_min_time = 0.01,  // each runs once, for a fixed number of ticks
       .full_min_time = 0.01,
       .full_repetitions = 1,
       .needs = {"cyclictest", "stress-ng"},
       .quick_env = {{"PRIME_LOOP_SECONDS", "0.5"}},
       .read = read_loop},
      // Each runs once, for a fixed time (2 s, 0.3 s quick; the play, 2 s).
      {.name = "record",
       .title = "prime record beside a publisher flat out and paced, and prime play's timing",
       .binary = "record/prime_record_bench",
       .quick_filter = ".",
       .quick_min_time = 0.01,
       .full_min_time = 0.01,
       .full_repetitions = 3,
       .quick_env = {{"PRIME_RECORD_SECONDS", "0.3"}},
       .read = read_record},
      // Latency_ShmToPython and Throughput_ShmToPython: rows beside ipc's
      // Latency_Shm and Throughput_Shm (C++ to C++) of the same run.
      {.name = "python",
       .title = "C++ to Python: Shm samples read in place through numpy",
       .binary = "python/prime_python_bench",
       .quick_filter = ".",
       .quick_min_time = 0.05,
       .full_min_time = 0.3,
       .full_repetitions = 3,
       .read = read_ipc},
      {.name = "system",
       .title = "components: sensor to command in each placement, against the pipeline wired by hand",
       .binary = "system/prime_system_bench",
       .quick_filter = "HandWired|Split|One",
       .quick_min_time = 0.05,
       .full_min_time = 0.5,
       .full_repetitions = 3,
       .read = read_system},
  };
}

}  // namespace prime::tool::bench
