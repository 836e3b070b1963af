#pragma once

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/prefetch.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// A publisher's chunks: those it claims for loans, and those its publishes
// push out of the ring, kept as spares for the next loans when no
// subscriber holds them (eviction), else let go to the last subscriber
// that does.
//
// A chunk is the publisher's while its holders carry kPublisherBit: a loan,
// a spare, one leaving the ring, or one the ring names. No one but the
// publisher takes free chunks, so the spares it keeps are missed by no one.
//
// Not thread-safe: the publisher's thread.
class ChunkPool {
 public:
  // For a topic whose ring holds `capacity` samples.
  ChunkPool(const Places& places, std::uint64_t capacity)
      : places_{places},
        spare_{capacity + kAhead},
        leaving_{kLeavingMax},
        batch_leaving_(capacity + kLeavingMax),
        holders_seen_(capacity + kLeavingMax) {}
  ChunkPool(const ChunkPool&) = delete;
  ChunkPool& operator=(const ChunkPool&) = delete;

  // Lets go of every chunk it keeps (not those the ring names): before the
  // publisher gives up the topic, so none is let go of under a successor.
  void give_back() noexcept {
    evict_leaving();
    while (auto chunk = spare_.pop()) let_go(*chunk);
  }

  // A chunk now held by this publisher: the spare kept longest, else a free one.
  std::optional<std::uint32_t> claim() noexcept {
    if (spare_.size() == 0) evict_leaving();
    if (auto chunk = spare_.pop()) return chunk;
    return claim_free(places_.chunk_count);
  }

  // This publisher's hold on a chunk (a loan's, or a spare's) ends.
  void let_go(std::uint32_t chunk) noexcept { places_.chunk(chunk).holders.fetch_and(~kPublisherBit); }

  // Keeps a few chunks claimed ahead of the loans (those leaving the ring
  // count: they become spares when evicted), and their lines on their way
  // for writing: a loan then writes lines already here, while the
  // subscribers read what was just published.
  // Only a few chunks are looked at for that: when subscribers hold every
  // chunk the ring has let go, a full search on every publish would find
  // nothing at a cost that grows with the topic (claim() still searches all).
  void claim_ahead() noexcept {
    // Out of spares: the chunks leaving the ring are evicted now, after the
    // publish, rather than by the next loan, before it.
    if (spare_.size() == 0) evict_leaving();
    while (spare_.size() + leaving_.size() < kAhead) {
      const auto next = claim_free(kAhead);
      if (!next) break;
      keep_spare(*next);
    }
  }

  // A chunk pushed out of the ring by a publish whose head store was fully
  // fenced, after that fence (see evict).
  void evict_fenced(std::uint32_t old) noexcept { evict(old, true); }

  // A chunk pushed out of the ring by a lightly fenced publish. Its
  // eviction waits until kLeavingMax have left (or the next batch, or until
  // the spares run out): an eviction is then a read-modify-write (evict),
  // which waits for every store before it to reach the other CPUs, the
  // ring entry just stored on the line a subscriber polls among them. So it
  // is one such wait per kLeavingMax samples, not per sample (a batch has
  // one fence for all, a full publish its head store's).
  // Until evicted, a chunk stays this publisher's: a subscriber that holds
  // it meanwhile finds the ring naming another, and lets go.
  void leave(std::uint32_t old) noexcept {
    leaving_.push(old);
    prefetch_for_write(&places_.chunk(old));
    if (leaving_.size() == kLeavingMax) evict_leaving();
  }

  // A batch's evictions: the chunks still leaving from before, and those
  // the batch pushes out of the ring (push, before its head store),
  // evicted together after its fence (evict_batch). Kept by the publish in
  // a local variable: its count and places then stay in registers, not
  // reloaded after every store the publish makes.
  class Batch {
   public:
    void push(std::uint32_t old) noexcept {
      chunks_[count_++] = old;
      __builtin_prefetch(&places_.chunk(old));  // for evict_batch's look at its holders
    }

   private:
    friend class ChunkPool;
    Batch(const Places& places, std::uint32_t* chunks) noexcept : places_{places}, chunks_{chunks} {}
    Places places_;
    std::uint32_t* chunks_;
    std::size_t count_ = 0;
  };
  [[nodiscard]] Batch start_batch() noexcept {
    Batch batch{places_, batch_leaving_.data()};
    while (const auto old = leaving_.pop()) batch.chunks_[batch.count_++] = *old;
    return batch;
  }
  // evict(chunk, true) for each: their holders all read first (relaxed),
  // then one acquire fence for the reads, then each chunk kept as a spare
  // or let go, not an acquire load per chunk (docs/performance.md: "Read a
  // batch's evicted holders at once").
  // ThreadSanitizer does not see fences (GCC says so: -Wtsan), so under it
  // the loads acquire themselves: the same order, one it can check.
  void evict_batch(const Batch& batch) noexcept {
#if defined(__SANITIZE_THREAD__)
    constexpr auto kRead = std::memory_order_acquire;
#else
    constexpr auto kRead = std::memory_order_relaxed;
#endif
    const auto places = batch.places_;
    const auto* const leaving = batch.chunks_;
    auto* const seen = holders_seen_.data();
    const auto n = batch.count_;
    for (std::size_t k = 0; k < n; ++k) seen[k] = places.chunk(leaving[k]).holders.load(kRead);
    std::atomic_thread_fence(std::memory_order_acquire);
    for (std::size_t k = 0; k < n; ++k) {
      if (seen[k] == kPublisherBit && !spare_.full()) {
        spare_.push(leaving[k]);
        prefetch_for_write(places.payload(leaving[k]));
      } else {
        places.chunk(leaving[k]).holders.fetch_and(~kPublisherBit, std::memory_order_acq_rel);
      }
    }
  }

