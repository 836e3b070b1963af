#pragma once

#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <climits>
#include <cstdint>
#include <ctime>

namespace prime::shm::detail {

static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t), "a futex word is a plain 32-bit word");

// Sleeps while `word` holds `expected`, until woken or `until` (steady_clock,
// which is CLOCK_MONOTONIC: the same clock in every process). The word may
// live in shared memory, so this is the process-shared (not FUTEX_PRIVATE) form.
inline void futex_wait(std::atomic<std::uint32_t>& word, std::uint32_t expected,
                       std::chrono::steady_clock::time_point until) {
  timespec at{};
  timespec* deadline = nullptr;
  if (until != std::chrono::steady_clock::time_point::max()) {
    const auto since = until.time_since_epoch();
    const auto s = std::chrono::duration_cast<std::chrono::seconds>(since);
    at = {static_cast<time_t>(s.count()), static_cast<long>(std::chrono::nanoseconds{since - s}.count())};
    deadline = &at;
  }
  // An absolute CLOCK_MONOTONIC deadline: a sleep interrupted and resumed does not drift.
  ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAIT_BITSET, expected, deadline, nullptr,
            FUTEX_BITSET_MATCH_ANY);
}

// Wakes every sleeper on `word`; returns how many there were.
inline long futex_wake_all(std::atomic<std::uint32_t>& word) {
  return ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAKE, INT_MAX, nullptr, nullptr, 0);
}

// A futex word with one bit per party that may sleep on it, so a waker pays
// for a system call only when someone may be asleep. A sleeper raises its bit
// before it checks its condition a last time; the waker changes the condition
// before it looks at the bits: one of the two always sees the other (both
// seq_cst, or an asymmetric fence). The bits name who sleeps, so a sleeper
// that died asleep is forgotten by clearing its bit: it cannot tax every
// later ring.
//
// Thread-safe; lives in shared memory (plain words, no pointers).
struct alignas(64) Doorbell {
  std::atomic<std::uint32_t> word{0};
  std::atomic<std::uint64_t> sleepers{0};

  // Sleeps as `bit` until `ready()`, `until` or a ring; returns ready().
  // `fence` runs between raising the bit and the last look, for a waker that
  // fences lightly (asymmetric_fence.hpp); it returns how long the sleep may
  // last at most (shorter when it could not fence: a ring may be missed).
  template <class Ready, class Fence = decltype([] { return std::chrono::steady_clock::time_point::max(); })>
  bool sleep_until(std::uint64_t bit, Ready&& ready, std::chrono::steady_clock::time_point until, Fence&& fence = {}) {
    sleepers.fetch_or(bit, std::memory_order_seq_cst);
    const auto seen = word.load(std::memory_order_seq_cst);
    until = std::min(until, fence());
    bool ok = ready();
    if (!ok && std::chrono::steady_clock::now() < until) {
      futex_wait(word, seen, until);
      ok = ready();
    }
    sleepers.fetch_and(~bit, std::memory_order_seq_cst);
    return ok;
  }

  // Wakes every sleeper. Returns how many the kernel woke, or -1 when no bit
  // was raised (one load, no system call).
  long ring() {
    if (sleepers.load(std::memory_order_seq_cst) == 0) return -1;
    word.fetch_add(1, std::memory_order_seq_cst);
    return futex_wake_all(word);
  }

  // Wakes whoever sleeps, whatever the bits say: for a stop request.
  void ring_always() {
    word.fetch_add(1, std::memory_order_seq_cst);
    futex_wake_all(word);
  }

  // Forgets sleepers found dead.
  void forget(std::uint64_t bits) { sleepers.fetch_and(~bits, std::memory_order_seq_cst); }
};

// Rings that woke nobody although a bit was raised happen when a sleeper is
// between raising its bit and sleeping, or is dead. After this many in a row
// the waker checks for the dead.
inline constexpr int kIdleRingsBeforeCheck = 16;

}  // namespace prime::shm::detail
