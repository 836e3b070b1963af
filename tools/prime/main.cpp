// prime: see a running Prime system from a terminal, and drive it.
//
//   prime [--domain D | --redis URL] [--json] <command>
//   prime bench [--quick] [--out DIR]     what each hop costs: a report folder
//   prime launch FILE [--placement NAME]  a system's processes, started and supervised
//
// Shm domains (the default; --domain, or PRIME_DOMAIN, or "robot") and
// Optimus domains (--redis tcp://host:port or unix:///path, with --domain as
// the key prefix).
// Exit codes: 0 done, 1 failed, 2 wrong usage (options, names or values),
// 3 no such domain, topic or service, 4 nothing arrived in time, 5 Redis
// unreachable, 130 interrupted by Ctrl-C before done.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <csignal>
#include <ctime>
#include <cstdlib>
#include <exception>
#include <functional>
#include <iostream>
#include <stdexcept>
#include <string>
#include <system_error>

#include "prime/logic/error.hpp"
#include "bench/command.hpp"
#include "json.hpp"
#include "launch_command.hpp"
#include "play_command.hpp"
#include "record_commands.hpp"
#include "shm_commands.hpp"

namespace {

using namespace prime::tool;

std::string bench_folder_name() {
  const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char text[48];
  std::strftime(text, sizeof text, "prime-bench-%Y%m%d-%H%M%S", std::gmtime(&now));
  return text;
}

// The most seconds an option takes: a year. Past it (or NaN, or infinity) a
// conversion to the clock's nanoseconds would overflow.
constexpr double kMaxSeconds = 365.0 * 24 * 3600;
constexpr auto kSecondsText = "from 0 to 31536000 seconds (a year)";

// A decimal number from `low` to `high` (`range` says so in words);
// anything else ("1e999", "nan", "inf", "0x10") is refused before a
// command converts it.
CLI::Validator number_in(double low, double high, const std::string& range) {
  return CLI::Validator{[=](std::string& text) {
                          double v = 0;
                          const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), v);
                          const bool ok = error == std::errc{} && end == text.data() + text.size() && v >= low && v <= high;
                          return ok ? std::string{} : "'" + text + "' is not a number " + range;
                        },
                        "NUMBER " + range};
}

// A name a command line gives: one with a control character is a mistake
// (and one with a NUL, which no command line carries, no registry takes).
void check_name(const std::string& what, const std::string& name) {
  if (std::ranges::any_of(name, [](unsigned char c) { return c < 0x20 || c == 0x7f; }))
    throw std::invalid_argument{what + " " + prime::tool::quote(name) + " has a control character"};
}

