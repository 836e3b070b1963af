#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>

#include "prime/logic/sample.hpp"
#include "prime/shm/detail/asymmetric_fence.hpp"
#include "prime/shm/detail/layout.hpp"

namespace prime::shm::detail {

// A subscriber's half of its publisher's head fence, before it sleeps.
//
// A publisher orders its head store before its look for sleepers by a full
// fence, or by a light one (PublishFence::light): then the heavy half runs
// here, between raising the subscriber's sleeper bit and its last look at
// the head. It interrupts every CPU running a process that publishes
// lightly, so a subscriber runs at most kHeavyPerWindow of them per
// kWindow: one that sleeps more often than that asks the publisher for full
// fences instead (as one refused membarrier does for good), until it sleeps
// less again. Where the system refuses the heavy fence, sleeps are cut into
// slices for a while instead: a publish it missed is seen a slice later.
//
// Not thread-safe: the subscriber's taking thread.
class SleepFences {
 public:
  // For the subscriber of `bit`, whose bit in full_fences_wanted is clear
  // (whoever freed its slot cleared it).
  SleepFences(TopicHeader& header, std::uint64_t bit) : header_{&header}, bit_{bit} {
    if (!heavy_fences_allowed()) ask_for_full_fences(Clock::now());
  }
  SleepFences(const SleepFences&) = delete;
  SleepFences& operator=(const SleepFences&) = delete;
  ~SleepFences() { header_->full_fences_wanted.fetch_and(~bit_); }

  // Runs the heavy half if the publisher fences lightly (or asks for full
  // fences); how long the sleep after it may last.
  Clock::time_point before_sleep() {
    const auto now = Clock::now();
    if (now >= window_end_) {
      if (full_fences_asked_ && !refused_ && sleeps_ < kHeavyPerWindow / 2) stop_asking_for_full_fences();
      window_end_ = now + kWindow;
      sleeps_ = 0;
    }
    ++sleeps_;
    if (header_->light_publisher.load(std::memory_order_seq_cst) != 0 && !full_fences_asked_) {
      if (sleeps_ <= kHeavyPerWindow && heavy_fence()) return Clock::time_point::max();
      ask_for_full_fences(now);
    }
    return now < slices_until_ ? now + kSlice : Clock::time_point::max();
  }

 private:
  // A publish under way may have looked at the bits before this one was
  // raised, and fenced lightly: one heavy fence covers it.
  void ask_for_full_fences(Clock::time_point now) {
    header_->full_fences_wanted.fetch_or(bit_, std::memory_order_seq_cst);
    full_fences_asked_ = true;
    if (refused_ || !heavy_fence()) {
      refused_ = true;
      slices_until_ = now + kSlicesFor;
    }
  }
  void stop_asking_for_full_fences() {
    header_->full_fences_wanted.fetch_and(~bit_, std::memory_order_seq_cst);
    full_fences_asked_ = false;
  }

  static constexpr auto kWindow = std::chrono::milliseconds{100};
  static constexpr std::uint32_t kHeavyPerWindow = 100;
  static constexpr auto kSlice = std::chrono::milliseconds{1};
  static constexpr auto kSlicesFor = std::chrono::milliseconds{100};

  TopicHeader* header_;
  std::uint64_t bit_;
  // Sleeps in the current window, and whether this subscriber asked for
  // full fences (for good once membarrier was refused).
  Clock::time_point window_end_{};
  std::uint32_t sleeps_ = 0;
  bool full_fences_asked_ = false;
  bool refused_ = false;
  Clock::time_point slices_until_{};
};

}  // namespace prime::shm::detail
