#pragma once

#include <atomic>
#include <chrono>
#include <concepts>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>
#include <stop_token>
#include <string>
#include <thread>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/loop.hpp"

namespace prime {

struct WatchdogOptions {
  std::string name = "watchdog";
};

namespace detail {

// What a watchdog's worker and its handle share.
struct WatchdogState {
  WatchdogState(std::string n, Clock::duration d) : name{std::move(n)}, deadline{d} {}

  [[nodiscard]] Clock::time_point fed() const noexcept {
    return Clock::time_point{Clock::duration{last_fed.load(std::memory_order_relaxed)}};
  }

  const std::string name;
  const Clock::duration deadline;
  std::atomic<Clock::rep> last_fed{Clock::now().time_since_epoch().count()};
  std::atomic<std::uint64_t> expiries{0};
  std::atomic<bool> expired{false};
  std::atomic<bool> stopping{false};
  std::mutex mutex;
  std::condition_variable done_cv;
  bool done = false;
  std::thread::id thread{};
};

// A watchdog's worker: sleeps until the deadline after the last feed; if no
// feed came meanwhile, the watchdog expires (once), and the worker then
// looks for a feed every deadline to arm it again.
template <class F>
void run_watchdog(WatchdogState& s, F& on_expired, const std::weak_ptr<RuntimeState>& runtime, const std::stop_token& stop) {
  const auto stopped = [&] { return stop.stop_requested() || s.stopping.load(std::memory_order_relaxed); };
  while (true) {
    const auto fed = s.fed();
    if (!sleep_until(fed + s.deadline, stopped)) return;
    if (s.fed() != fed) continue;  // fed meanwhile: the deadline moved
    s.expired.store(true, std::memory_order_relaxed);
    s.expiries.store(s.expiries.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    try {
      on_expired();
    } catch (const std::exception& e) {
      if (auto r = runtime.lock()) r->report({Errc::block_failed, "watchdog '" + s.name + "': " + e.what()});
    } catch (...) {
      if (auto r = runtime.lock()) r->report({Errc::block_failed, "watchdog '" + s.name + "': an exception of unknown type"});
    }
    for (auto next = Clock::now() + s.deadline; s.fed() == fed; next += s.deadline)
      if (!sleep_until(next, stopped)) return;
    s.expired.store(false, std::memory_order_relaxed);
  }
}

}  // namespace detail

// A deadline monitor: whoever expects something regularly (a command, a
// heartbeat, a sensor's sample) feeds the watchdog each time it comes; when
// a deadline passes with no feed, the watchdog calls its action once, in a
// worker of its core. The next feed arms it again. Destroying the handle
// stops it (as stop() does); so does stopping the core.
//
// Thread-safe; feed() is one clock read and one store, with no lock.
class Watchdog {
 public:
  explicit Watchdog(std::shared_ptr<detail::WatchdogState> state) : state_{std::move(state)} {}
  Watchdog(Watchdog&&) noexcept = default;
  Watchdog& operator=(Watchdog&& other) noexcept {
    if (this != &other) {
      stop();
      state_ = std::move(other.state_);
    }
    return *this;
  }
  ~Watchdog() { stop(); }

  // What was expected came now: the deadline starts again.
  void feed() const noexcept { state_->last_fed.store(Clock::now().time_since_epoch().count(), std::memory_order_relaxed); }

  // Whether it has expired and not been fed since (as its worker last saw).
  [[nodiscard]] bool expired() const noexcept { return state_->expired.load(std::memory_order_relaxed); }
  // How many times it has expired.
  [[nodiscard]] std::uint64_t expiries() const noexcept { return state_->expiries.load(std::memory_order_relaxed); }
  [[nodiscard]] const std::string& name() const noexcept { return state_->name; }
  [[nodiscard]] Clock::duration deadline() const noexcept { return state_->deadline; }

  // Stops it and waits for an action under way, if any, to end; from within
  // its own action, stops it without waiting. Idempotent.
  void stop() {
    if (!state_) return;
    state_->stopping.store(true, std::memory_order_relaxed);
    std::unique_lock lock{state_->mutex};
    if (state_->thread == std::this_thread::get_id()) return;
    state_->done_cv.wait(lock, [&] { return state_->done; });
  }

 private:
  std::shared_ptr<detail::WatchdogState> state_;
};

// A watchdog on `core` that calls `on_expired` when `deadline` passes with
// no feed, from now on:
//
//   auto commands = prime::watchdog(core, 100ms, [&] { motors.stop(); }, {.name = "commands"});
//   ... on each command: commands.feed();
//
// What the action throws is reported on `core.errors()`. Throws
// Errc::invalid_argument for a deadline that is not positive;
// Errc::stopped when the core is gone.
template <Medium M, class F>
  requires std::invocable<F&>
[[nodiscard]] Watchdog watchdog(M& core, Clock::duration deadline, F on_expired, WatchdogOptions options = {}) {
  if (deadline <= Clock::duration::zero())
    throw Failure{{Errc::invalid_argument, "watchdog '" + options.name + "': the deadline must be positive"}};
  auto runtime = core.runtime().lock();
  if (!runtime) throw Failure{{Errc::stopped, "watchdog '" + options.name + "': the core is gone"}};
  auto state = std::make_shared<detail::WatchdogState>(options.name, deadline);
  runtime->spawn([state, on_expired = std::move(on_expired), weak = core.runtime()](std::stop_token stop) mutable {
    {
      std::scoped_lock lock{state->mutex};
      state->thread = std::this_thread::get_id();
    }
    detail::run_watchdog(*state, on_expired, weak, stop);
    std::scoped_lock lock{state->mutex};
    state->done = true;
    state->done_cv.notify_all();
  });
  return Watchdog{std::move(state)};
}

}  // namespace prime
