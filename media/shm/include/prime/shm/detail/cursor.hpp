#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/asymmetric_fence.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/prefetch.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// A sample taken by a subscriber: its chunk, held by the subscriber's bit
// until released.
struct Taken {
  std::uint32_t chunk;
  std::uint64_t seq;
};

// One subscriber slot's cursor over a topic.
//
// Not thread-safe: one thread at a time takes; releasing is thread-safe.
class Cursor {
 public:
  // Takes a free subscriber slot, or (`observer`) the slot kept for tools,
  // whose cursor no `block` publisher ever waits for.
  Cursor(std::shared_ptr<Topic> topic, std::size_t history, bool observer = false) : topic_{std::move(topic)} {
    auto& h = topic_->header();
    const auto me = topic_->registry().me();
    const auto first = observer ? kSlots - 1 : 0;
    const auto end = observer ? kSlots : h.max_subscribers;
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
      throw Failure{{Errc::limit_exceeded, observer ? "topic '" + topic_->name() + "' is observed already"
                                                    : "topic '" + topic_->name() + "' has its maximum of " +
                                                          std::to_string(h.max_subscribers) + " subscribers"}};
    bit_ = 1ull << slot_;
    topic_->release_subscriber_holds(slot_);  // nothing of an earlier owner lingers
    h.subscribers[slot_].lagging.store(0);
    const auto head = h.head.load();
    const auto back = std::min<std::uint64_t>({history, h.capacity, head});
    next_ = head - back;
    acked_ = next_;
    ack_every_ = std::clamp<std::uint64_t>(h.capacity / 8, 1, 16);
    // The slot's bit in full_fences_wanted is clear: whoever freed the slot
    // (the destructor, or reclaim_subscriber) cleared it.
    if (!heavy_fences_allowed()) ask_for_full_fences(Clock::now());
    h.subscribers[slot_].cursor.store(next_, std::memory_order_seq_cst);
  }
  Cursor(const Cursor&) = delete;
  Cursor& operator=(const Cursor&) = delete;
  ~Cursor() {
    auto& slot = topic_->header().subscribers[slot_];
    slot.cursor.store(kNoCursor);
    // Views own the cursor jointly with the reader, so none is out by now.
    topic_->release_subscriber_holds(slot_);
    slot.lagging.store(0);
    topic_->header().full_fences_wanted.fetch_and(~bit_);
    slot.owner.store(0);
    topic_->wake_publisher();
  }

  [[nodiscard]] const std::shared_ptr<Topic>& topic() const noexcept { return topic_; }
  [[nodiscard]] std::uint64_t bit() const noexcept { return bit_; }

  // The next sample, if one is published and unread. Looks at one ring
  // entry (one cache line) when none is.
  std::optional<Taken> try_take() {
    auto& h = topic_->header();
    while (true) {
      const auto entry = topic_->ring(next_).load(std::memory_order_acquire);
      const auto ahead = RingEntry::ahead(entry, next_);
      if (ahead < 0) {
        caught_up();
        acknowledge();
        return std::nullopt;
      }
      if (ahead == 0) {
        const auto index = RingEntry::chunk(entry);
        auto& chunk = topic_->chunk(index);
        __builtin_prefetch(topic_->payload(index));  // arrives while the hold is taken
        chunk.holders.fetch_or(bit_, std::memory_order_seq_cst);
        if (chunk.seq.load(std::memory_order_seq_cst) == next_) {
          const Taken taken{index, next_};
          advance(next_ + 1);
          return taken;
        }
        chunk.holders.fetch_and(~bit_);
      }
      // Overwritten before we took it: lost to us. Skip to the oldest still
      // in the ring.
      const auto head = h.head.load(std::memory_order_acquire);
      skip_to(std::max(next_ + 1, head > h.capacity ? head - h.capacity : 0));
    }
  }

