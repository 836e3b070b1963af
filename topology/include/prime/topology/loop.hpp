#pragma once

#include <time.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <concepts>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/logic/token.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/histogram.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/realtime.hpp"

namespace prime {

// What a periodic loop does with the ticks a late one made it miss.
enum class Missed {
  skip,  // goes on with the next tick still ahead (the default: a controller wants fresh data, not a backlog)
  run,   // runs each missed tick at once, in order, until it has caught up
};

// How a periodic loop runs: `every(core, period, chain, {.name = "planner", .deadline = 15ms})`.
struct LoopOptions {
  std::string name = "loop";
  // Ticks fall on the monotonic clock's multiples of the period, this much
  // later: loops of one period keep a fixed phase to each other, however
  // far apart they were started. The first tick is the first of those
  // still ahead.
  Clock::duration phase{};
  // A tick's run must end within this of its time, or it is an overrun,
  // reported on the core's errors. The period when not given.
  std::optional<Clock::duration> deadline{};
  Missed missed = Missed::skip;
  // The loop's thread's scheduling: policy and priority, CPUs (realtime.hpp).
  Realtime realtime{};
};

// The spread of a loop's durations since it started: each within 6.25 %
// (rounded up, never above `max`).
struct DurationStats {
  Clock::duration p50{};
  Clock::duration p99{};
  Clock::duration max{};
};

struct LoopStats {
  std::uint64_t ticks = 0;     // runs of the chain
  std::uint64_t overruns = 0;  // runs that ended after their tick's deadline
  std::uint64_t skipped = 0;   // ticks missed and not run (Missed::skip)
  DurationStats lateness{};    // from a tick's time to the chain's start
  DurationStats run_time{};    // the chain's run
};

// The tick a periodic loop is running, as its chain sees it (this_tick()).
struct Tick {
  std::uint64_t cycle = 0;        // 0 for the first tick; cycle k is due k periods after it
  Clock::time_point time{};       // when it was due
  Clock::time_point deadline{};   // when its run must have ended
};

namespace detail {

// The tick this thread runs, if it runs a loop's chain.
inline thread_local const Tick* current_tick = nullptr;

// Sleeps until `when` on the monotonic clock, as an absolute time
// (clock_nanosleep with TIMER_ABSTIME: a tick's time is never pushed back
// by the time it took to get there), so a loop does not drift. Sleeps in
// slices of at most kStopSlice, each absolute too, so that a stop is seen;
// a period under it sleeps once. False when `stopped()` said so.
template <class Stopped>
bool sleep_until(Clock::time_point when, Stopped stopped) {
  static_assert(std::is_same_v<Clock, std::chrono::steady_clock>, "prime::Clock must be CLOCK_MONOTONIC");
  constexpr Clock::duration kStopSlice = std::chrono::milliseconds{50};
  while (true) {
    if (stopped()) return false;
    const auto now = Clock::now();
    if (now >= when) return true;
    const auto until = std::min(when, now + kStopSlice);
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(until.time_since_epoch()).count();
    const timespec at{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
    while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, nullptr) == EINTR) {
    }
  }
}

// When each tick of a loop is due and must end, and which comes after a
// run: pure arithmetic, so the schedule is exact whatever the runs took.
struct Schedule {
  Clock::time_point start;  // tick 0's time
  Clock::duration period;
  Clock::duration deadline;

  // Ticks at the clock's multiples of `period` plus `phase`, the first of
  // them at or after `now`.
  static Schedule aligned(Clock::time_point now, Clock::duration period, Clock::duration phase,
                          Clock::duration deadline) noexcept {
    auto first = Clock::time_point{(now.time_since_epoch() - phase) / period * period} + phase;
    if (first < now) first += period;
    return {first, period, deadline};
  }

