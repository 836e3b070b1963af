// sync: the cost of one synchronised set and how late it is made, for the
// sensors of a robot — lidar 40 Hz, odometry 100 Hz, IMU 200 Hz (and a
// second odometry for 4 inputs) — with exact_time as the floor.
//
//   BM_SyncCost_<policy>/<inputs>      ns per set (the matcher's work, one thread)
//   BM_SyncLatency_<policy>/<inputs>   when a set is made after its newest part
//                                      arrived, in stream time (values arrive
//                                      when stamped): mean and p99, in ms
//
// Policies: Exact (every sensor stamps on one shared 1 ms clock tick: the
// floor), Approximate (adaptive, no bounds), ApproximateBounded (told each
// input's least interval), Tolerance (the greedy within_tolerance(5ms)).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <memory>
#include <random>
#include <vector>

#include "prime/liberty.hpp"

namespace {

using namespace std::chrono_literals;
using prime::Clock;

enum class Policy { exact, approximate, bounded, tolerance };

// The streams' values in arrival (stamp) order: (input, stamp).
std::vector<std::pair<std::size_t, Clock::time_point>> arrivals(std::size_t inputs, Policy policy, int seconds) {
  const std::array<Clock::duration, 4> period{25ms, 10ms, 5ms, 10ms};
  std::mt19937 random{1};
  std::vector<std::pair<std::size_t, Clock::time_point>> all;
  for (std::size_t i = 0; i < inputs; ++i) {
    for (auto t = Clock::time_point{} + 1s; t < Clock::time_point{} + std::chrono::seconds{1 + seconds}; t += period[i]) {
      auto stamp = t;
      if (policy != Policy::exact) stamp += std::chrono::microseconds{std::uniform_int_distribution<int>{-1500, 1500}(random)};
      all.emplace_back(i, stamp);
    }
  }
  std::stable_sort(all.begin(), all.end(), [](auto& a, auto& b) { return a.second < b.second; });
  return all;
}

prime::SyncPolicy policy_of(Policy p) {
  switch (p) {
    case Policy::exact: return prime::exact_time;
    case Policy::approximate: return prime::approximate_time();
    case Policy::bounded: return prime::approximate_time({.min_interval = {20ms, 7ms, 3ms, 7ms}});
    case Policy::tolerance: return prime::within_tolerance(5ms);
  }
  return prime::exact_time;
}

template <std::size_t... I>
void offer(auto& matcher, std::size_t input, Clock::time_point stamp, std::index_sequence<I...>) {
  ((input == I ? matcher.template offer<I>({static_cast<int>(I), stamp}, {}) : void()), ...);
}

template <class... Ts>
struct Harness {
  static constexpr std::size_t kN = sizeof...(Ts);
  prime::LocalSource<prime::Synced<Ts...>> out{"out", {.capacity = 1 << 16}, {}, prime::Graph{}};
  prime::Reader<prime::Synced<Ts...>> reader = out.subscribe();
  std::unique_ptr<prime::detail::Synchronizer<Ts...>> matcher;

  explicit Harness(Policy p) {
    std::array<std::size_t, kN> depths;
    depths.fill(64);
    matcher = std::make_unique<prime::detail::Synchronizer<Ts...>>(policy_of(p), depths, out);
  }
  void add(std::size_t input, Clock::time_point stamp) { offer(*matcher, input, stamp, std::index_sequence_for<Ts...>{}); }
};

template <class H>
void cost(benchmark::State& state, Policy policy) {
  const auto values = arrivals(H::kN, policy, 10);
  std::size_t sets = 0;
  for (auto _ : state) {
    state.PauseTiming();  // a fresh matcher and output buffer each time: set up and torn down untimed
    auto h = std::make_unique<H>(policy);
    state.ResumeTiming();
    for (const auto& [input, stamp] : values) h->add(input, stamp);
    sets += h->reader.read_all().size();
    state.PauseTiming();
    h.reset();
    state.ResumeTiming();
  }
  state.counters["ns/set"] = benchmark::Counter(static_cast<double>(sets), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.SetItemsProcessed(static_cast<std::int64_t>(sets));
}

template <class H>
void latency(benchmark::State& state, Policy policy) {
  const auto values = arrivals(H::kN, policy, 10);
  std::vector<double> ms;
  for (auto _ : state) {
    ms.clear();
    H h{policy};
    for (const auto& [input, stamp] : values) {
      h.add(input, stamp);
      for (auto& set : h.reader.read_all())
        ms.push_back(std::chrono::duration<double, std::milli>(stamp - set.stamp).count());  // made on this arrival
    }
  }
  std::sort(ms.begin(), ms.end());
  double mean = 0;
  for (double v : ms) mean += v / static_cast<double>(ms.size());
  state.counters["mean_ms"] = mean;
  state.counters["p99_ms"] = ms.empty() ? 0 : ms[static_cast<std::size_t>(0.99 * static_cast<double>(ms.size() - 1))];
  state.counters["sets"] = static_cast<double>(ms.size());
}

using Two = Harness<int, int>;
using Four = Harness<int, int, int, int>;

#define PRIME_SYNC_BENCH(Name, P)                                                      \
  void BM_SyncCost_##Name##_2(benchmark::State& s) { cost<Two>(s, Policy::P); }       \
  void BM_SyncCost_##Name##_4(benchmark::State& s) { cost<Four>(s, Policy::P); }      \
  void BM_SyncLatency_##Name##_2(benchmark::State& s) { latency<Two>(s, Policy::P); } \
  void BM_SyncLatency_##Name##_4(benchmark::State& s) { latency<Four>(s, Policy::P); } \
  BENCHMARK(BM_SyncCost_##Name##_2);                                                   \
  BENCHMARK(BM_SyncCost_##Name##_4);                                                   \
  BENCHMARK(BM_SyncLatency_##Name##_2)->Iterations(1);                                 \
  BENCHMARK(BM_SyncLatency_##Name##_4)->Iterations(1)

PRIME_SYNC_BENCH(Exact, exact);
PRIME_SYNC_BENCH(Approximate, approximate);
PRIME_SYNC_BENCH(ApproximateBounded, bounded);
PRIME_SYNC_BENCH(Tolerance, tolerance);

}  // namespace

BENCHMARK_MAIN();
