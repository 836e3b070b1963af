// A subscriber's cursor: its slot taken and given back, and the rare paths
// of a take (a sample lost or damaged, a block publisher that stopped
// waiting). The take itself stays inline in cursor.hpp.
#include "prime/shm/detail/cursor.hpp"

#include <algorithm>

namespace prime::shm::detail {

Cursor::Cursor(std::shared_ptr<Topic> topic, std::size_t history, bool observer, std::atomic<std::uint32_t>* views)
    : topic_{std::move(topic)}, views_{views} {
  auto& h = topic_->header();
  const auto& g = topic_->geometry();
  by_cursor_ = !observer && topic_->overflow() == Overflow::block;
  max_held_ = g.max_held;
  // As many batches as samples it may hold, each sized when taken.
  batches_ = std::vector<TakenBatch>(observer ? 1 : g.max_held);
  for (std::uint32_t i = 0; i < batches_.size(); ++i) free_.push_back(i);
  live_.reserve(batches_.size());
  in_batch_.resize(g.chunk_count());
  const auto me = topic_->registry().me();
  const auto first = observer ? kSlots - 1 : 0;
  const auto end = observer ? kSlots : g.max_subscribers;
  for (int pass = 0; pass < 2 && slot_ == kNone; ++pass) {
    for (std::size_t i = first; i < end; ++i) {
      ParticipantId free = 0;
      if (h.subscribers[i].owner.compare_exchange_strong(free, me)) {
        slot_ = i;
        break;
      }
    }
    if (slot_ == kNone && topic_->reclaim_dead_subscribers() == 0) break;
  }
  if (slot_ == kNone)
    throw Failure{{Errc::too_many_subscribers, observer ? "topic '" + topic_->name() + "' is observed already"
                                                  : "topic '" + topic_->name() + "' has its maximum of " +
                                                        std::to_string(g.max_subscribers) + " subscribers"}};
  bit_ = 1ull << slot_;
  topic_->release_subscriber_holds(slot_);  // nothing of an earlier owner lingers
  h.subscribers[slot_].lagging.store(0);
  h.subscribers[slot_].kept_end.store(0);
  const auto head = h.head.load();
  const auto back = std::min<std::uint64_t>({history, g.capacity, head});
  next_ = head - back;
  acked_ = next_;
  ack_every_ = std::clamp<std::uint64_t>(g.capacity / 8, 1, 16);
  fences_.emplace(h, bit_);
  h.subscribers[slot_].cursor.store(next_, std::memory_order_seq_cst);
  covered_from_ = h.head.load(std::memory_order_seq_cst);
}

Cursor::~Cursor() {
  auto& slot = topic_->header().subscribers[slot_];
  slot.cursor.store(kNoCursor);
  // Views own the cursor jointly with the reader, so none is out by now.
  topic_->release_subscriber_holds(slot_);
  slot.lagging.store(0);
  slot.kept_end.store(0);
  fences_.reset();  // its bit in full_fences_wanted cleared for the slot's next owner
  slot.owner.store(0);
  topic_->wake_publisher();
}

bool Cursor::skip_overwritten() {
  const auto entry = topic_->ring(next_).load(std::memory_order_acquire);
  const auto head = topic_->header().head.load(std::memory_order_acquire);
  const auto capacity = topic_->geometry().capacity;
  const auto ahead = RingEntry::ahead(entry, next_);
  const auto seq = next_ + static_cast<std::uint64_t>(ahead);
  if ((ahead == 0 && RingEntry::chunk(entry) != kNoChunk && !topic_->places().names_chunk(entry)) ||
      (ahead > 0 && (static_cast<std::uint64_t>(ahead) % capacity != 0 || (seq >= head && seq - head >= capacity))))
    note_damage(entry, ahead, head);
  const auto to = std::max(next_ + 1, head > capacity ? head - capacity : 0);
  if (to > head) {
    note_damage(entry, ahead, head);
    return false;
  }
  skip_to(to);
  return true;
}

void Cursor::note_damage(std::uint64_t entry, std::int64_t ahead, std::uint64_t head) {
  if (damage_) return;
  damage_ = Error{Errc::damaged, "topic '" + topic_->name() + "': its shared memory is damaged (the ring entry for sample " +
                                     std::to_string(next_) + " names sample " + std::to_string(next_ + ahead) +
                                     " in chunk " + std::to_string(RingEntry::chunk(entry)) + ", with " +
                                     std::to_string(head) + " published); passed over"};
}

void Cursor::sort_out_holds_for_lagging() noexcept {
  passed_over_ = true;
  std::fill(in_batch_.begin(), in_batch_.end(), false);
  for (const auto i : live_) {
    batches_[i].pinned = true;
    for (const auto c : batches_[i].chunks) in_batch_[c] = true;
  }
  for (std::uint32_t c = 0; c < in_batch_.size(); ++c)
    if (!in_batch_[c] && (topic_->chunk(c).holders.load(std::memory_order_acquire) & bit_) != 0 &&
        views_[c].load(std::memory_order_acquire) == 0)
      release(c);
}

}  // namespace prime::shm::detail