  [[nodiscard]] Clock::time_point at(std::uint64_t cycle) const noexcept {
    return start + period * static_cast<Clock::rep>(cycle);
  }
  // The cycle to run after `cycle`, whose run ended at `ended`: the next
  // one, or with Missed::skip the first whose time is still ahead.
  [[nodiscard]] std::uint64_t next(std::uint64_t cycle, Clock::time_point ended, Missed missed) const noexcept {
    const auto following = cycle + 1;
    if (missed == Missed::run || at(following) > ended) return following;
    return static_cast<std::uint64_t>((ended - start) / period) + 1;  // the first tick after `ended`
  }
};

// What a loop's thread records of its runs: atomics only, at fixed
// offsets, so it may live in memory shared with tools (a medium's
// `record_loop`, below) as well as in this process's heap.
struct LoopRecord {
  DurationHistogram lateness;
  DurationHistogram run_time;
  std::atomic<std::uint64_t> overruns{0};
  std::atomic<std::uint64_t> skipped{0};
};
static_assert(std::is_standard_layout_v<LoopRecord> && std::atomic<std::uint64_t>::is_always_lock_free,
              "a LoopRecord may sit in shared memory");

// The statistics of `r`, read while its loop records.
[[nodiscard]] inline LoopStats stats_of(const LoopRecord& r) noexcept {
  const auto spread = [](const DurationHistogram& h) { return DurationStats{h.percentile(0.5), h.percentile(0.99), h.max()}; };
  return {r.run_time.count(), r.overruns.load(std::memory_order_relaxed), r.skipped.load(std::memory_order_relaxed),
          spread(r.lateness), spread(r.run_time)};
}

// Where a loop of `core` records: a medium that shows its loops to tools
// gives the place (`core.record_loop(name, period, deadline)`, held for as
// long as the loop lives; Shm's is in its domain's registry, for `prime ls`
// and `prime info`); otherwise this process's heap.
template <class M>
std::shared_ptr<LoopRecord> loop_record(M& core, const std::string& name, Clock::duration period, Clock::duration deadline) {
  if constexpr (requires { { core.record_loop(name, period, deadline) } -> std::same_as<std::shared_ptr<LoopRecord>>; })
    return core.record_loop(name, period, deadline);
  else
    return std::make_shared<LoopRecord>();
}

// What a loop's worker and its handle share.
struct LoopState {
  LoopState(std::string n, Schedule s, Missed m, std::shared_ptr<LoopRecord> r)
      : name{std::move(n)}, schedule{s}, missed{m}, record{std::move(r)} {}

  const std::string name;
  const Schedule schedule;
  const Missed missed;
  const std::shared_ptr<LoopRecord> record;
  std::atomic<bool> stopping{false};
  std::mutex mutex;
  std::condition_variable done_cv;
  bool set_up = false;              // the worker applied its scheduling (or gave up)
  std::optional<Error> refused{};   // what the system refused, when the loop does not run without it
  bool done = false;
  std::thread::id thread{};
};

// A loop's worker: sleeps until each tick's time, runs the chain, records
// how late it started and how long it ran, reports an overrun, and picks
// the next tick. Allocates nothing but to report.
template <class C>
void run_loop(LoopState& s, C& chain, const std::weak_ptr<RuntimeState>& runtime, const std::stop_token& stop) {
  const auto stopped = [&] { return stop.stop_requested() || s.stopping.load(std::memory_order_relaxed); };
  const auto report = [&](Error error) {
    if (auto r = runtime.lock()) r->report(std::move(error));
  };
  const auto ms = [](Clock::duration d) {
    char text[32];
    std::snprintf(text, sizeof text, "%.3f ms", std::chrono::duration<double, std::milli>{d}.count());
    return std::string{text};
  };
  auto& r = *s.record;
  Tick tick{};
  current_tick = &tick;
  for (std::uint64_t cycle = 0;;) {
    tick = {cycle, s.schedule.at(cycle), s.schedule.at(cycle) + s.schedule.deadline};
    if (!sleep_until(tick.time, stopped)) break;
    const auto began = Clock::now();
    r.lateness.record(began - tick.time);
    try {
      (void)chain(Token{});
    } catch (const std::exception& e) {
      if (stopped()) break;  // a wait in the chain ended by the stop
      report({Errc::block_failed, "loop '" + s.name + "', cycle " + std::to_string(cycle) + ": " + e.what()});
    } catch (...) {
      if (stopped()) break;
      report({Errc::block_failed, "loop '" + s.name + "', cycle " + std::to_string(cycle) +
                                               ": an exception of unknown type"});
    }
    const auto ended = Clock::now();
    r.run_time.record(ended - began);
    const auto next = s.schedule.next(cycle, ended, s.missed);
    if (next > cycle + 1) r.skipped.store(r.skipped.load(std::memory_order_relaxed) + (next - cycle - 1), std::memory_order_relaxed);
    if (ended > tick.deadline) {
      r.overruns.store(r.overruns.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
      std::string what = "loop '" + s.name + "', cycle " + std::to_string(cycle) + ": ended " + ms(ended - tick.deadline) +
                         " after its deadline (" + ms(s.schedule.deadline) + " after its time; it started " +
                         ms(began - tick.time) + " late and ran " + ms(ended - began) + ")";
      if (next > cycle + 1) what += "; " + std::to_string(next - cycle - 1) + " tick(s) skipped";
      report({Errc::overrun, std::move(what)});
    }
    cycle = next;
  }
  current_tick = nullptr;
}

}  // namespace detail

// The tick the calling thread's loop is running: its cycle, its time and its
// deadline (a controller's dt, a stamp for what it sends). None outside a
// periodic loop's chain.
[[nodiscard]] inline std::optional<Tick> this_tick() noexcept {
  if (detail::current_tick == nullptr) return std::nullopt;
  return *detail::current_tick;
}

// A periodic loop that runs a chain in a worker of its core. Destroying the
// handle stops the loop (as stop() does); so does stopping the core.
//
// Thread-safe.
class Loop {
 public:
  explicit Loop(std::shared_ptr<detail::LoopState> state) : state_{std::move(state)} {}
  Loop(Loop&&) noexcept = default;
  Loop& operator=(Loop&& other) noexcept {
    if (this != &other) {
      stop();
      state_ = std::move(other.state_);
    }
    return *this;
  }
  ~Loop() { stop(); }

