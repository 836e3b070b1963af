// Periodic loops: the schedule, overruns, skipped and caught-up ticks,
// statistics and stopping, written once and run on every medium.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "conformance/media.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// A run of a loop's chain as the chain saw it.
struct Run {
  Tick tick;
  Clock::time_point began;
  Clock::time_point ended;
};

// Keeps every run a loop's chain makes, for the test thread to wait on.
class Runs {
 public:
  explicit Runs(std::size_t expected) { runs_.reserve(expected * 4); }

  // In the chain: its tick, and the work `work(cycle)` (the chain's own run time).
  template <class Work>
  void run(Work&& work) {
    const auto began = Clock::now();
    const auto tick = this_tick();
    if (!tick) throw std::logic_error{"this_tick() is empty inside a loop's chain"};
    work(tick->cycle);
    std::scoped_lock lock{mutex_};
    runs_.push_back({*tick, began, Clock::now()});
    cv_.notify_all();
  }
  void run() {
    run([](std::uint64_t) {});
  }
  // A run seen from a block that another thread runs for the loop (a
  // service): it has no tick of its own.
  void count() {
    std::scoped_lock lock{mutex_};
    runs_.push_back({Tick{}, Clock::now(), Clock::now()});
    cv_.notify_all();
  }

  // Waits until `n` runs are in (false after `timeout`).
  [[nodiscard]] bool wait_for(std::size_t n, Clock::duration timeout = 20s) {
    std::unique_lock lock{mutex_};
    return cv_.wait_for(lock, timeout, [&] { return runs_.size() >= n; });
  }
  [[nodiscard]] std::vector<Run> all() {
    std::scoped_lock lock{mutex_};
    return runs_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<Run> runs_;
};

// Busy for `d`: the chain's work, which takes the CPU as a controller would.
void work_for(Clock::duration d) {
  const auto until = Clock::now() + d;
  while (Clock::now() < until) {
  }
}

// The first error on `errors` that mentions `text`, within `timeout`.
std::optional<Error> error_mentioning(Reader<Error>& errors, const std::string& text, Clock::duration timeout = 20s) {
  const auto give_up = Clock::now() + timeout;
  while (Clock::now() < give_up) {
    auto e = errors.read_for(give_up - Clock::now());
    if (!e) return std::nullopt;
    if (e->value.message.find(text) != std::string::npos) return e->value;
  }
  return std::nullopt;
}

template <class M>
class LoopTest : public MediumTest<M> {};
TYPED_TEST_SUITE(LoopTest, Media, MediumName);

TYPED_TEST(LoopTest, TicksComeOnAnAbsoluteScheduleNeverEarlyAndTheStatsCountEveryRun) {
  constexpr auto period = 2ms;
  Runs runs{100};
  auto loop = every(*this->core, period, [&](Token) { runs.run([](std::uint64_t) { work_for(500us); }); },
                    {.name = "steady"});
  ASSERT_TRUE(runs.wait_for(100));
  loop.stop();
  const auto all = runs.all();  // final: stop() waited for the run under way
  const auto& first = all.front();
  EXPECT_EQ(first.tick.cycle, 0u);
  for (std::size_t i = 0; i < all.size(); ++i) {
    const auto& r = all[i];
    // Each tick's time is start + cycle * period exactly: the time a run
    // took never pushes the next tick back.
    EXPECT_EQ(r.tick.time, first.tick.time + period * static_cast<int>(r.tick.cycle)) << "cycle " << r.tick.cycle;
    EXPECT_EQ(r.tick.deadline, r.tick.time + period);
    EXPECT_GE(r.began, r.tick.time) << "a tick never runs before its time";
    if (i > 0) {
      ASSERT_GT(r.tick.cycle, all[i - 1].tick.cycle);
      EXPECT_GE(r.began, all[i - 1].ended) << "one run at a time";
    }
  }
  const auto stats = loop.stats();
  EXPECT_EQ(stats.ticks, all.size());
  const auto gaps = all.back().tick.cycle + 1 - all.size();  // cycles not run between the first and the last run
  EXPECT_GE(stats.skipped, gaps) << "every cycle not run was counted as skipped (and so may be one after the last)";
  EXPECT_GE(stats.run_time.max, 500us);
  EXPECT_LE(stats.run_time.p50, stats.run_time.p99);
  EXPECT_LE(stats.run_time.p99, stats.run_time.max);
  EXPECT_LE(stats.lateness.p50, stats.lateness.p99);
  EXPECT_LE(stats.lateness.p99, stats.lateness.max);
  EXPECT_EQ(loop.name(), "steady");
  EXPECT_EQ(loop.period(), period);
}

TYPED_TEST(LoopTest, ALateRunIsReportedOnceWithItsCycleAndTheTicksItMissedAreSkipped) {
  constexpr auto period = 20ms;
  auto errors = this->core->errors().subscribe();
  Runs runs{6};
  auto loop = every(*this->core, period, [&](Token) {
    runs.run([](std::uint64_t cycle) {
      if (cycle == 2) std::this_thread::sleep_for(70ms);  // the work of a slow tick: 3.5 periods
    });
  }, {.name = "planner"});
  ASSERT_TRUE(runs.wait_for(5));
  loop.stop();
  const auto overrun = error_mentioning(errors, "cycle 2:");
  ASSERT_TRUE(overrun) << "the overrun of cycle 2 is reported";
  EXPECT_EQ(overrun->code, Errc::overrun);
  EXPECT_NE(overrun->message.find("loop 'planner'"), std::string::npos) << overrun->message;
  EXPECT_NE(overrun->message.find("after its deadline"), std::string::npos) << overrun->message;
  EXPECT_NE(overrun->message.find("skipped"), std::string::npos) << overrun->message;

  const auto all = runs.all();
  std::size_t slow = 0;
  while (all[slow].tick.cycle != 2) ++slow;
  const auto& next = all[slow + 1];
  EXPECT_GE(next.tick.cycle, 5u) << "cycles 3 and 4 were due while cycle 2 ran, and were not run";
  EXPECT_GT(next.tick.time, all[slow].ended) << "the loop went on with the first tick still ahead";
  EXPECT_GE(loop.stats().skipped, next.tick.cycle - 3);
  EXPECT_GE(loop.stats().overruns, 1u);
  EXPECT_GE(loop.stats().run_time.max, 70ms);
}

TYPED_TEST(LoopTest, AskedToRunMissedTicksTheLoopCatchesUpInOrder) {
  constexpr auto period = 10ms;
  Runs runs{8};
  auto loop = every(*this->core, period, [&](Token) {
    runs.run([](std::uint64_t cycle) {
      if (cycle == 1) std::this_thread::sleep_for(45ms);
    });
  }, {.name = "integrator", .missed = Missed::run});
  ASSERT_TRUE(runs.wait_for(8));
  loop.stop();
  const auto all = runs.all();
  for (std::size_t i = 0; i < all.size(); ++i) EXPECT_EQ(all[i].tick.cycle, i) << "no cycle is skipped";
  EXPECT_GE(all[2].began, all[1].ended) << "the missed ticks run after the late one";
  EXPECT_GE(all[2].began, all[2].tick.time + 35ms) << "cycle 2, due 35 ms before cycle 1 ended, was run late, not skipped";
  EXPECT_EQ(loop.stats().skipped, 0u);
}

TYPED_TEST(LoopTest, WhatTheChainThrowsIsReportedAndTheLoopGoesOn) {
  auto errors = this->core->errors().subscribe();
  Runs runs{3};
  auto loop = every(*this->core, 5ms, [&](Token) {
    runs.run([](std::uint64_t cycle) {
      if (cycle == 0) throw std::runtime_error{"sensor not ready"};
    });
  }, {.name = "fragile"});
  const auto thrown = error_mentioning(errors, "sensor not ready");
  ASSERT_TRUE(thrown);
  EXPECT_EQ(thrown->code, Errc::block_failed);
  EXPECT_NE(thrown->message.find("loop 'fragile', cycle 0"), std::string::npos) << thrown->message;
  EXPECT_TRUE(runs.wait_for(3)) << "the loop ran on after the throw";
}

TYPED_TEST(LoopTest, TheMediumsOwnChainRunsAsTheLoopsChain) {
  Runs runs{5};
  auto chain = this->template chain<Token>([&](Token) {
    runs.count();
    return 1;
  }, "tick");
  auto loop = every(*this->core, 5ms, chain, {.name = "own"});
  EXPECT_TRUE(runs.wait_for(5));
}

TYPED_TEST(LoopTest, StoppingTheLoopOrItsCoreEndsItsRuns) {
  Runs runs{3};
  auto loop = every(*this->core, 2ms, [&](Token) { runs.run(); }, {.name = "short"});
  ASSERT_TRUE(runs.wait_for(3));
  this->core->stop();  // joins the loop's worker
  const auto ticks = loop.stats().ticks;
  EXPECT_EQ(ticks, runs.all().size()) << "no run after the core stopped";
  loop.stop();  // returns at once: the worker is gone
  EXPECT_EQ(loop.stats().ticks, ticks);
  EXPECT_TRUE(fails_with([&] { (void)every(*this->core, 2ms, [](Token) {}); }, Errc::stopped, "no new worker"));
}

TYPED_TEST(LoopTest, TicksFallOnTheClocksMultiplesOfThePeriodShiftedByThePhase) {
  constexpr auto period = 10ms;
  Runs on_grid{2}, shifted{2};
  auto first = every(*this->core, period, [&](Token) { on_grid.run(); }, {.name = "first"});
  ASSERT_TRUE(on_grid.wait_for(1));
  auto second = every(*this->core, period, [&](Token) { shifted.run(); }, {.name = "second", .phase = 3ms});
  ASSERT_TRUE(on_grid.wait_for(2) && shifted.wait_for(2));
  for (const auto& r : on_grid.all()) EXPECT_EQ(r.tick.time.time_since_epoch() % period, 0ms);
  for (const auto& r : shifted.all()) EXPECT_EQ(r.tick.time.time_since_epoch() % period, 3ms) << "started later, in phase";
}

TYPED_TEST(LoopTest, OptionsItCannotTakeAreRefusedNamingTheLoop) {
  const auto nothing = [](Token) {};
  EXPECT_TRUE(fails_with([&] { (void)every(*this->core, 0ms, nothing, {.name = "zero"}); }, Errc::invalid_argument,
                         "loop 'zero': the period must be positive"));
  EXPECT_TRUE(fails_with([&] { (void)every(*this->core, 1ms, nothing, {.name = "d", .deadline = -1ms}); },
                         Errc::invalid_argument, "the deadline must be positive"));
  EXPECT_TRUE(fails_with([&] { (void)every(*this->core, 1ms, nothing, {.name = "p", .phase = -1ms}); },
                         Errc::invalid_argument, "the phase must be at least 0 and less than the period"));
  EXPECT_TRUE(fails_with([&] { (void)every(*this->core, 5ms, nothing, {.name = "p", .phase = 5ms}); },
                         Errc::invalid_argument, "less than the period"));
  EXPECT_FALSE(this_tick()) << "outside a loop's chain there is no tick";
}

}  // namespace
}  // namespace prime::test
