#pragma once

#include <algorithm>
#include <chrono>
#include <optional>
#include <stop_token>
#include <thread>
#include <utility>

#include "prime/logic/sample.hpp"

namespace prime::detail {

// Tells the core this thread is busy-waiting: frees the sibling hyperthread
// and eases the memory system's look at the watched line.
inline void cpu_relax() noexcept {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

// `ready` for spin_then_sleep that every 64th look also yields the core. On a
// machine with fewer cores than busy threads, a thread spinning on its core
// may keep the very thread (of this process or another) it waits for from
// running: two Shm readers sharing a core, or two services' workers, the
// second waiting for the first's hand-over. A yield with no one else to run
// returns at once.
template <class Ready>
[[nodiscard]] auto yielding(Ready ready) {
  return [ready = std::move(ready), looks = 0u]() mutable {
    if (++looks % 64 == 0) std::this_thread::yield();
    return ready();
  };
}

enum class Waited { ready, timeout, stopped };

// How every medium waits: polls `ready()` for `spin` (a value due within
// microseconds then costs no wake-up call), then sleeps by calling
// `sleep(until)` — which returns when woken, at `until`, or for no reason —
// and looks again, until `ready()`, `deadline` or a stop request. `sleep`
// must not sleep through a stop request (ring the sleeper from a
// stop_callback, or use a stop-aware wait).
// `now`: the time the caller read last, if it has it (a clock read saved).
template <class Ready, class Sleep>
Waited spin_then_sleep(Ready&& ready, Sleep&& sleep, std::chrono::nanoseconds spin, Clock::time_point deadline,
                       const std::stop_token& stop, std::optional<Clock::time_point> now = std::nullopt) {
  if (ready()) return Waited::ready;
  if (spin > std::chrono::nanoseconds::zero()) {
    const auto until = std::min(deadline, (now ? *now : Clock::now()) + spin);
    do {
      for (int i = 0; i < 64; ++i) {  // a clock read costs more than a look
        if (ready()) return Waited::ready;
        cpu_relax();
      }
    } while (Clock::now() < until && !stop.stop_requested());
  }
  while (true) {
    if (ready()) return Waited::ready;
    if (stop.stop_requested()) return Waited::stopped;
    if (Clock::now() >= deadline) return Waited::timeout;
    sleep(deadline);
  }
}

}  // namespace prime::detail