  // Stops the loop and waits for the run under way, if any, to end; from
  // within the loop's own chain, stops it without waiting. Idempotent.
  void stop() {
    if (!state_) return;
    state_->stopping.store(true, std::memory_order_relaxed);
    std::unique_lock lock{state_->mutex};
    if (state_->thread == std::this_thread::get_id()) return;
    state_->done_cv.wait(lock, [&] { return state_->done; });
  }

  [[nodiscard]] LoopStats stats() const { return detail::stats_of(*state_->record); }

  [[nodiscard]] const std::string& name() const noexcept { return state_->name; }
  [[nodiscard]] Clock::duration period() const noexcept { return state_->schedule.period; }
  [[nodiscard]] Clock::duration deadline() const noexcept { return state_->schedule.deadline; }

 private:
  std::shared_ptr<detail::LoopState> state_;
};

// Runs `chain` (any chain that takes a Token: a collector, a sync's
// collector, either linked to blocks) every `period`, in a worker of `core`:
// on an absolute schedule on the monotonic clock, so it does not drift. A
// run that ends after its deadline is an overrun, reported on
// `core.errors()` with its cycle and how late it ended; then the ticks it
// missed are skipped or run, as `options.missed` says. What the chain throws
// is reported there too, and the loop goes on with its next tick.
//
//   auto planner = prime::every(core, 20ms, prime::collector(core, sets) | plan | control,
//                               {.name = "planner", .deadline = 15ms});
//   planner.stats().lateness.p99;
//
// With `options.realtime`, the loop's thread gets its policy, priority and
// CPUs before the first tick; what the system refuses throws Errc::refused,
// naming the limit and how to raise it (or, with best_effort, is one
// warning on core.errors()).
//
// Throws Errc::invalid_argument for a period or deadline that is not
// positive, a phase not within the period, a priority out of range; Errc::stopped when
// the core is stopping; Errc::domain_full when a medium that shows its loops
// to tools has no room for another (Shm: 64 per domain).
template <Medium M, class C>
  requires std::invocable<C&, Token>
[[nodiscard]] Loop every(M& core, Clock::duration period, C chain, LoopOptions options = {}) {
  const auto deadline = options.deadline.value_or(period);
  const auto refuse = [&](const std::string& why) {
    return Failure{{Errc::invalid_argument, "loop '" + options.name + "': " + why}};
  };
  if (period <= Clock::duration::zero()) throw refuse("the period must be positive");
  if (deadline <= Clock::duration::zero()) throw refuse("the deadline must be positive");
  if (options.phase < Clock::duration::zero() || options.phase >= period)
    throw refuse("the phase must be at least 0 and less than the period");
  if (auto invalid = detail::realtime_invalid(options.realtime)) throw refuse(*invalid);
  auto runtime = core.runtime().lock();
  if (!runtime) throw Failure{{Errc::stopped, "loop '" + options.name + "': the core is gone"}};
  auto state = std::make_shared<detail::LoopState>(
      options.name, detail::Schedule::aligned(Clock::now(), period, options.phase, deadline), options.missed,
      detail::loop_record(core, options.name, period, deadline));
  runtime->spawn([state, chain = std::move(chain), weak = core.runtime(),
                  realtime = options.realtime](std::stop_token stop) mutable {
    auto refused = detail::apply_realtime(realtime, "loop '" + state->name + "'");
    if (refused && realtime.best_effort) {
      refused->message += "; best effort: the loop runs without it";
      if (auto r = weak.lock()) r->report(*refused);
      refused.reset();
    }
    {
      std::scoped_lock lock{state->mutex};
      state->thread = std::this_thread::get_id();
      state->set_up = true;
      state->refused = refused;
      if (refused) state->done = true;
    }
    state->done_cv.notify_all();
    if (refused) return;
    detail::run_loop(*state, chain, weak, stop);
    std::scoped_lock lock{state->mutex};
    state->done = true;
    state->done_cv.notify_all();
  });
  {
    // The loop runs as asked, or not at all: wait for its scheduling.
    std::unique_lock lock{state->mutex};
    state->done_cv.wait(lock, [&] { return state->set_up; });
    if (state->refused) throw Failure{*state->refused};
  }
  return Loop{std::move(state)};
}

}  // namespace prime
