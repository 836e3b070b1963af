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
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/asymmetric_fence.hpp"
#include "prime/shm/detail/back_pressure.hpp"
#include "prime/shm/detail/chunk_pool.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/prefetch.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// The publishing side of a topic: its one live publisher. A publisher that
// finds the previous one dead takes the topic over where it stopped
// (src/recovery.hpp). Its chunks come from a ChunkPool; under `block`, its
// loans wait for the subscribers by BackPressure. What is its own: the
// ring entries, sizes and stamps it writes, the head and its fence, and
// the wake.
//
// Not thread-safe: one thread at a time loans and publishes.
class Writer {
 public:
  // `report` hears of each subscriber a `block` publisher stops waiting for.
  // `light`: fence head stores lightly where this process can register for
  // the heavy half (asymmetric_fence.hpp).
  Writer(std::shared_ptr<Topic> topic, std::chrono::nanoseconds block_timeout, bool light,
         std::function<void(Error)> report);
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;
  ~Writer();

  [[nodiscard]] const std::shared_ptr<Topic>& topic() const noexcept { return topic_; }

  // A free chunk, held by this loan, once the ring has room for it: at once
  // under drop_oldest; under block, when every live subscriber has taken
  // the sample it overwrites. Under block each loan out takes its place in
  // the ring (its publish will overwrite one more sample a subscriber must
  // have taken), so loans stop at the ring's capacity. A subscriber that
  // takes nothing for `block_timeout` is reported once and passed over from
  // then on, like a drop_oldest reader, until it catches up.
  std::expected<std::uint32_t, Error> loan() {
    const auto& g = topic_->geometry();
    const bool block = topic_->overflow() == Overflow::block;
    if (block && out_ >= g.capacity)
      return std::unexpected(Error{Errc::queue_full, "topic '" + topic_->name() + "': all " +
                                                             std::to_string(g.capacity) +
                                                             " places of its ring are loaned out; publish or drop a "
                                                             "loan before taking another"});
    if (block) back_pressure_.wait_for_room(next_ + out_, next_, in_ring_);
    for (int pass = 0; pass < 2; ++pass) {
      if (auto i = pool_.claim()) {
        ++out_;
        return *i;
      }
      if (topic_->reclaim_dead_subscribers() == 0) break;
    }
    // The topic keeps a chunk for one loan beyond what the ring and every
    // subscriber's max_held take. With none out, running short means a
    // slot's owner broke that rule (a foreign or corrupted participant).
    if (out_ > 0)
      return std::unexpected(Error{Errc::queue_full, "topic '" + topic_->name() +
                                                             "': no chunk is free for another loan: this publisher has " +
                                                             std::to_string(out_) +
                                                             " loaned out and the ring and subscribers hold the rest; "
                                                             "publish or drop a loan before taking another"});
    return std::unexpected(Error{Errc::queue_full, "topic '" + topic_->name() + "': all " +
                                                           std::to_string(g.chunk_count()) +
                                                           " chunks are in use; a subscriber holds more than max_held (" +
                                                           std::to_string(g.max_held) + ")"});
  }

  // Up to `max` chunks at once, appended to `out`: the first as loan()
  // gives it (waiting under block), then as many more as are free and as
  // the ring has places for (under block, without waiting). Never more than
  // the ring's capacity. The extra chunks are ones no subscriber holds, so
  // taking them costs no subscriber its max_held.
  std::expected<void, Error> loan_some(std::size_t max, std::vector<std::uint32_t>& out) {
    auto first = loan();
    if (!first) return std::unexpected(std::move(first.error()));
    out.push_back(*first);
    const auto& g = topic_->geometry();
    const bool block = topic_->overflow() == Overflow::block;
    auto room = [&]() -> std::uint64_t {  // more loans the ring has places for now
      const auto places = g.capacity > out_ ? g.capacity - out_ : 0;  // out_ passes it only under drop_oldest
      return block ? std::min(places, back_pressure_.room_after(next_ + out_)) : places;
    };
    auto more = std::min<std::uint64_t>(max - 1, room());
    if (more < max - 1 && block) {
      back_pressure_.look_again(next_);  // a fresh look may find more room
      more = std::min<std::uint64_t>(max - 1, room());
    }
    const auto from = out.size();
    out.resize(from + more);
    std::uint64_t got = 0;
    for (; got < more; ++got) {
      const auto chunk = pool_.claim();
      if (!chunk) break;
      out[from + got] = *chunk;
    }
    out.resize(from + got);
    out_ += got;
    // The lines of their infos (published in order, the batch lands after
    // the loans out before it), on their way while the samples are written.
    const auto at = next_ + out_ - out.size();
    for (std::uint64_t k = 0; k < out.size(); k += kInfosPerLine) prefetch_for_write(&topic_->info(at + k));
    prefetch_for_write(&topic_->info(at + out.size() - 1));
    return {};
  }

