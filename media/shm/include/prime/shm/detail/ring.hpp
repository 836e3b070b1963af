#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/process.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// The publishing side of a topic: the one live publisher of it. A publisher
// that finds the previous one dead takes the topic over where it stopped.
//
// Not thread-safe: one thread at a time loans and publishes.
class Writer {
 public:
  // `report` hears of each subscriber that a `block` publisher stopped
  // waiting for.
  Writer(std::shared_ptr<Topic> topic, std::chrono::nanoseconds block_timeout, std::function<void(Error)> report)
      : topic_{std::move(topic)}, me_{this_process()}, block_timeout_{block_timeout}, report_{std::move(report)} {
    auto& h = topic_->header();
    auto current = h.publisher.load();
    while (true) {
      if (current != 0 && alive(current))
        throw Failure{{Errc::limit_exceeded, "topic '" + topic_->name() + "' already has a publisher: pid " +
                                                 std::to_string(pid_of(current))}};
      if (h.publisher.compare_exchange_strong(current, me_)) break;
    }
    if (current != 0) recover();  // the previous publisher died: its loans and half-done publish
    next_ = h.head.load();
  }
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;
  ~Writer() {
    if (ready_ != kNoChunk) discard(ready_);
    auto expected = me_;
    topic_->header().publisher.compare_exchange_strong(expected, 0);
  }

  [[nodiscard]] const std::shared_ptr<Topic>& topic() const noexcept { return topic_; }

  // A free chunk, held by this loan, once the ring has room for the next
  // sequence: at once under drop_oldest; under block, when every live
  // subscriber has taken the sample the next one overwrites. A subscriber
  // that takes nothing for `block_timeout` loses that oldest sample (it is
  // reported, and its lost() counts it), so a wedged subscriber slows the
  // publisher but never stops it, and a dead one is reclaimed.
  std::expected<std::uint32_t, Error> loan() {
    auto& h = topic_->header();
    if (static_cast<Overflow>(h.overflow) == Overflow::block) wait_for_room();
    if (ready_ != kNoChunk) return std::exchange(ready_, kNoChunk);
    for (int pass = 0; pass < 2; ++pass) {
      if (auto i = claim()) return *i;
      if (topic_->reclaim_dead_subscribers() == 0) break;
    }
    return std::unexpected(Error{Errc::limit_exceeded,
                                 "topic '" + topic_->name() + "': all " + std::to_string(h.chunk_count) +
                                     " chunks are in use; subscribers hold more than max_held (" +
                                     std::to_string(h.max_held) + ") samples each"});
  }

  // A free chunk, now held by this publisher, if there is one.
  std::optional<std::uint32_t> claim() noexcept {
    const auto count = topic_->header().chunk_count;
    for (std::uint64_t tried = 0; tried < count; ++tried) {
      const auto i = static_cast<std::uint32_t>(search_++ % count);
      std::uint64_t free = 0;
      if (topic_->chunk(i).holders.compare_exchange_strong(free, kLoanBit)) return i;
    }
    return std::nullopt;
  }

  // Hands a loaned chunk back unpublished.
  void discard(std::uint32_t chunk) noexcept { topic_->chunk(chunk).holders.fetch_and(~kLoanBit); }

  // Publishes the loaned `chunk` as the next sequence. Never waits.
  void publish(std::uint32_t chunk, std::size_t size, Clock::time_point stamp) noexcept {
    auto& h = topic_->header();
    auto& c = topic_->chunk(chunk);
    const auto seq = next_++;
    c.size = size;
    c.stamp = stamp.time_since_epoch().count();
    c.seq.store(seq, std::memory_order_release);
    c.holders.fetch_xor(kRingBit | kLoanBit);  // from the loan to the ring in one step
    auto& entry = topic_->ring(seq);
    const auto old = RingEntry::chunk(entry.load(std::memory_order_relaxed));
    entry.store(RingEntry::pack(seq, chunk), std::memory_order_release);
    h.head.store(seq + 1, std::memory_order_seq_cst);
    if (old != kNoChunk) {
      auto& dropped = topic_->chunk(old);
      // Released by the fetch_and: a subscriber whose hold lands after it
      // sees the chunk no longer carries that sequence.
      dropped.seq.store(kNotPublished, std::memory_order_relaxed);
      dropped.holders.fetch_and(~kRingBit, std::memory_order_acq_rel);
    }
    h.data.ring();
    // Claim the next loan's chunk now, while subscribers read this one, and
    // fetch its lines for writing: the next loan then waits on no one.
    if (auto next = claim()) {
      ready_ = *next;
      __builtin_prefetch(&topic_->chunk(ready_), 1);
      __builtin_prefetch(topic_->payload(ready_), 1);
    }
  }

