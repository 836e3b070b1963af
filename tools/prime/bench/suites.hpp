#pragma once

// The benchmark binaries `prime bench` runs, what it runs of each in the
// quick and the full mode, and how their Google Benchmark results become
// Figures.

#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "../json.hpp"
#include "results.hpp"

namespace prime::tool::bench {

struct Suite {
  std::string name;                 // ipc, table1, optimus
  std::string title;                // what it measures, for the progress line and the report
  std::filesystem::path binary;     // relative to the benchmark directory
  std::string quick_filter;         // --benchmark_filter in the quick mode
  std::string full_filter = ".";    // and in the full one: everything, unless said
  double quick_min_time = 0.05;     // seconds per benchmark
  double full_min_time = 0.2;
  int full_repetitions = 3;         // runs of each in the full mode, one per round; the quick mode runs once
  std::vector<std::string> needs = {};  // programs that must be on the PATH, or the suite is skipped
  // Benchmarks (a part of their names) a full build has, with the reason
  // to report when the binary lacks them (a peer it was built without).
  std::vector<std::pair<std::string, std::string>> expected = {};
  // Benchmarks no build has, as a peer cannot do what they measure, each
  // with the reason: always listed as skipped, so that the report says why
  // a row is missing.
  std::vector<std::pair<std::string, std::string>> not_measured = {};
  // Environment the quick mode gives the binary (fewer requests, say).
  std::vector<std::pair<std::string, std::string>> quick_env = {};
  // Adds the figures of one benchmark's result (a Google Benchmark JSON
  // run; a full report takes the median of each figure over its rounds).
  std::function<void(const Json& run, Results&)> read;
};

std::vector<Suite> suites();

// The number `key` of a JSON object, if it has one.
const double* number(const Json& object, const std::string& key);

}  // namespace prime::tool::bench
