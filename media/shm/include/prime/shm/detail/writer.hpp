#pragma once

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/asymmetric_fence.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/prefetch.hpp"
#include "prime/shm/detail/topic.hpp"
#include "prime/topology/detail/wait.hpp"

namespace prime::shm::detail {

// The publishing side of a topic: its one live publisher. A publisher that
// finds the previous one dead takes the topic over where it stopped.
//
// Not thread-safe: one thread at a time loans and publishes.
class Writer {
 public:
  // `report` hears of each subscriber a `block` publisher stops waiting for.
  // `light`: fence head stores lightly where this process can register for
  // the heavy half (asymmetric_fence.hpp).
  Writer(std::shared_ptr<Topic> topic, std::chrono::nanoseconds block_timeout, bool light,
         std::function<void(Error)> report)
      : topic_{std::move(topic)},
        me_{topic_->registry().me()},
        block_timeout_{block_timeout},
        report_{std::move(report)},
        light_{light && light_fences()},
        spare_{topic_->geometry().capacity + kAhead},
        leaving_{kLeavingMax} {
    auto& h = topic_->header();
    const auto& g = topic_->geometry();
    auto current = h.publisher.load();
    while (true) {
      if (current != 0 && topic_->registry().alive(current))
        throw Failure{{Errc::in_use, "topic '" + topic_->name() + "' already has a publisher: " +
                                         topic_->registry().describe(current)}};
      if (h.publisher.compare_exchange_strong(current, me_)) break;
    }
    if (current != 0) recover();  // the previous publisher died: its loans and half-done publish
    h.block_timeout_ns.store(block_timeout_.count());
    // Before any light store: a subscriber that then raises its sleeper bit
    // and reads this clear is seen by every later look for sleepers.
    h.light_publisher.store(light_ ? 1 : 0, std::memory_order_seq_cst);
    next_ = h.head.load();
    in_ring_.resize(g.capacity);
    batch_leaving_.resize(g.capacity + kLeavingMax);
    holders_seen_.resize(g.capacity + kLeavingMax);
    for (std::uint64_t i = 0; i < g.capacity; ++i) {
      const auto entry = topic_->ring(i).load();
      in_ring_[i] = topic_->places().names_chunk(entry) ? RingEntry::chunk(entry) : kNoChunk;
    }
  }
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;
  ~Writer() {
    evict_leaving();
    while (auto chunk = spare_.pop()) let_go(*chunk);
    // After the last light store, which this seq_cst store makes visible first.
    topic_->header().light_publisher.store(0, std::memory_order_seq_cst);
    auto expected = me_;
    topic_->header().publisher.compare_exchange_strong(expected, 0);
  }

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
    if (block) wait_for_room();
    for (int pass = 0; pass < 2; ++pass) {
      if (auto i = claim()) {
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
    auto room = [&]() -> std::uint64_t {  // more loans the ring has places for now (see wait_for_room)
      const auto places = g.capacity > out_ ? g.capacity - out_ : 0;  // out_ passes it only under drop_oldest
      if (!block) return places;
      const auto after = next_ + out_;
      return std::min(places, min_cursor_ + g.capacity > after ? min_cursor_ + g.capacity - after : 0);
    };
    auto more = std::min<std::uint64_t>(max - 1, room());
    if (more < max - 1 && block) {
      min_cursor_ = std::min(slowest(), next_);  // a fresh look may find more room
      more = std::min<std::uint64_t>(max - 1, room());
    }
    const auto from = out.size();
    out.resize(from + more);
    std::uint64_t got = 0;
    for (; got < more; ++got) {
      const auto chunk = claim();
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
    let_go(chunk);
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
    std::size_t leaving = 0;
    while (const auto old = leaving_.pop()) batch_leaving_[leaving++] = *old;
    for (std::size_t i = 0; i < chunks.size(); ++i)
      if (const auto old = std::exchange(in_ring_[places.ring_index(first + i)], chunks[i]); old != kNoChunk) {
        batch_leaving_[leaving++] = old;
        __builtin_prefetch(&places.chunk(old));  // for evict's look at its holders
      }
    next_ = first + chunks.size();
    const bool full = fences_fully();
    store_head(next_, full);
    // One fence for the batch's evictions (evict), not a read-modify-write
    // per sample.
    fence_after_head(full);
    evict_fenced(places, leaving);
    wake_subscribers();
    claim_ahead();
  }

  // Publishes the loaned `chunk` as the next sequence. Never waits.
  //
  // The ring entry (what a busy subscriber polls) goes before the head (what
  // a sleeping one looks at; store_head orders it before the look for
  // sleepers), so a subscriber that sees the head finds the entry, and a
  // publisher killed in between leaves a head no later than the ring (see
  // recover). Then the chunk the entry pushed out of the ring is let go:
  // after a full head store, evicted at once, as a batch's are (the store's
  // fence serves the eviction); after a light one, with others later (leave).
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
        evict(old, true);
      } else {
        leave(old);
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

  // This publisher's hold on a chunk (a loan's, or a spare's) ends.
  void let_go(std::uint32_t chunk) noexcept { topic_->chunk(chunk).holders.fetch_and(~kPublisherBit); }

  // Keeps a few chunks claimed ahead of the loans (those leaving the ring
  // count: they become spares when evicted), and their lines on their way
  // for writing: a loan then writes lines already here, while the
  // subscribers read what was just published.
  // Only a few chunks are looked at for that: when subscribers hold every
  // chunk the ring has let go, a full search on every publish would find
  // nothing at a cost that grows with the topic (loan() still searches all).
  void claim_ahead() noexcept {
    // Out of spares: the chunks leaving the ring are evicted now, after the
    // publish, rather than by the next loan, before it.
    if (spare_.size() == 0) evict_leaving();
    while (spare_.size() + leaving_.size() < kAhead) {
      const auto next = claim_free(kAhead);
      if (!next) break;
      keep_spare(*next);
    }
    // The chunk the next sequence pushes out of the ring: its line, last
    // written by the subscriber that released it, is fetched meanwhile.
    const auto next_out = in_ring_[topic_->ring_index(next_)];
    if (next_out != kNoChunk) prefetch_for_write(&topic_->chunk(next_out));
  }

  // A spare's payload is on its way for writing (its header is written, if
  // at all, by describe at publish).
  void keep_spare(std::uint32_t chunk) noexcept {
    spare_.push(chunk);
    prefetch_for_write(topic_->payload(chunk));
  }

  // A chunk pushed out of the ring by a light publish(). Its eviction waits
  // until kLeavingMax have left (or the next batch, or until the spares run
  // out): an eviction is then a read-modify-write (evict), which waits for
  // every store before it to reach the other CPUs, the ring entry just
  // stored on the line a subscriber polls among them. So it is one such
  // wait per kLeavingMax samples, not per sample (a batch has one fence for
  // all, a full publish() its head store's).
  // Until evicted, a chunk stays this publisher's: a subscriber that holds
  // it meanwhile finds the ring naming another, and lets go.
  void leave(std::uint32_t old) noexcept {
    leaving_.push(old);
    prefetch_for_write(&topic_->chunk(old));
    if (leaving_.size() == kLeavingMax) evict_leaving();
  }
  void evict_leaving() noexcept {
    while (auto old = leaving_.pop()) evict(*old, false);
  }

  // A chunk pushed out of the ring. If no subscriber holds it, it stays
  // this publisher's, as a spare for the next loans (nothing written), else
  // the last subscriber to let it go frees it. A subscriber holds a chunk by
  // setting its bit (seq_cst), then checking that the ring entry still names
  // it; so the eviction looks at the holders after the entry that replaced
  // it, ordered by
  // - (not `fenced`) a read-modify-write of the holders; or
  // - (`fenced`: the entry stored before the head of a batch or full
  //   publish, fenced after it) that fence, so a plain load does, no
  //   read-modify-write per sample.
  // That is Dekker's: either the look sees the bit, or the subscriber finds
  // the entry replaced, takes its bit back and reads nothing. A batch that
  // a subscriber's cursor kept, and later holds without a check
  // (Cursor::hold), never lies in a chunk leaving the ring: the publisher
  // waits for that cursor, or held the batch's chunks for the subscriber
  // when it stopped waiting.
  // A light publisher, one at a time, evicts by read-modify-writes per
  // kLeavingMax samples, cheaper than a fence for them (docs/performance.md:
  // "Evictions ride on the head's fence").
  void evict(std::uint32_t old, bool fenced) noexcept {
    auto& dropped = topic_->chunk(old);
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

  // evict(chunk, true) for each of the first `n` chunks of batch_leaving_:
  // their holders all read first (relaxed), then one acquire fence for the
  // reads, then each chunk kept as a spare or let go, not an acquire load
  // per chunk (docs/performance.md: "Read a batch's evicted holders at
  // once").
  // ThreadSanitizer does not see fences (GCC says so: -Wtsan), so under it
  // the loads acquire themselves: the same order, one it can check.
  void evict_fenced(const Places& places, std::size_t n) noexcept {
#if defined(__SANITIZE_THREAD__)
    constexpr auto kRead = std::memory_order_acquire;
#else
    constexpr auto kRead = std::memory_order_relaxed;
#endif
    const auto* const leaving = batch_leaving_.data();
    auto* const seen = holders_seen_.data();
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

  // A chunk now held by this publisher: the spare one kept longest, else a free one.
  std::optional<std::uint32_t> claim() noexcept {
    if (spare_.size() == 0) evict_leaving();
    if (auto chunk = spare_.pop()) return chunk;
    return claim_free(topic_->places().chunk_count);
  }

  // A free chunk among the next `tries` of the search, now held by this
  // publisher, if there is one. A held chunk is passed over on a plain load,
  // without taking its line from the subscriber that holds it.
  std::optional<std::uint32_t> claim_free(std::uint64_t tries) noexcept {
    const auto count = topic_->places().chunk_count;
    for (std::uint64_t tried = 0; tried < std::min(tries, count); ++tried) {
      const auto i = static_cast<std::uint32_t>(search_++ % count);
      auto& holders = topic_->chunk(i).holders;
      std::uint64_t free = 0;
      if (holders.load(std::memory_order_relaxed) == 0 && holders.compare_exchange_strong(free, kPublisherBit)) return i;
    }
    return std::nullopt;
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

  // Room for one more loan: its sample is published after those of the
  // loans out already (out_ < capacity), as sequence next_ + out_.
  void wait_for_room() {
    auto& h = topic_->header();
    const auto& g = topic_->geometry();
    const auto after = next_ + out_;
    if (after < g.capacity) return;
    const auto needed = after + 1 - g.capacity;  // every waited-for subscriber must have taken this
    if (min_cursor_ >= needed) return;
    // Capped at next_: a subscriber joining from now on starts at or after it.
    auto room = [&] { return (min_cursor_ = std::min(slowest(), next_)) >= needed; };
    // Asleep, wait for half a ring of room, not one slot: then the publisher
    // and a subscriber that keeps up take turns by the half ring, not by the
    // sample, and wake each other rarely.
    const auto wanted = std::min(needed + g.capacity / 2, next_);
    auto plenty = [&] { return (min_cursor_ = std::min(slowest(), next_)) >= wanted; };
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
    const auto waited = prime::detail::spin_then_sleep(room, sleep, std::chrono::microseconds{50},
                                                       deadline_after(block_timeout_), std::stop_token{});
    if (waited == prime::detail::Waited::ready) return;
    give_up_on_laggards(needed);
  }

  // The slowest cursor among subscribers this publisher waits for: not the
  // observer's, not those it gave up on, not those joining or gone.
  //
  // Fenced after the head store (a light publisher's is a release): a
  // subscriber joining, or waited for again, stores its cursor and then
  // reads the head, and lets its cursor keep only samples from there on
  // (Cursor::covers). Either this look sees its cursor, or that read sees
  // a head no earlier than this publisher's: nothing the cursor keeps is
  // overwritten on the strength of a look that missed it.
  std::uint64_t slowest() const {
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
  void give_up_on_laggards(std::uint64_t needed) {
    auto& h = topic_->header();
    const auto& g = topic_->geometry();
    for (std::size_t i = 0; i < g.max_subscribers; ++i) {
      auto& slot = h.subscribers[i];
      if (slot.cursor.load() >= needed || slot.lagging.load() != kWaitedFor) continue;
      slot.lagging.store(kPinning, std::memory_order_seq_cst);
      const auto from = slot.cursor.load(std::memory_order_seq_cst);
      const auto to = slot.kept_end.load(std::memory_order_seq_cst);
      if (from != kNoCursor)
        for (auto seq = std::max(from, next_ > g.capacity ? next_ - g.capacity : 0); seq < std::min(to, next_); ++seq)
          if (const auto chunk = in_ring_[topic_->ring_index(seq)]; chunk != kNoChunk)
            topic_->chunk(chunk).holders.fetch_or(1ull << i, std::memory_order_seq_cst);
      slot.lagging.store(kPassedOver, std::memory_order_seq_cst);
      if (report_)
        report_(Error{Errc::overflow, "topic '" + topic_->name() + "': subscriber " +
                                          topic_->registry().describe(slot.owner.load()) + " read nothing for " +
                                          std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(block_timeout_).count()) +
                                          " ms; the publisher stops waiting for it until it catches up, and it loses "
                                          "what is overwritten before it reads it"});
    }
    min_cursor_ = std::min(slowest(), next_);
  }

  // After a publisher died: the chunks the ring names are this one's, the
  // rest (its loans and spares) freed, whatever step of a publish it died
  // in; and the topic goes on after the last sequence that reached the ring.
  void recover() {
    auto& h = topic_->header();
    const auto& g = topic_->geometry();
    std::vector<bool> in_ring(g.chunk_count(), false);
    const auto head = h.head.load();
    auto last = head;
    for (std::uint64_t i = 0; i < g.capacity; ++i) {
      const auto entry = topic_->ring(i).load();
      if (!topic_->places().names_chunk(entry)) continue;
      in_ring[RingEntry::chunk(entry)] = true;
      // An entry stored after the last head store (at most a batch on).
      if (const auto ahead = RingEntry::ahead(entry, head); ahead >= 0)
        last = std::max(last, head + static_cast<std::uint64_t>(ahead) + 1);
    }
    for (std::uint32_t c = 0; c < g.chunk_count(); ++c) {
      auto& chunk = topic_->chunk(c);
      if (in_ring[c]) chunk.holders.fetch_or(kPublisherBit);
      else chunk.holders.fetch_and(~kPublisherBit);
    }
    h.head.store(last);
    // A subscriber it died setting holds for sorts out the ones it set.
    for (auto& slot : h.subscribers) {
      auto pinning = kPinning;
      slot.lagging.compare_exchange_strong(pinning, kPassedOver);
    }
    h.space_wanted.store(~0ull);
    h.space.forget(kPublisherSleeper);  // it may have died asleep, waiting for room
  }

  std::shared_ptr<Topic> topic_;
  ParticipantId me_;
  std::chrono::nanoseconds block_timeout_;
  std::function<void(Error)> report_;
  const bool light_;
  std::uint64_t next_ = 0;
  std::uint64_t search_ = 0;
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
  static constexpr std::size_t kInfosPerLine = kPayloadAlignment / sizeof(SampleInfo);  // a line of them
  static constexpr std::size_t kLeavingMax = 8;
  // Chunks this publisher holds by its bit for the next loans: claimed
  // ahead, or taken over as they left the ring. Room for as many as the
  // ring holds and kAhead: a batch as large as the ring hands every chunk
  // it pushes out to the next loans without a read-modify-write (once let
  // go, a chunk is claimed again by one). No one but this publisher takes
  // free chunks, so the ones it keeps are missed by no one
  // (docs/performance.md: "Keep every chunk a batch pushes out of the ring").
  Fifo spare_;
  Fifo leaving_;  // out of the ring, not evicted yet (see leave)
  // A batch's (publish_some), and those leaving from before: room for a
  // batch as large as the ring and kLeavingMax more.
  std::vector<std::uint32_t> batch_leaving_;
  std::vector<std::uint64_t> holders_seen_;  // their holders, as evict_fenced read them
  std::vector<std::uint32_t> in_ring_;  // the chunk each ring entry names, as this publisher wrote it
  std::uint64_t min_cursor_ = 0;    // the slowest subscriber's cursor when last looked at
  std::uint64_t out_ = 0;           // chunks loaned, not yet published or handed back
  int idle_rings_ = 0;              // rings in a row that found a sleeper's bit but woke no one
};

}  // namespace prime::shm::detail
