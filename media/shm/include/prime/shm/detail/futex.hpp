#pragma once

#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <climits>
#include <cstdint>
#include <ctime>

namespace prime::shm::detail {

static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t), "a futex word is a plain 32-bit word");

// Sleeps while `word` holds `expected`, for at most `timeout`. The word lives in
// shared memory, so this is the process-shared (not FUTEX_PRIVATE) form.
inline void futex_wait(std::atomic<std::uint32_t>& word, std::uint32_t expected, std::chrono::nanoseconds timeout) {
  if (timeout <= std::chrono::nanoseconds::zero()) return;
  const auto s = std::chrono::duration_cast<std::chrono::seconds>(timeout);
  timespec ts{static_cast<time_t>(s.count()), static_cast<long>((timeout - s).count())};
  ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAIT, expected, &ts, nullptr, 0);
}

inline void futex_wake_all(std::atomic<std::uint32_t>& word) {
  ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAKE, INT_MAX, nullptr, nullptr, 0);
}

// A futex word with a count of sleepers, so that a writer pays for a wake-up
// call only when someone sleeps. A sleeper announces itself before it checks
// its condition a last time; the waker changes the condition before it looks
// for sleepers: one of the two always sees the other (both use seq_cst).
struct alignas(64) Doorbell {
  std::atomic<std::uint32_t> word{0};
  std::atomic<std::uint32_t> sleepers{0};

  // Sleeps until `ready()` or `until`, or a ring; returns ready().
  template <class Ready>
  bool sleep_until(Ready ready, std::chrono::steady_clock::time_point until) {
    sleepers.fetch_add(1, std::memory_order_seq_cst);
    const auto seen = word.load(std::memory_order_seq_cst);
    bool ok = ready();
    if (!ok) {
      futex_wait(word, seen, until - std::chrono::steady_clock::now());
      ok = ready();
    }
    sleepers.fetch_sub(1, std::memory_order_seq_cst);
    return ok;
  }

  // Wakes every sleeper; costs one load when there is none.
  void ring() {
    if (sleepers.load(std::memory_order_seq_cst) == 0) return;
    word.fetch_add(1, std::memory_order_seq_cst);
    futex_wake_all(word);
  }
};

}  // namespace prime::shm::detail
