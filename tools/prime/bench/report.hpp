#pragma once

// The report folder of `prime bench`:
//   figures.csv   every figure: who, scenario, payload, statistic, value, unit
//   rounds.csv    a full run's figures round by round (figures.csv has their medians)
//   summary.md    the machine, headline ratios, a table per scenario (each
//                 Prime cell with its ratio to the floor and to the best
//                 peer), the plots, and what was skipped and why
//   plots/        <name>.dat and <name>.gp (gnuplot), rendered to .svg and .png
//   raw/          each benchmark's Google Benchmark JSON, and the suites' logs

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "machine.hpp"
#include "results.hpp"

namespace prime::tool::bench {

struct RunInfo {
  bool quick = false;
  bool interrupted = false;
  std::chrono::seconds took{};
  std::size_t benchmarks = 0;
  std::string suites;  // $PRIME_BENCH_SUITES, when only those ran
};

struct Written {
  std::string headline;            // the headline table, in Markdown
  std::vector<std::string> plots;  // rendered: plots/<name>.svg and .png
  std::string plot_problem;        // why plots are missing, if they are
};

// `results`: each figure's median over `rounds`, each round's own figures.
Written write_report(const std::filesystem::path& dir, const Results& results, const std::vector<Results>& rounds,
                     const Machine& machine, const RunInfo& info);

// Plots of `results` in dir/plots; returns the names rendered, and sets
// `problem` when gnuplot could not render them.
std::vector<std::string> write_plots(const std::filesystem::path& dir, const Results& results, std::string& problem);

// "147 ns", "1.2 µs"; "9.7 M/s".
std::string time_text(double ns);
std::string rate_text(double per_second);
std::string size_text(std::int64_t bytes);

}  // namespace prime::tool::bench
