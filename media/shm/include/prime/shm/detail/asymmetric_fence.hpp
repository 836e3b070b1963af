#pragma once

#include <linux/membarrier.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>

namespace prime::shm::detail {

// An asymmetric fence, for a handshake where one side runs on every sample
// and the other rarely: a publisher stores the head, then looks for sleeping
// subscribers' bits; a subscriber about to sleep raises its bit, then looks
// at the head. One of the two must see the other's store. With a full fence
// on each side, every publish waits for its stores to reach the other CPU
// (the head's, and the ring entry's before it, on the line a busy
// subscriber polls): a cache-line transfer per sample. Instead the publisher
// only keeps the compiler from reordering (light), and the sleeper, before
// its last look, makes every CPU running a registered process pass a full
// fence (heavy: membarrier, an interrupt to each, a few microseconds). Either
// the publisher looked for sleepers before that fence, and its head store
// has been drained by it, or after it, and sees the bit.
//
// The interrupt reaches every CPU running any registered process, not only
// the topic's publisher: so only publishers that opt in register
// (PublishFence::light), and each sleeper bounds its heavy fences (cursor.hpp).

// Heavy fences this process asked for, for tests that bound them.
inline std::atomic<std::uint64_t> heavy_fences{0};

// Whether this process may use the light half: it is registered for the
// heavy half's interrupts (Linux 4.16). Registers on the first call.
inline bool light_fences() noexcept {
  static const bool registered = ::syscall(SYS_membarrier, MEMBARRIER_CMD_REGISTER_GLOBAL_EXPEDITED, 0, 0) == 0;
  return registered;
}

// Whether this process may ask for heavy fences, without asking for one
// (which would interrupt other CPUs). Asked once.
inline bool heavy_fences_allowed() noexcept {
  static const bool allowed = [] {
    const auto commands = ::syscall(SYS_membarrier, MEMBARRIER_CMD_QUERY, 0, 0);
    return commands > 0 && (commands & MEMBARRIER_CMD_GLOBAL_EXPEDITED) != 0;
  }();
  return allowed;
}

// The light half, between the store and the load.
inline void light_fence() noexcept { std::atomic_signal_fence(std::memory_order_seq_cst); }

// The heavy half, between the store and the load. False where the system
// refuses it (a seccomp filter, as a container's may; a kernel before 4.16):
// the other side must then fence fully.
inline bool heavy_fence() noexcept {
  heavy_fences.fetch_add(1, std::memory_order_relaxed);
  return ::syscall(SYS_membarrier, MEMBARRIER_CMD_GLOBAL_EXPEDITED, 0, 0) == 0;
}

}  // namespace prime::shm::detail