 private:
  // A spare's payload is on its way for writing (its header is written, if
  // at all, by the publish: Writer::describe).
  void keep_spare(std::uint32_t chunk) noexcept {
    spare_.push(chunk);
    prefetch_for_write(places_.payload(chunk));
  }

  void evict_leaving() noexcept {
    while (auto old = leaving_.pop()) evict(*old, false);
  }

  // A chunk pushed out of the ring. If no subscriber holds it, it stays
  // this publisher's, as a spare for the next loans (nothing written), else
  // the last subscriber to let it go frees it. A subscriber holds a chunk
  // by the take protocol (take.hpp): its bit set (seq_cst), then a check
  // that the ring entry still names it. So the eviction looks at the
  // holders after the entry that replaced it, ordered by
  // - (not `fenced`) a read-modify-write of the holders; or
  // - (`fenced`: the entry stored before the head of a batch or full
  //   publish, fenced after it) that fence, so a plain load does, no
  //   read-modify-write per sample.
  // That is Dekker's: either the look sees the bit, or the subscriber finds
  // the entry replaced, takes its bit back and reads nothing. A batch that
  // a subscriber's cursor kept, and later holds without a check
  // (Cursor::hold_all), never lies in a chunk leaving the ring: the publisher
  // waits for that cursor, or held the batch's chunks for the subscriber
  // when it stopped waiting (BackPressure::give_up_on_laggards).
  // A light publisher, one at a time, evicts by read-modify-writes per
  // kLeavingMax samples, cheaper than a fence for them (docs/performance.md:
  // "Evictions ride on the head's fence").
  void evict(std::uint32_t old, bool fenced) noexcept {
    auto& dropped = places_.chunk(old);
    if (!spare_.full()) {
      const auto holders = fenced ? dropped.holders.load(std::memory_order_acquire)
                                  : dropped.holders.fetch_or(0, std::memory_order_seq_cst);
      if (holders == kPublisherBit) {
        keep_spare(old);
        return;
      }
    }
    dropped.holders.fetch_and(~kPublisherBit, std::memory_order_acq_rel);
  }

  // A free chunk among the next `tries` of the search, now held by this
  // publisher, if there is one. A held chunk is passed over on a plain load,
  // without taking its line from the subscriber that holds it.
  std::optional<std::uint32_t> claim_free(std::uint64_t tries) noexcept {
    const auto count = places_.chunk_count;
    for (std::uint64_t tried = 0; tried < std::min(tries, count); ++tried) {
      const auto i = static_cast<std::uint32_t>(search_++ % count);
      auto& holders = places_.chunk(i).holders;
      std::uint64_t free = 0;
      if (holders.load(std::memory_order_relaxed) == 0 && holders.compare_exchange_strong(free, kPublisherBit)) return i;
    }
    return std::nullopt;
  }

  // Chunk indices, oldest first, at most as many as it was made for.
  class Fifo {
   public:
    explicit Fifo(std::size_t max) : chunks_(std::bit_ceil(max)), mask_{chunks_.size() - 1}, max_{max} {}
    [[nodiscard]] std::size_t size() const noexcept { return count_; }
    [[nodiscard]] bool full() const noexcept { return count_ == max_; }
    void push(std::uint32_t chunk) noexcept { chunks_[(first_ + count_++) & mask_] = chunk; }
    std::optional<std::uint32_t> pop() noexcept {
      if (count_ == 0) return std::nullopt;
      --count_;
      return chunks_[first_++ & mask_];
    }

   private:
    std::vector<std::uint32_t> chunks_;
    std::size_t mask_;
    std::size_t max_;
    std::size_t first_ = 0;
    std::size_t count_ = 0;
  };

  // Claimed ahead of the loans when the ring gives back none: enough that a
  // loan's lines have arrived by the time it is written.
  static constexpr std::size_t kAhead = 4;
  static constexpr std::size_t kLeavingMax = 8;

  Places places_;  // fixed for the topic's life
  std::uint64_t search_ = 0;
  // Held by this publisher's bit for the next loans: claimed ahead, or
  // taken over as they left the ring. Room for as many as the ring holds
  // and kAhead: a batch as large as the ring hands every chunk it pushes
  // out to the next loans without a read-modify-write (once let go, a chunk
  // is claimed again by one) (docs/performance.md: "Keep every chunk a
  // batch pushes out of the ring").
  Fifo spare_;
  Fifo leaving_;  // out of the ring, not evicted yet (see leave)
  // A batch's (Batch), and those leaving from before:
  // room for a batch as large as the ring and kLeavingMax more.
  std::vector<std::uint32_t> batch_leaving_;
  std::vector<std::uint64_t> holders_seen_;  // their holders, as evict_batch read them
};

}  // namespace prime::shm::detail