  // Hands a loaned chunk back unpublished.
  void discard(std::uint32_t chunk) noexcept {
    pool_.let_go(chunk);
    --out_;
  }

  // Publishes loaned chunks of `size` bytes each as the next sequences, in
  // order, chunk i stamped stamp_of(i). Never waits. As publish() does, for
  // all at once: every size and stamp, then the ring entries one after
  // another (a subscriber polling the ring fetches its line once for several
  // samples, not once for each), the head, the chunks they pushed out, and
  // one wake.
  template <class StampOf>
  void publish_some(std::span<const std::uint32_t> chunks, std::size_t size, StampOf&& stamp_of) noexcept {
    const auto places = topic_->places();
    const auto first = next_;
    out_ -= chunks.size();
    for (std::size_t i = 0; i < chunks.size(); ++i)
      describe(places, chunks[i], first + i, size, stamp_of(i));
    for (std::size_t i = 0; i < chunks.size(); ++i)
      places.ring(first + i).store(RingEntry::pack(first + i, chunks[i]), std::memory_order_release);
    // The chunks these entries push out of the ring, and those still leaving
    // from before: evicted after the head.
    auto leaving = pool_.start_batch();
    for (std::size_t i = 0; i < chunks.size(); ++i)
      if (const auto old = std::exchange(in_ring_[places.ring_index(first + i)], chunks[i]); old != kNoChunk)
        leaving.push(old);
    next_ = first + chunks.size();
    const bool full = fences_fully();
    store_head(next_, full);
    // One fence for the batch's evictions (ChunkPool::evict), not a
    // read-modify-write per sample.
    fence_after_head(full);
    pool_.evict_batch(leaving);
    wake_subscribers();
    claim_ahead();
  }

  // Publishes the loaned `chunk` as the next sequence. Never waits.
  //
  // The ring entry (what a busy subscriber polls) goes before the head (what
  // a sleeping one looks at; store_head orders it before the look for
  // sleepers), so a subscriber that sees the head finds the entry, and a
  // publisher killed in between leaves a head no later than the ring (see
  // src/recovery.hpp). Then the chunk the entry pushed out of the ring is let
  // go: after a full head store, evicted at once, as a batch's are (the
  // store's fence serves the eviction); after a light one, with others
  // later (ChunkPool::leave).
  void publish(std::uint32_t chunk, std::size_t size, Clock::time_point stamp) noexcept {
    const auto seq = next_++;
    --out_;
    describe(topic_->places(), chunk, seq, size, stamp);
    topic_->ring(seq).store(RingEntry::pack(seq, chunk), std::memory_order_release);
    const auto old = std::exchange(in_ring_[topic_->ring_index(seq)], chunk);
    const bool full = fences_fully();
    store_head(seq + 1, full);
    if (old != kNoChunk) {
      if (full) {
        fence_after_head(true);
        pool_.evict_fenced(old);
      } else {
        pool_.leave(old);
      }
    }
    wake_subscribers();
    claim_ahead();
  }