 private:
  void wait_for_room() {
    auto& h = topic_->header();
    if (next_ < h.capacity) return;
    const auto needed = next_ + 1 - h.capacity;  // every live subscriber must have taken this
    if (min_cursor_ >= needed) return;
    const auto deadline = Clock::now() + block_timeout_;
    const auto spin_until = std::min(deadline, Clock::now() + std::chrono::microseconds{50});
    // Capped at next_: a subscriber joining from now on starts at or after it.
    auto room = [&] { return (min_cursor_ = std::min(slowest(), next_)) >= needed; };
    while (Clock::now() < spin_until) {
      if (room()) return;
    }
    // Asleep, wait for half a ring of room, not one slot: then the publisher
    // and a subscriber that keeps up take turns by the half ring, not by the
    // sample, and wake each other rarely.
    const auto wanted = std::min(needed + h.capacity / 2, next_);
    auto plenty = [&] { return (min_cursor_ = std::min(slowest(), next_)) >= wanted; };
    auto next_check = Clock::now();
    bool woken = false;
    h.space_wanted.store(wanted, std::memory_order_seq_cst);
    while (!woken) {
      if (Clock::now() >= next_check) {  // a subscriber that died holds no one up
        topic_->reclaim_dead_subscribers();
        next_check = Clock::now() + std::chrono::milliseconds{10};
      }
      woken = h.space.sleep_until(plenty, std::min(deadline, next_check)) || room();
      if (!woken && Clock::now() >= deadline) break;
    }
    h.space_wanted.store(~0ull, std::memory_order_relaxed);
    if (woken) return;
    if (report_)
      report_(Error{Errc::overflow, "topic '" + topic_->name() + "': subscriber pid " + std::to_string(slowest_pid()) +
                                        " took nothing for " + std::to_string(block_timeout_.count() / 1'000'000) +
                                        " ms and loses its oldest sample"});
    min_cursor_ = needed;  // publish over it; it counts the loss when it next reads
  }

  // The cursor of the slowest live subscriber (those joining or gone do not count).
  std::uint64_t slowest() const {
    auto& h = topic_->header();
    auto min = ~0ull;
    for (std::size_t i = 0; i < h.max_subscribers; ++i) {
      const auto cursor = h.subscribers[i].cursor.load(std::memory_order_acquire);
      if (cursor < min) min = cursor;
    }
    return min;
  }
  std::uint32_t slowest_pid() const {
    auto& h = topic_->header();
    const auto min = slowest();
    for (std::size_t i = 0; i < h.max_subscribers; ++i)
      if (h.subscribers[i].cursor.load() == min) return pid_of(h.subscribers[i].owner.load());
    return 0;
  }

  // After a publisher died: its loans are freed, and each chunk the ring
  // names holds the ring's bit (whatever step of a publish it died in).
  void recover() {
    auto& h = topic_->header();
    std::vector<bool> in_ring(h.chunk_count, false);
    for (std::uint64_t i = 0; i < h.capacity; ++i) {
      const auto c = RingEntry::chunk(topic_->ring(i).load());
      if (c < h.chunk_count) in_ring[c] = true;
    }
    for (std::uint32_t c = 0; c < h.chunk_count; ++c) {
      auto& chunk = topic_->chunk(c);
      if (in_ring[c]) {
        chunk.holders.fetch_or(kRingBit);
        chunk.holders.fetch_and(~kLoanBit);
      } else {
        chunk.seq.store(kNotPublished);
        chunk.holders.fetch_and(~(kRingBit | kLoanBit));
      }
    }
  }