  // Up to `max` samples, appended to `out`, with one store of the cursor for
  // them all; how many. A sample overwritten before it was taken ends the
  // batch, and the next take skips what was lost.
  //
  // In two passes: the ring entries of what is out first, each chunk's
  // header line fetched for writing and its payload for reading as it is
  // found, then the holds. So the lines travel from the publisher together,
  // not one after another, each hold waiting for its own.
  std::size_t take_some(std::size_t max, std::vector<Taken>& out) {
    if (max == 0) return 0;
    const auto first = out.size();
    for (auto seq = next_; seq - next_ < max; ++seq) {
      const auto entry = topic_->ring(seq).load(std::memory_order_acquire);
      if (RingEntry::ahead(entry, seq) != 0) break;
      const auto index = RingEntry::chunk(entry);
      prefetch_for_write(&topic_->chunk(index));
      __builtin_prefetch(topic_->payload(index));
      out.push_back({index, seq});
    }
    for (auto i = first; i < out.size(); ++i) {
      auto& chunk = topic_->chunk(out[i].chunk);
      chunk.holders.fetch_or(bit_, std::memory_order_seq_cst);
      if (chunk.seq.load(std::memory_order_seq_cst) != out[i].seq) {
        chunk.holders.fetch_and(~bit_);
        out.resize(i);  // later ones are not held yet
        break;
      }
    }
    if (out.size() != first) {
      const auto seq = out.back().seq + 1;
      const auto n = seq - next_;
      advance(seq);
      // Read everything published: a subscriber passed over is waited for
      // again, and the publisher learns how far it is.
      if (RingEntry::ahead(topic_->ring(seq).load(std::memory_order_acquire), seq) < 0) {
        caught_up();
        acknowledge();
      }
      return n;
    }
    auto taken = try_take();  // nothing in order: the single take skips a loss or notes it has caught up
    if (!taken) return 0;
    out.push_back(*taken);
    return 1;
  }

  // Moves on to the newest sample published, passing over the older unread
  // ones (read past, not lost): for a reader that wants only the latest.
  void skip_to_newest() {
    const auto head = topic_->header().head.load(std::memory_order_acquire);
    if (head > next_ + 1) advance(head - 1);
  }

  // Whether the next sample (or a later one) is out: the ring entry, for a
  // busy poll...
  [[nodiscard]] bool ready() const noexcept {
    return RingEntry::ahead(topic_->ring(next_).load(std::memory_order_acquire), next_) >= 0;
  }
  // ...and the head, for a sleeper: the publisher stores it before it looks
  // for sleepers (see sleep_until).
  [[nodiscard]] bool available() const noexcept {
    return topic_->header().head.load(std::memory_order_seq_cst) > next_;
  }

  // Sleeps on the topic's doorbell until a sample is out, `until`, a ring, or
  // `woken()` (a stop). A publisher orders its head store before its look
  // for sleepers by a full fence, or by a light one (PublishFence::light):
  // then the heavy half runs here, between raising this subscriber's bit and
  // its last look at the head.
  template <class Woken>
  void sleep_until(Woken&& woken, Clock::time_point until) {
    topic_->header().data.sleep_until(
        bit_, [&] { return available() || woken(); }, until, [&] { return fence_before_sleep(); });
  }

  void release(std::uint32_t chunk) const noexcept { topic_->chunk(chunk).holders.fetch_and(~bit_); }

  // Tells the publisher how far this subscriber has read, and wakes it if it
  // waits for that. A reader does so before it waits (for a sample or for
  // room in its budget), when it finds it has read everything, and every
  // ack_every_ samples in between.
  void acknowledge() noexcept {
    if (acked_ == next_) return;
    acked_ = next_;
    auto& h = topic_->header();
    h.subscribers[slot_].cursor.store(next_, std::memory_order_seq_cst);
    if (next_ >= h.space_wanted.load(std::memory_order_seq_cst)) topic_->wake_publisher();
  }

  [[nodiscard]] std::uint64_t lost() const noexcept { return lost_; }