int exit_for(prime::Errc code) {
  switch (code) {
    case prime::Errc::not_found: return kNotFound;
    case prime::Errc::timeout: return kNothing;
    case prime::Errc::unreachable: return kUnreachable;
    case prime::Errc::invalid_argument: return kUsage;  // a name or value from the command line
    default: return kFailed;
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"prime: see a running Prime system — its processes, topics and services — and drive it"};
  app.require_subcommand(1);
  app.fallthrough();  // the global options after the subcommand too: `prime hz lidar --domain robot`
  Options o;
  if (const char* env = std::getenv("PRIME_DOMAIN"); env && *env) o.domain = env;
  app.add_option("--domain", o.domain, "the domain (default: $PRIME_DOMAIN, or robot)");
  app.add_option("--redis", o.redis,
                 "look at an Optimus domain on this Redis server (tcp://[user:password@]host:port or unix:///path) "
                 "instead; or credentials from $PRIME_REDIS_USER and $PRIME_REDIS_PASSWORD");
  app.add_option("--owner", o.owner,
                 "read and join a shm domain this user (a name or uid) set up; by default only your own are");
  app.add_flag("--json", o.json, "one JSON document (listings) or one per line (streams), for scripts");
  std::function<int()> run;
  const bool redis = [&] {
    for (int i = 1; i < argc; ++i)
      if (std::string{argv[i]}.starts_with("--redis")) return true;
    return false;
  }();

  auto command = [&](const std::string& name, const std::string& help, std::function<int()> shm,
                     std::function<int()> optimus = {}) {
    auto* sub = app.add_subcommand(name, help);
    sub->callback([&run, shm, optimus, name, redis] {
      run = redis ? (optimus ? optimus : [name] {
        std::cerr << "prime: " << name << " is for shared-memory domains\n";
        return int{kUsage};
      }) : shm;
    });
    return sub;
  };
  auto duration = [&](CLI::App* sub) {
    sub->add_option("--duration", o.duration, "seconds to run (default: until Ctrl-C)")->check(number_in(0, kMaxSeconds, kSecondsText));
    sub->add_option("-n,--count", o.count, "stop after this many samples");
    sub->add_option("--window", o.window, "samples the figures are taken over (default 100)");
  };

  command("domains", "the shared-memory domains on this machine", [&] { return shm_domains(o); });
  command("ls", "participants, topics and services of the domain", [&] { return shm_ls(o); },
          [&] { return optimus_ls(o); });
  command("info", "one topic, service or loop in full", [&] { return shm_info(o); }, [&] { return optimus_info(o); })
      ->add_option("name", o.name, "the topic, service or loop")
      ->required();
  auto* hz = command("hz", "a topic's rate: mean, min and max period, standard deviation", [&] { return shm_watch(o, "hz"); },
                     [&] { return optimus_watch(o, "hz"); });
  hz->add_option("topic", o.name)->required();
  duration(hz);
  auto* bw = command("bw", "a topic's bandwidth, bytes per second", [&] { return shm_watch(o, "bw"); },
                     [&] { return optimus_watch(o, "bw"); });
  bw->add_option("topic", o.name)->required();
  duration(bw);
  auto* delay = command("delay", "how old each sample is when it arrives, from its stamp (mean, p50, p99, max)",
                        [&] { return shm_watch(o, "delay"); }, [&] { return optimus_watch(o, "delay"); });
  delay->add_option("topic", o.name)->required();
  duration(delay);
  auto* echo = command("echo", "a topic's samples, field by field", [&] { return shm_echo(o); },
                       [&] { return optimus_watch(o, "echo"); });
  echo->add_option("topic", o.name)->required();
  echo->add_option("-n,--count", o.count, "stop after this many samples");
  const auto seconds = number_in(0, kMaxSeconds, kSecondsText);
  echo->add_option("--timeout", o.timeout, "seconds to wait for the first sample (default 5; 0: forever)")->check(seconds);
  auto* pub = command("pub", "publish a message built from JSON or field=value words", [&] { return shm_pub(o); });
  pub->add_option("topic", o.name)->required();
  pub->add_option("values", o.values, "{\"x\": 1} or x=1 y=2 pose.theta=0.5")->required();
  pub->add_option("--rate", o.rate, "publish this many times a second until --count or Ctrl-C (default: once)")
      ->check(number_in(1e-6, 1e9, "from 0.000001 to 1000000000 a second"));
  pub->add_option("-n,--count", o.count, "with --rate: how many");
  auto* call = command("call", "call a service with a request built from JSON or field=value words",
                       [&] { return shm_call(o); });
  call->add_option("service", o.name)->required();
  call->add_option("values", o.values, "{\"x\": 1} or x=1 y=2")->required();
  call->add_option("--timeout", o.timeout, "seconds to wait for the answer (default 5)")->check(seconds);
  command("graph", "the running system as Graphviz DOT", [&] { return shm_graph(o); }, [&] { return optimus_graph(o); });
  command("clean", "remove what dead participants left; never touches a live one's", [&] { return shm_clean(o); })
      ->add_flag("--all", o.all, "every domain on this machine, not only --domain");
  RecordOptions rec;
  std::string recording;
  auto* record = command("record", "record topics into an MCAP file, as the domain's observer (never slowing a publisher)",
                         [&] { return shm_record(o, rec); });
  record->add_option("topics", rec.topics, "the topics to record");
  record->add_flag("--all", rec.all, "every topic, and those that appear while recording");
  record->add_option("--exclude", rec.exclude, "with --all: leave out topics this regular expression finds");
  record->add_option("-o,--output", rec.out, "the MCAP file to write");
  record->add_option("--compression", rec.compression, "of each chunk: none, lz4 or zstd (default)")
      ->check(CLI::IsMember({"none", "lz4", "zstd"}));
  record->add_option("--chunk-size", rec.chunk_size, "bytes of messages a chunk collects (default 1 MiB)")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 30));
  record->add_option("--max-size", rec.max_size, "bytes a file reaches before the next is begun (FILE_0.mcap, FILE_1.mcap, ...)")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 50));
  record->add_option("--max-duration", rec.max_duration, "seconds a file spans before the next is begun")
      ->check(number_in(1e-3, kMaxSeconds, "from 0.001 to 31536000 seconds"));
  record->add_option("--snapshot", rec.snapshot, "keep only the last S seconds in memory; each SIGUSR1 writes them (FILE_0.mcap, ...)")
      ->check(number_in(1e-3, 3600, "from 0.001 to 3600 seconds"));
  record->add_option("--duration", o.duration, "seconds to record (default: until Ctrl-C)")->check(number_in(0, kMaxSeconds, kSecondsText));
  record->add_option("-n,--count", o.count, "stop after this many samples");
  auto* info_of_recording = record->add_subcommand("info", "what a recording holds: topics, types, counts, rates, losses");
  info_of_recording->add_option("file", recording, "the MCAP file")->required();
  info_of_recording->callback([&] { run = [&] { return record_info(o, recording); }; });
  std::string recovered;
  auto* recover = record->add_subcommand("recover", "rewrite a recording whose recorder died, with an index and a summary");
  recover->add_option("file", recording, "the MCAP file cut short")->required();
  recover->add_option("-o,--output", recovered, "the MCAP file to write")->required();
  recover->callback([&] { run = [&] { return record_recover(recording, recovered); }; });
  record->callback([&, info_of_recording, recover, redis] {
    if (info_of_recording->parsed() || recover->parsed()) return;
    run = redis ? std::function<int()>{[&] { return optimus_record(o, rec); }} : std::function<int()>{[&] { return shm_record(o, rec); }};
  });
  PlayOptions play_options;
  auto* play = command("play", "publish recordings into the domain at their recorded timing, as one timeline",
                       [&] { return shm_play(o, play_options); }, [&] { return optimus_play(o, play_options); });
  play->add_option("files", play_options.files, "the MCAP files")->required();
  play->add_option("--rate", play_options.rate, "times the recorded speed (default 1), or max: as fast as the readers take them");
  play->add_flag("--loop", play_options.loop, "again from the start, until Ctrl-C");
  play->add_option("--start", play_options.start, "seconds into the recordings to start at (found by their index)")->check(seconds);
  play->add_option("--duration", play_options.duration, "seconds of the recordings to play (default: to their end)")->check(seconds);
  play->add_option("--topics", play_options.topics, "only these recorded topics");
  play->add_option("--remap", play_options.remaps, "recorded:=published, publish a topic under another name (repeatable)")
      ->allow_extra_args(false);
  play->add_option("--stamps", play_options.stamps, "the samples' stamps: now (when published, the default) or keep (as recorded)")
      ->check(CLI::IsMember({"now", "keep"}));
  LaunchOptions launch_options;
  auto* launch = command("launch", "start the processes of a system file's placement in order of readiness, supervise them, stop them on Ctrl-C",
                         [&] { return prime::tool::launch(launch_options); });
  launch->add_option("file", launch_options.file, "the system file (YAML)")->required();
  launch->add_option("--placement", launch_options.placement, "which of its placements (default: the first)");
  launch->add_option("--param", launch_options.params, "component.name=value: a parameter's value, for every process (repeatable)")
      ->allow_extra_args(false);
  launch->add_option("--executable", launch_options.executable, "what every process runs, instead of what the file says");
  launch->add_option("--namespace", launch_options.ns,
                     "a prefix of every topic and service name, instead of the file's: one system launched twice side by side");
  launch->add_option("--grace", launch_options.grace, "seconds from SIGTERM to SIGKILL when stopping (default 5)")->check(seconds);
  launch->add_option("--ready-timeout", launch_options.ready_timeout, "seconds a process may take to be ready (default 20)")->check(seconds);
  bench::Options b;
  auto* bench = command("bench", "measure what each hop costs, against the floors and the peers: a report folder",
                        [&] {
                          if (b.out.empty()) b.out = bench_folder_name();
                          return bench::run(b);
                        });
  bench->add_flag("--quick", b.quick, "the main figures only, in under two minutes");
  bench->add_option("--out", b.out, "the report folder (default: prime-bench-<date>-<time>)");
  bench->add_option("--bin-dir", b.bin_dir, "where the benchmark binaries are (default: $PRIME_BENCH_DIR, or beside this prime: installed or built)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : int{kUsage};
  }
  // A domain named on the command line (or by $PRIME_DOMAIN) replaces the
  // system file's for what prime launch starts.
  if (app.count("--domain") > 0 || std::getenv("PRIME_DOMAIN")) launch_options.domain = o.domain;
  std::signal(SIGINT, [](int) { std::_Exit(kInterrupted); });  // replaced by commands that want to finish their report
  // A file past its size limit (ulimit -f) is an error the command reports
  // (EFBIG, a recording's no_space), not a signal that kills it mid-write.
  std::signal(SIGXFSZ, SIG_IGN);
  try {
    check_name("domain", o.domain);
    check_name("name", o.name);
    return run();
  } catch (const prime::Failure& f) {
    std::cerr << "prime: " << f.error().message << '\n';
    return exit_for(f.error().code);
  } catch (const std::invalid_argument& e) {  // what the command line gave: a value, JSON, a name
    std::cerr << "prime: " << e.what() << '\n';
    return kUsage;
  } catch (const std::exception& e) {
    std::cerr << "prime: " << e.what() << '\n';
    return kFailed;
  }
}
