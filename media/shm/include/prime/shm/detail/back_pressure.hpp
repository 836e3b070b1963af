#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <stop_token>
#include <string>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/topic.hpp"
#include "prime/topology/detail/wait.hpp"

namespace prime::shm::detail {

// A `block` publisher's wait for its subscribers: a sample is published
// over an older one only once every subscriber it waits for has taken that.
// A subscriber that takes nothing for `block_timeout` is reported once and
// passed over from then on, like a drop_oldest reader, until it catches up.
//
// Not thread-safe: the publisher's thread.
class BackPressure {
 public:
  // `report` hears of each subscriber the publisher stops waiting for.
  BackPressure(Topic& topic, std::chrono::nanoseconds block_timeout, std::function<void(Error)> report)
      : topic_{&topic}, block_timeout_{block_timeout}, report_{std::move(report)} {}

  // How many samples from sequence `after` on may be published now without
  // waiting, as of the last look at the cursors; look_again takes a fresh
  // one (the publisher has published up to `next`).
  [[nodiscard]] std::uint64_t room_after(std::uint64_t after) const noexcept {
    const auto capacity = topic_->geometry().capacity;
    return min_cursor_ + capacity > after ? min_cursor_ + capacity - after : 0;
  }
  void look_again(std::uint64_t next) noexcept { min_cursor_ = std::min(slowest(), next); }

  // Room for sample `after` (the publisher has published up to `next`, and
  // `in_ring` says what chunk each ring entry names): waits, spinning then
  // asleep, until the subscribers it waits for have taken what it
  // overwrites, or gives up on those that took nothing for the block
  // timeout.
  void wait_for_room(std::uint64_t after, std::uint64_t next, std::span<const std::uint32_t> in_ring) {
    const auto capacity = topic_->geometry().capacity;
    if (after < capacity || min_cursor_ >= after + 1 - capacity) return;  // room known already: no call
    wait_for_room_slowly(after, next, in_ring);
  }

 private:
  // The slowest cursor among subscribers this publisher waits for: not the
  // observer's, not those it gave up on, not those joining or gone.
  //
  // Fenced after the head store (a light publisher's is a release): a
  // subscriber joining, or waited for again, stores its cursor and then
  // reads the head, and lets its cursor keep only samples from there on
  // (Cursor::covers). Either this look sees its cursor, or that read sees
  // a head no earlier than this publisher's: nothing the cursor keeps is
  // overwritten on the strength of a look that missed it.
  [[nodiscard]] std::uint64_t slowest() const noexcept {
    auto& h = topic_->header();
    const auto& g = topic_->geometry();
    std::atomic_thread_fence(std::memory_order_seq_cst);
    auto min = ~0ull;
    for (std::size_t i = 0; i < g.max_subscribers; ++i) {
      const auto& slot = h.subscribers[i];
      const auto cursor = slot.cursor.load(std::memory_order_acquire);
      if (cursor < min && slot.lagging.load(std::memory_order_relaxed) == kWaitedFor) min = cursor;
    }
    return min;
  }

  // Every subscriber still short of `needed` read nothing for the block
  // timeout: reported once each, then passed over until it catches up (it
  // then loses what is overwritten before it reads it, and its lost() says so).
  //
  // Its cursor kept the batches it has out (Cursor) from being overwritten:
  // from now on, its bit does, on the chunks from its cursor to its
  // kept_end (where such batches lie). Both are read after `lagging` is
  // set, so they are no earlier than any the subscriber stored before it
  // last saw the flag clear; the holds are in place before the flag says
  // kPassedOver, when the subscriber lets go of those it does not need.
  void give_up_on_laggards(std::uint64_t needed, std::uint64_t next, std::span<const std::uint32_t> in_ring);

  // wait_for_room when the last look at the cursors does not show room.
  void wait_for_room_slowly(std::uint64_t after, std::uint64_t next, std::span<const std::uint32_t> in_ring);

  Topic* topic_;
  std::chrono::nanoseconds block_timeout_;
  std::function<void(Error)> report_;
  std::uint64_t min_cursor_ = 0;  // the slowest subscriber's cursor when last looked at
};

}  // namespace prime::shm::detail
