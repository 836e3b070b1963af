// `prime bench`: every benchmark suite, one benchmark per process run (a
// full run: each in rounds), with progress on stderr, into a report folder
// (report.hpp says what is in it). $PRIME_BENCH_SUITES=loop,ipc runs only
// the suites it names.
#include "command.hpp"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include "machine.hpp"
#include "process.hpp"
#include "report.hpp"
#include "suites.hpp"

namespace prime::tool::bench {

namespace {

using Clock = std::chrono::steady_clock;

std::atomic<bool> interrupted{false};

std::string clock_text(Clock::duration d) {
  const auto s = std::chrono::duration_cast<std::chrono::seconds>(d).count();
  char text[16];
  std::snprintf(text, sizeof text, "%lld:%02lld", static_cast<long long>(s / 60), static_cast<long long>(s % 60));
  return text;
}

std::string regex_quoted(const std::string& name) {
  std::string out = "^";
  for (const char c : name) {
    if (std::string{".[]{}()*+?^$|\\"}.find(c) != std::string::npos) out += '\\';
    out += c;
  }
  return out + "$";
}

// Progress on stderr: one line redrawn on a terminal, a line per benchmark otherwise.
class Progress {
 public:
  explicit Progress(std::size_t total) : total_{total}, tty_{::isatty(STDERR_FILENO) == 1} {}

  void start(std::size_t index, const std::string& suite, const std::string& benchmark) {
    index_ = index;
    label_ = suite + "  " + benchmark;
    began_ = Clock::now();
    show(!tty_);
  }
  void tick() {
    if (tty_) show(false);
  }
  void finish(Clock::duration took) {
    spent_ += took;
    ++done_;
  }
  void end() const {
    if (tty_) std::cerr << "\r\033[K";
  }

 private:
  void show(bool newline) const {
    const auto elapsed = spent_ + (Clock::now() - began_);
    std::string left = "?";
    if (done_ > 0) left = clock_text(spent_ / done_ * static_cast<long>(total_ - done_));
    std::ostringstream line;
    line << '[' << index_ + 1 << '/' << total_ << "] " << label_ << "   " << clock_text(elapsed) << " elapsed, ~" << left
         << " left";
    if (tty_) std::cerr << "\r\033[K" << line.str() << std::flush;
    if (newline) std::cerr << line.str() << '\n';
  }

