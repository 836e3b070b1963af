// A `block` publisher giving up on subscribers that took nothing for its
// block timeout (the wait itself stays inline in back_pressure.hpp).
#include "prime/shm/detail/back_pressure.hpp"

#include <algorithm>
#include <string>

namespace prime::shm::detail {

void BackPressure::give_up_on_laggards(std::uint64_t needed, std::uint64_t next, std::span<const std::uint32_t> in_ring) {
  auto& h = topic_->header();
  const auto& g = topic_->geometry();
  for (std::size_t i = 0; i < g.max_subscribers; ++i) {
    auto& slot = h.subscribers[i];
    if (slot.cursor.load() >= needed || slot.lagging.load() != kWaitedFor) continue;
    slot.lagging.store(kPinning, std::memory_order_seq_cst);
    const auto from = slot.cursor.load(std::memory_order_seq_cst);
    const auto to = slot.kept_end.load(std::memory_order_seq_cst);
    if (from != kNoCursor)
      for (auto seq = std::max(from, next > g.capacity ? next - g.capacity : 0); seq < std::min(to, next); ++seq)
        if (const auto chunk = in_ring[topic_->ring_index(seq)]; chunk != kNoChunk)
          topic_->chunk(chunk).holders.fetch_or(1ull << i, std::memory_order_seq_cst);
    slot.lagging.store(kPassedOver, std::memory_order_seq_cst);
    if (report_)
      report_(Error{Errc::overflow, "topic '" + topic_->name() + "': subscriber " +
                                        topic_->registry().describe(slot.owner.load()) + " read nothing for " +
                                        std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(block_timeout_).count()) +
                                        " ms; the publisher stops waiting for it until it catches up, and it loses "
                                        "what is overwritten before it reads it"});
  }
  look_again(next);
}

void BackPressure::wait_for_room_slowly(std::uint64_t after, std::uint64_t next, std::span<const std::uint32_t> in_ring) {
  auto& h = topic_->header();
  const auto& g = topic_->geometry();
  const auto needed = after + 1 - g.capacity;  // every waited-for subscriber must have taken this
  // Capped at next: a subscriber joining from now on starts at or after it.
  auto room = [&] { return (min_cursor_ = std::min(slowest(), next)) >= needed; };
  // Asleep, wait for half a ring of room, not one slot: then the publisher
  // and a subscriber that keeps up take turns by the half ring, not by the
  // sample, and wake each other rarely.
  const auto wanted = std::min(needed + g.capacity / 2, next);
  auto plenty = [&] { return (min_cursor_ = std::min(slowest(), next)) >= wanted; };
  auto next_check = Clock::now();
  auto sleep = [&](Clock::time_point until) {
    if (Clock::now() >= next_check) {  // a subscriber that died holds no one up
      topic_->reclaim_dead_subscribers();
      next_check = Clock::now() + std::chrono::milliseconds{10};
    }
    h.space_wanted.store(wanted, std::memory_order_seq_cst);
    h.space.sleep_until(kPublisherSleeper, plenty, std::min(until, next_check));
    h.space_wanted.store(~0ull, std::memory_order_relaxed);
  };
  const auto waited = prime::detail::spin_then_sleep(prime::detail::yielding(room), sleep, std::chrono::microseconds{50},
                                                     deadline_after(block_timeout_), std::stop_token{});
  if (waited == prime::detail::Waited::ready) return;
  give_up_on_laggards(needed, next, in_ring);
}

}  // namespace prime::shm::detail