  std::shared_ptr<Topic> topic_;
  ProcessId me_;
  std::chrono::nanoseconds block_timeout_;
  std::function<void(Error)> report_;
  std::uint64_t next_ = 0;
  std::uint64_t search_ = 0;
  std::uint32_t ready_ = kNoChunk;  // claimed ahead for the next loan
  std::uint64_t min_cursor_ = 0;  // the slowest subscriber's cursor when last looked at
};

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
  Cursor(std::shared_ptr<Topic> topic, std::size_t history) : topic_{std::move(topic)} {
    auto& h = topic_->header();
    const auto me = this_process();
    for (int pass = 0; pass < 2 && slot_ == kNone; ++pass) {
      for (std::size_t i = 0; i < h.max_subscribers; ++i) {
        ProcessId free = 0;
        if (h.subscribers[i].owner.compare_exchange_strong(free, me)) {
          slot_ = i;
          break;
        }
      }
      if (slot_ == kNone && topic_->reclaim_dead_subscribers() == 0) break;
    }
    if (slot_ == kNone)
      throw Failure{{Errc::limit_exceeded, "topic '" + topic_->name() + "' has its maximum of " +
                                               std::to_string(h.max_subscribers) + " subscribers"}};
    bit_ = 1ull << slot_;
    topic_->release_subscriber_holds(slot_);  // nothing of an earlier owner lingers
    const auto head = h.head.load();
    const auto back = std::min<std::uint64_t>({history, h.capacity, head});
    next_ = head - back;
    h.subscribers[slot_].cursor.store(next_, std::memory_order_seq_cst);
  }
  Cursor(const Cursor&) = delete;
  Cursor& operator=(const Cursor&) = delete;
  ~Cursor() {
    auto& slot = topic_->header().subscribers[slot_];
    slot.cursor.store(kNoCursor);
    // Views own the cursor jointly with the reader, so none is out by now.
    topic_->release_subscriber_holds(slot_);
    slot.owner.store(0);
    topic_->header().space.ring();
  }

  [[nodiscard]] const std::shared_ptr<Topic>& topic() const noexcept { return topic_; }

  // The next sample, if one is published and unread. Looks at one ring
  // entry (one cache line) when nothing is.
  std::optional<Taken> try_take() {
    auto& h = topic_->header();
    while (true) {
      const auto entry = topic_->ring(next_).load(std::memory_order_acquire);
      const auto ahead = RingEntry::ahead(entry, next_);
      if (ahead < 0) return std::nullopt;
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

  // Whether the next sample (or a later one) is out: the ring entry, for a
  // busy poll...
  [[nodiscard]] bool ready() const noexcept {
    return RingEntry::ahead(topic_->ring(next_).load(std::memory_order_acquire), next_) >= 0;
  }
  // ...and the head, for a sleeper: the publisher stores it seq_cst before it
  // looks for sleepers.
  [[nodiscard]] bool available() const noexcept {
    return topic_->header().head.load(std::memory_order_seq_cst) > next_;
  }

  void release(std::uint32_t chunk) const noexcept { topic_->chunk(chunk).holders.fetch_and(~bit_); }

  [[nodiscard]] std::uint64_t lost() const noexcept { return lost_; }

 private:
  static constexpr std::size_t kNone = ~std::size_t{0};

  void skip_to(std::uint64_t seq) {
    lost_ += seq - next_;
    advance(seq);
  }
  void advance(std::uint64_t seq) {
    next_ = seq;
    auto& h = topic_->header();
    h.subscribers[slot_].cursor.store(seq, std::memory_order_seq_cst);
    if (seq >= h.space_wanted.load(std::memory_order_seq_cst)) h.space.ring();
  }

  std::shared_ptr<Topic> topic_;
  std::size_t slot_ = kNone;
  std::uint64_t bit_ = 0;
  std::uint64_t next_ = 0;
  std::uint64_t lost_ = 0;
};

}  // namespace prime::shm::detail