  std::size_t total_, index_ = 0, done_ = 0;
  bool tty_;
  std::string label_;
  Clock::time_point began_{};
  Clock::duration spent_{};
};

struct Planned {
  const Suite* suite;
  std::string benchmark;
};

// The benchmarks `suite` has in this mode, or why it cannot run.
std::vector<std::string> list(const Suite& suite, const std::filesystem::path& binary, bool quick, Results& results) {
  if (!std::filesystem::exists(binary)) {
    results.skipped.push_back({suite.name, "", binary.string() + " is not built (configure with -DPRIME_BUILD_BENCH=ON)"});
    return {};
  }
  for (const auto& program : suite.needs)
    if (!on_path(program)) {
      results.skipped.push_back({suite.name, "", program + " is not installed"});
      return {};
    }
  Finished listed;
  try {
    listed = run_program({binary.string(), "--benchmark_list_tests=true",
                          "--benchmark_filter=" + (quick ? suite.quick_filter : suite.full_filter)},
                         std::nullopt, std::chrono::seconds{30});
  } catch (const std::exception& e) {
    results.skipped.push_back({suite.name, "", e.what()});
    return {};
  }
  if (listed.status != 0) {
    results.skipped.push_back({suite.name, "", binary.string() + " could not list its benchmarks (exit " +
                                                   std::to_string(listed.status) + ")"});
    return {};
  }
  std::vector<std::string> names;
  std::istringstream lines{listed.output};
  for (std::string line; std::getline(lines, line);)
    if (line.starts_with("BM_")) names.push_back(line);
  for (const auto& [part, reason] : suite.expected)
    if (std::none_of(names.begin(), names.end(), [&](const std::string& n) { return n.find(part) != std::string::npos; }))
      results.skipped.push_back({suite.name, "BM" + part + "*", reason});
  for (const auto& [benchmark, reason] : suite.not_measured) results.skipped.push_back({suite.name, benchmark, reason});
  return names;
}

// Runs one benchmark once and adds what it measured, or why it could not.
// `json`: where its own report goes.
void run_one(const Suite& suite, const std::filesystem::path& binary, const std::string& benchmark, bool quick,
             const std::filesystem::path& raw, const std::filesystem::path& json, Progress& progress, Results& results) {
  std::vector<std::string> argv{binary.string(),
                                "--benchmark_filter=" + regex_quoted(benchmark),
                                "--benchmark_min_time=" + std::to_string(quick ? suite.quick_min_time : suite.full_min_time),
                                "--benchmark_out=" + json.string(),
                                "--benchmark_out_format=json"};
  auto skip = [&](const std::string& why) { results.skipped.push_back({suite.name, benchmark, why}); };
  Finished finished;
  try {
    finished = run_program(argv, raw / (suite.name + ".log"), std::chrono::seconds{180}, [&] { progress.tick(); },
                           [] { return interrupted.load(); });
  } catch (const std::exception& e) {
    return skip(e.what());
  }
  if (interrupted) return skip("interrupted");
  if (finished.timed_out) return skip("ran past 180 s and was killed");
  std::ifstream in{json};
  std::stringstream text;
  text << in.rdbuf();
  if (finished.status != 0 || text.str().empty())
    return skip("exited with status " + std::to_string(finished.status) + " (see raw/" + suite.name + ".log)");
  Json report;
  try {
    report = parse_json(text.str());
  } catch (const std::exception& e) {
    return skip(std::string{"its result could not be read: "} + e.what());
  }
  const auto& object = report.object();
  const auto runs = object.find("benchmarks");
  if (runs == object.end() || !runs->second.is_array() || runs->second.array().empty())
    return skip("reported nothing (see raw/" + suite.name + ".log)");
  const auto& run = runs->second.array().front();
  const auto& fields = run.object();
  if (const auto error = fields.find("error_occurred");
      error != fields.end() && std::holds_alternative<bool>(error->second.value) && std::get<bool>(error->second.value)) {
    const auto message = fields.find("error_message");
    return skip(message != fields.end() && std::holds_alternative<std::string>(message->second.value)
                    ? std::get<std::string>(message->second.value)
                    : "failed");
  }
  const auto before = results.figures.size();
  suite.read(run, results);
  if (results.figures.size() == before) skip("its result has no figure this report knows");
}

// Each figure as the median of its rounds' values (the middle one, or the
// lower of the two middle ones), in the order first measured; each skip and note once.
Results medians(const std::vector<Results>& rounds) {
  Results out;
  std::vector<std::vector<double>> values;
  for (const auto& round : rounds) {
    for (const auto& f : round.figures) {
      const auto same = [&](const Figure& g) {
        return g.who == f.who && g.scenario == f.scenario && g.payload == f.payload && g.statistic == f.statistic;
      };
      const auto at = std::find_if(out.figures.begin(), out.figures.end(), same);
      if (at == out.figures.end()) {
        out.figures.push_back(f);
        values.push_back({f.value});
      } else {
        values[static_cast<std::size_t>(at - out.figures.begin())].push_back(f.value);
      }
    }
    for (const auto& s : round.skipped)
      if (std::none_of(out.skipped.begin(), out.skipped.end(),
                       [&](const Skipped& t) { return t.suite == s.suite && t.benchmark == s.benchmark; }))
        out.skipped.push_back(s);
    for (const auto& note : round.notes)
      if (std::find(out.notes.begin(), out.notes.end(), note) == out.notes.end()) out.notes.push_back(note);
  }
  for (std::size_t i = 0; i < values.size(); ++i) {
    auto& v = values[i];
    const auto middle = v.begin() + static_cast<long>((v.size() - 1) / 2);
    std::nth_element(v.begin(), middle, v.end());
    out.figures[i].value = *middle;
  }
  return out;
}

// Where the benchmark binaries are: --bin-dir, $PRIME_BENCH_DIR, or beside
// this prime: installed (<prefix>/libexec/prime/bench, from <prefix>/bin) or
// in its build tree (<build>/bench, from <build>/tools/prime). Empty, with
// what was tried said, where none holds them.
std::filesystem::path benchmark_folder(const Options& options) {
  if (!options.bin_dir.empty()) return options.bin_dir;
  if (const char* env = std::getenv("PRIME_BENCH_DIR"); env && *env) return env;
  std::error_code error;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", error).parent_path();
  const std::filesystem::path places[] = {self / ".." / "libexec" / "prime" / "bench", self / ".." / ".." / "bench"};
  const auto first = suites().front().binary;
  for (const auto& place : places)
    if (std::filesystem::is_regular_file(place / first, error)) return place.lexically_normal();
  std::cerr << "prime bench: no benchmark binaries (" << first << ") in " << places[0].lexically_normal().string()
            << " or " << places[1].lexically_normal().string()
            << ": this prime was built or installed without the benchmarks; pass --bin-dir or set PRIME_BENCH_DIR\n";
  return {};
}

}  // namespace

int run(const Options& options) {
  const std::filesystem::path bin_dir = benchmark_folder(options);
  if (bin_dir.empty()) return 2;
  const std::filesystem::path out = options.out;
  const auto raw = out / "raw";
  std::filesystem::create_directories(raw);
  interrupted = false;
  std::signal(SIGINT, [](int) { interrupted = true; });

  const auto machine = this_machine();
  const auto began = Clock::now();
  Results results;
  const auto all = suites();
  std::vector<Planned> plan;
  if (options.quick)
    for (const auto& suite : all)
      for (const auto& [name, value] : suite.quick_env) ::setenv(name.c_str(), value.c_str(), 0);
  // $PRIME_BENCH_SUITES (names, comma-separated) runs only those suites;
  // the others are listed as skipped, so a partial report says it is one.
  const char* selected = std::getenv("PRIME_BENCH_SUITES");
  const std::string only = selected ? "," + std::string{selected} + "," : "";
  for (const auto& suite : all) {
    if (!only.empty() && only != ",," && only.find("," + suite.name + ",") == std::string::npos) {
      results.skipped.push_back({suite.name, "", "not selected (PRIME_BENCH_SUITES=" + std::string{selected} + ")"});
      continue;
    }
    for (auto& name : list(suite, bin_dir / suite.binary, options.quick, results)) plan.push_back({&suite, std::move(name)});
  }

  std::cerr << "prime bench: " << plan.size() << " benchmarks" << (options.quick ? " (quick)" : "") << " on " << machine.cpu
            << ", " << machine.cpus << " CPUs; report in " << out.string() << '\n';
  // A full run takes each benchmark's repetitions in rounds over the whole
  // plan, not one after another: so a figure, and the floor or peer it is
  // compared with, were measured across the same stretch of whatever else
  // the machine was doing, and their medians compare.
  std::vector<std::pair<int, std::size_t>> runs;  // (round, plan index)
  int rounds = 1;
  if (!options.quick)
    for (const auto& [suite, benchmark] : plan) rounds = std::max(rounds, suite->full_repetitions);
  for (int round = 0; round < rounds; ++round)
    for (std::size_t i = 0; i < plan.size(); ++i)
      if (round == 0 || round < plan[i].suite->full_repetitions) runs.emplace_back(round, i);
  Progress progress{runs.size()};
  std::vector<Results> measured(static_cast<std::size_t>(rounds));  // each round's own figures
  for (std::size_t k = 0; k < runs.size() && !interrupted; ++k) {
    const auto [round, i] = runs[k];
    const auto& [suite, benchmark] = plan[i];
    progress.start(k, suite->name, benchmark);
    const auto t = Clock::now();
    const auto json = raw / (suite->name + "-" + std::to_string(i) + (rounds > 1 ? "-" + std::to_string(round + 1) : "") + ".json");
    run_one(*suite, bin_dir / suite->binary, benchmark, options.quick, raw, json, progress,
            measured[static_cast<std::size_t>(round)]);
    progress.finish(Clock::now() - t);
  }
  progress.end();
  auto merged = medians(measured);
  results.figures = std::move(merged.figures);
  results.skipped.insert(results.skipped.end(), merged.skipped.begin(), merged.skipped.end());
  results.notes = std::move(merged.notes);

  const RunInfo info{.quick = options.quick,
                     .interrupted = interrupted.load(),
                     .took = std::chrono::duration_cast<std::chrono::seconds>(Clock::now() - began),
                     .benchmarks = plan.size(),
                     .suites = only.empty() || only == ",," ? "" : selected};
  const auto written = write_report(out, results, measured, machine, info);
  std::cout << written.headline << "\nReport: " << (out / "summary.md").string() << " (" << results.figures.size()
            << " figures in figures.csv";
  if (!written.plots.empty()) std::cout << ", " << written.plots.size() << " plots";
  std::cout << ")\n";
  if (!written.plot_problem.empty()) std::cerr << "prime bench: plots: " << written.plot_problem << '\n';
  if (interrupted) return 1;
  return results.figures.empty() ? 1 : 0;
}

}  // namespace prime::tool::bench
