// A publisher taking over a topic whose publisher died.
#include "recovery.hpp"

#include <algorithm>
#include <cstdint>
#include <vector>

#include "prime/shm/detail/layout.hpp"

namespace prime::shm::detail {

void recover_from_dead_publisher(Topic& topic) {
  auto& h = topic.header();
  const auto& g = topic.geometry();
  std::vector<bool> in_ring(g.chunk_count(), false);
  const auto head = h.head.load();
  auto last = head;
  for (std::uint64_t i = 0; i < g.capacity; ++i) {
    const auto entry = topic.ring(i).load();
    if (!topic.places().names_chunk(entry)) continue;
    in_ring[RingEntry::chunk(entry)] = true;
    // An entry stored after the last head store (at most a batch on).
    if (const auto ahead = RingEntry::ahead(entry, head); ahead >= 0)
      last = std::max(last, head + static_cast<std::uint64_t>(ahead) + 1);
  }
  for (std::uint32_t c = 0; c < g.chunk_count(); ++c) {
    auto& chunk = topic.chunk(c);
    if (in_ring[c]) chunk.holders.fetch_or(kPublisherBit);
    else chunk.holders.fetch_and(~kPublisherBit);
  }
  h.head.store(last);
  // A subscriber it died setting holds for (BackPressure::give_up_on_laggards)
  // sorts out the ones it set.
  for (auto& slot : h.subscribers) {
    auto pinning = kPinning;
    slot.lagging.compare_exchange_strong(pinning, kPassedOver);
  }
  h.space_wanted.store(~0ull);
  h.space.forget(kPublisherSleeper);  // it may have died asleep, waiting for room
}

}  // namespace prime::shm::detail