 private:
  static constexpr std::size_t kNone = ~std::size_t{0};

  void skip_to(std::uint64_t seq) {
    lost_ += seq - next_;
    advance(seq);
  }
  // The cursor in shared memory follows in steps (acknowledge): one store
  // per step, not per sample, on the line the publisher reads to learn
  // whether it has room. A publisher waiting for this subscriber is woken
  // at once (space_wanted is on a line of its own, rarely written).
  void advance(std::uint64_t seq) {
    next_ = seq;
    if (next_ - acked_ >= ack_every_ ||
        next_ >= topic_->header().space_wanted.load(std::memory_order_relaxed))
      acknowledge();
  }
  // The heavy half of the fence before a sleep, when the publisher fences
  // lightly; how long the sleep may last. It interrupts every CPU running a
  // process that publishes lightly, so a subscriber runs at most
  // kHeavyPerWindow of them per kWindow: one that sleeps more often than
  // that asks the publisher for full fences instead (as one refused
  // membarrier does for good), until it sleeps less again.
  Clock::time_point fence_before_sleep() {
    const auto now = Clock::now();
    if (now >= window_end_) {
      if (full_fences_asked_ && !refused_ && sleeps_ < kHeavyPerWindow / 2) stop_asking_for_full_fences();
      window_end_ = now + kWindow;
      sleeps_ = 0;
    }
    ++sleeps_;
    if (topic_->header().light_publisher.load(std::memory_order_seq_cst) != 0 && !full_fences_asked_) {
      if (sleeps_ <= kHeavyPerWindow && heavy_fence()) return Clock::time_point::max();
      ask_for_full_fences(now);
    }
    return now < slices_until_ ? now + kSlice : Clock::time_point::max();
  }
  // A publish under way may have looked at the bits before this one was
  // raised, and fenced lightly: one heavy fence covers it. Where the system
  // refuses that, sleeps are cut into slices for a while instead: a publish
  // it missed is seen a slice later.
  void ask_for_full_fences(Clock::time_point now) {
    topic_->header().full_fences_wanted.fetch_or(bit_, std::memory_order_seq_cst);
    full_fences_asked_ = true;
    if (refused_ || !heavy_fence()) {
      refused_ = true;
      slices_until_ = now + kSlicesFor;
    }
  }
  void stop_asking_for_full_fences() {
    topic_->header().full_fences_wanted.fetch_and(~bit_, std::memory_order_seq_cst);
    full_fences_asked_ = false;
  }

  // A subscriber the publisher stopped waiting for is waited for again once
  // it has read everything.
  void caught_up() {
    auto& lagging = topic_->header().subscribers[slot_].lagging;
    if (lagging.load(std::memory_order_relaxed) != 0) lagging.store(0);
  }

  std::shared_ptr<Topic> topic_;
  std::size_t slot_ = kNone;
  std::uint64_t bit_ = 0;
  std::uint64_t next_ = 0;
  std::uint64_t acked_ = 0;  // the cursor the publisher sees
  // Samples read between two acknowledgements at most: an eighth of the
  // ring, up to 16. A reader that stops half-way between two costs a
  // `block` publisher at most that much of the ring.
  std::uint64_t ack_every_ = 1;
  std::uint64_t lost_ = 0;
  // Sleeps in the current window, and whether this subscriber asked for
  // full fences (for good once membarrier was refused).
  static constexpr auto kWindow = std::chrono::milliseconds{100};
  static constexpr std::uint32_t kHeavyPerWindow = 100;
  Clock::time_point window_end_{};
  std::uint32_t sleeps_ = 0;
  bool full_fences_asked_ = false;
  bool refused_ = false;
  static constexpr auto kSlice = std::chrono::milliseconds{1};
  static constexpr auto kSlicesFor = std::chrono::milliseconds{100};
  Clock::time_point slices_until_{};
};

}  // namespace prime::shm::detail
