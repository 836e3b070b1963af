// A topic's publisher taking the topic over, after a dead one where that
// one stopped, and letting it go. Loans and publishes stay inline in
// writer.hpp.
#include "prime/shm/detail/writer.hpp"

#include "recovery.hpp"

namespace prime::shm::detail {

Writer::Writer(std::shared_ptr<Topic> topic, std::chrono::nanoseconds block_timeout, bool light,
               std::function<void(Error)> report)
    : topic_{std::move(topic)},
      me_{topic_->registry().me()},
      light_{light && light_fences()},
      pool_{topic_->places(), topic_->geometry().capacity},
      back_pressure_{*topic_, block_timeout, std::move(report)} {
  auto& h = topic_->header();
  const auto& g = topic_->geometry();
  auto current = h.publisher.load();
  while (true) {
    if (current != 0 && topic_->registry().alive(current))
      throw Failure{{Errc::in_use, "topic '" + topic_->name() + "' already has a publisher: " +
                                       topic_->registry().describe(current)}};
    if (h.publisher.compare_exchange_strong(current, me_)) break;
  }
  if (current != 0) recover_from_dead_publisher(*topic_);  // its loans and half-done publish
  h.block_timeout_ns.store(block_timeout.count());
  // Before any light store: a subscriber that then raises its sleeper bit
  // and reads this clear is seen by every later look for sleepers.
  h.light_publisher.store(light_ ? 1 : 0, std::memory_order_seq_cst);
  next_ = h.head.load();
  in_ring_.resize(g.capacity);
  for (std::uint64_t i = 0; i < g.capacity; ++i) {
    const auto entry = topic_->ring(i).load();
    in_ring_[i] = topic_->places().names_chunk(entry) ? RingEntry::chunk(entry) : kNoChunk;
  }
}

Writer::~Writer() {
  pool_.give_back();
  // After the last light store, which this seq_cst store makes visible first.
  topic_->header().light_publisher.store(0, std::memory_order_seq_cst);
  auto expected = me_;
  topic_->header().publisher.compare_exchange_strong(expected, 0);
}

}  // namespace prime::shm::detail