 private:
  // Sample `seq`'s size and stamp, beside its ring entry (SampleInfo says
  // in which order), before the entry. A chunk a page or more long also has
  // its header written, though it says nothing new: its holders, this
  // publisher's alone (a bit a subscriber sets meanwhile is one it takes
  // back at once: the ring no longer names the chunk for the sample it
  // looked for). A subscriber that holds it then finds the line in this
  // publisher's cache, not as the subscriber that let go of the chunk's
  // previous sample left it. Below a page the header is left alone
  // (docs/performance.md: "Layout 12", "Chunks of a page or more still get
  // their header written").
  static void describe(const Places& places, std::uint32_t chunk, std::uint64_t seq, std::size_t size,
                       Clock::time_point stamp) noexcept {
    auto& info = places.info(seq);
    info.word.store(SampleInfo::pack(seq, size), std::memory_order_release);
    info.stamp.store(stamp.time_since_epoch().count(), std::memory_order_release);
    if (places.stride >= kPageAlignment) places.chunk(chunk).holders.store(kPublisherBit, std::memory_order_relaxed);
  }

  // Whether the next head store fences fully: always, but for a light
  // publisher no subscriber asked for full fences.
  [[nodiscard]] bool fences_fully() const noexcept {
    return !light_ || topic_->header().full_fences_wanted.load(std::memory_order_relaxed) != 0;
  }

  // The head, ordered before the look for sleepers that follows it (in
  // wake_subscribers): by a full fence (`full`), which waits for this
  // publish's stores to reach the subscribers' CPUs; or by the light half
  // of an asymmetric one.
  void store_head(std::uint64_t head, bool full) noexcept {
    auto& h = topic_->header();
    if (full) {
      h.head.store(head, std::memory_order_seq_cst);
    } else {
      h.head.store(head, std::memory_order_release);
      light_fence();
    }
  }

  // A full fence after store_head(`full`): every store before the head's
  // reaches the other CPUs before any load after it. Free after a full
  // store on x86, where a seq_cst store is a full barrier already (a locked
  // exchange, or a store and mfence): a fence there would be a second
  // locked instruction per publish.
  static void fence_after_head(bool full) noexcept {
#if defined(__x86_64__) || defined(__i386__)
    if (full) {
      std::atomic_signal_fence(std::memory_order_seq_cst);
      return;
    }
#endif
    std::atomic_thread_fence(std::memory_order_seq_cst);
  }

  // The pool's chunks claimed ahead (ChunkPool::claim_ahead), and the
  // chunk the next sequence pushes out of the ring: its line, last written
  // by the subscriber that released it, is fetched meanwhile.
  void claim_ahead() noexcept {
    pool_.claim_ahead();
    const auto next_out = in_ring_[topic_->ring_index(next_)];
    if (next_out != kNoChunk) prefetch_for_write(&topic_->chunk(next_out));
  }

  // Wakes sleeping subscribers. A ring that finds a sleeper's bit but wakes
  // no one, again and again, means a sleeper died asleep: reclaiming dead
  // subscribers forgets its bit, so it does not cost a system call per
  // sample for as long as the domain lives.
  void wake_subscribers() {
    const auto woken = topic_->header().data.ring();
    if (woken != 0) {
      idle_rings_ = 0;
      return;
    }
    if (++idle_rings_ < kIdleRingsBeforeCheck) return;
    idle_rings_ = 0;
    topic_->reclaim_dead_subscribers();
  }

  std::shared_ptr<Topic> topic_;
  ParticipantId me_;
  const bool light_;
  ChunkPool pool_;
  BackPressure back_pressure_;
  std::uint64_t next_ = 0;
  std::vector<std::uint32_t> in_ring_;  // the chunk each ring entry names, as this publisher wrote it
  std::uint64_t out_ = 0;               // chunks loaned, not yet published or handed back
  int idle_rings_ = 0;                  // rings in a row that found a sleeper's bit but woke no one
  static constexpr std::size_t kInfosPerLine = kPayloadAlignment / sizeof(SampleInfo);  // a line of them
};

}  // namespace prime::shm::detail
