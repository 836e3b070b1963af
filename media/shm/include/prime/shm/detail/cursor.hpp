#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/prefetch.hpp"
#include "prime/shm/detail/sleep_fences.hpp"
#include "prime/shm/detail/take.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// Samples taken together for a batch of views (shm::Views): consecutive
// sequences from `first`, let go of together.
struct TakenBatch {
  std::atomic<bool> out{false};  // its Views lives; cleared when it ends, on any thread
  std::uint64_t first = 0;
  std::vector<std::uint32_t> chunks;
  std::vector<TakenInfo> info;  // chunks[i]'s
  // By the subscriber's bit, released when it ends; else by the cursor.
  bool held = false;
  // Held for it by a publisher that stopped waiting (taking thread only):
  // released when its end is seen.
  bool pinned = false;
};

// One subscriber slot's cursor over a topic.
//
// A taken sample's chunk is kept from reuse by the subscriber's bit in its
// holders word (a hold), checked against the ring: the hold counts if the
// ring entry that named the chunk still does (ChunkPool::evict says why). A
// batch of views on a `block` topic needs none: the publisher overwrites no
// sample a subscriber it waits for has not passed, and the cursor the
// publisher sees stays at the first sample of the oldest such batch still
// out. Taking one then writes nothing in shared memory per sample: per
// batch, the end of the span it keeps (kept_end), and the cursor as the
// reader acknowledges what it read (every ack_every_ samples).
// - A subscriber joining, or waited for again after the publisher passed
//   it over, is covered so from the head it sees after its cursor is
//   stored (see BackPressure::slowest for why).
// - Its batches kept so lie between the cursor it published and the end
//   of the newest (kept_end, in its slot), a span that with its other
//   holds stays within max_held: older batches are held (their bits set)
//   before a new one would reach further. So a publisher that stops
//   waiting for it (block_timeout) holds, for it, the chunks of that span
//   (see BackPressure::give_up_on_laggards), within what the topic's memory is
//   sized for; the subscriber keeps those of batches still out until they
//   end, and lets go of the others.
// Samples of a drop_oldest topic, and those the observer slot or a lagging
// subscriber takes, are always held.
//
// Not thread-safe: one thread at a time takes; releasing and ending a batch
// are thread-safe.
class Cursor {
 public:
  // Takes a free subscriber slot, or (`observer`) the slot kept for tools,
  // whose cursor no `block` publisher ever waits for. `views`: the views of
  // each chunk this subscriber took one by one (Subscriber's): a take
  // counts the first, and a chunk held for it while lagging is let go of
  // once they are gone.
  Cursor(std::shared_ptr<Topic> topic, std::size_t history, bool observer, std::atomic<std::uint32_t>* views);
  Cursor(const Cursor&) = delete;
  Cursor& operator=(const Cursor&) = delete;
  ~Cursor();

  [[nodiscard]] const std::shared_ptr<Topic>& topic() const noexcept { return topic_; }
  [[nodiscard]] std::uint64_t bit() const noexcept { return bit_; }

  // The next sample, if one is published and unread. Looks at one ring
  // entry (one cache line) when none is. Bounded: a ring whose entries
  // name samples no publisher wrote (damage, see take_damage) ends the
  // look, as does a publisher lapping this reader on every look.
  std::optional<Taken> try_take() {
    retire_ended();
    const auto places = topic_->places();
    for (std::uint64_t looks = 0; looks <= max_looks(); ++looks) {
      const auto found = look(places, next_, true);
      if (found.is == Look::Is::not_yet) {
        caught_up();
        acknowledge_all();
        return std::nullopt;
      }
      if (found.is == Look::Is::out && hold(places, bit_, next_, found.chunk)) {
        // No view of it is out: its hold was released before the
        // publisher could publish it again, so no other thread touches
        // its count now.
        views_[found.chunk].store(1, std::memory_order_relaxed);
        const Taken taken{found.chunk, next_, found.info};
        advance(next_ + 1);
        prefetch_next();
        return taken;
      }
      if (!skip_overwritten()) return std::nullopt;
    }
    return std::nullopt;
  }

  // Up to `max` samples, appended to `out`, with one store of the cursor for
  // them all; how many. A sample overwritten before it was taken ends the
  // batch, and the next take skips what was lost.
  //
  // In the take protocol's two passes (take.hpp): the ring entries of what
  // is out first, with their sizes and stamps, each chunk's header line
  // fetched for writing and its payload for reading as it is found, then
  // the holds. So the lines travel together, not one after another, each
  // hold waiting for its own.
  std::size_t take_some(std::size_t max, std::vector<Taken>& out) {
    if (max == 0) return 0;
    retire_ended();
    const auto places = topic_->places();
    const auto first = out.size();
    look_ahead(places, max, true, [&, from = next_](std::uint32_t chunk, const TakenInfo& info) {
      out.push_back({chunk, from + (out.size() - first), info});
    });
    const auto held =
        hold_in_order(places, bit_, next_, out.size() - first, [&](std::size_t i) { return out[first + i].chunk; });
    out.resize(first + held);  // later ones are not held
    for (auto i = first; i < out.size(); ++i) views_[out[i].chunk].store(1, std::memory_order_relaxed);
    if (held != 0) {
      taken_together(held);
      return held;
    }
    auto taken = try_take();  // nothing in order: the single take skips a loss or notes it has caught up
    if (!taken) return 0;
    out.push_back(*taken);
    return 1;
  }

  // Up to `max` samples as a batch (see TakenBatch): its index, for
  // batch(); none when nothing is out (or a sample was lost: the next take
  // goes on after it). In two passes, as take_some, but a batch the cursor
  // keeps needs no holds. `held`: the samples this subscriber has out now.
  std::optional<std::uint32_t> take_batch(std::size_t max, std::size_t held) {
    retire_ended();
    if (max == 0 || free_.empty()) return std::nullopt;
    const auto index = free_.back();
    auto& b = batches_[index];
    b.chunks.clear();
    b.info.clear();
    b.chunks.reserve(max);  // the steps that may throw: before anything is taken
    b.info.reserve(max);
    free_.pop_back();  // before anything retires more
    auto none = [&] {  // nothing taken: the batch's place is free again
      free_.push_back(index);
      return std::optional<std::uint32_t>{};
    };
    const auto places = topic_->places();
    for (std::uint64_t looks = 0;; ++looks) {
      if (looks > max_looks()) return none();  // bounded, as try_take
      // The sizes and stamps are read (by the look) before the look at
      // `lagging` that decides whether the cursor keeps the batch, and
      // before a hold's check (SampleInfo says why those orders).
      const bool may_keep = may_cover(next_);
      const auto seen = look_ahead(places, max, !may_keep, [&](std::uint32_t chunk, const TakenInfo& info) {
        b.chunks.push_back(chunk);
        b.info.push_back(info);
      });
      if (b.chunks.empty()) {
        if (seen == Look::Is::not_yet) {  // nothing new
          caught_up();
          acknowledge_all();
          return none();
        }
        if (skip_overwritten()) continue;
        return none();
      }
      if (may_keep) keep_within_reach(next_ + b.chunks.size(), held);
      b.held = !covers(next_);  // after the ring entries' and infos' loads, and kept_end's store
      if (!b.held) break;
      const auto n = hold_in_order(places, bit_, next_, b.chunks.size(), [&](std::size_t i) { return b.chunks[i]; });
      b.chunks.resize(n);  // later ones are not held
      b.info.resize(n);
      if (n != 0) break;
      if (!skip_overwritten()) return none();
    }
    b.first = next_;
    b.pinned = false;
    b.out.store(true, std::memory_order_relaxed);
    live_.push_back(index);
    taken_together(b.chunks.size());
    return index;
  }
  [[nodiscard]] TakenBatch& batch(std::uint32_t index) noexcept { return batches_[index]; }

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
        bit_, [&] { return available() || woken(); }, until, [&] { return fences_->before_sleep(); });
  }

  void release(std::uint32_t chunk) const noexcept { topic_->chunk(chunk).holders.fetch_and(~bit_); }

  // Tells the publisher how far this subscriber has read, and wakes it if it
  // waits for that. A reader does so before it waits (for a sample or for
  // room in its budget), when it finds it has read everything, and every
  // ack_every_ samples in between.
  // Not past the oldest batch still out that the cursor keeps.
  void acknowledge() noexcept {
    retire_ended();
    auto to = next_;
    for (const auto i : live_)
      if (kept_by_cursor(batches_[i])) {
        to = std::min(to, batches_[i].first);
        break;  // in the order taken: the oldest
      }
    if (acked_ == to) return;
    acked_ = to;
    auto& h = topic_->header();
    h.subscribers[slot_].cursor.store(to, std::memory_order_seq_cst);
    if (to >= h.space_wanted.load(std::memory_order_seq_cst)) topic_->wake_publisher();
  }

  // The same, before the reader waits or when it finds nothing new: every
  // batch out is held first, so the cursor reaches all it has read, and a
  // `block` publisher is never held back by a reader waiting for more.
  void acknowledge_all() noexcept {
    retire_ended();
    for (const auto i : live_)
      if (kept_by_cursor(batches_[i])) hold_all(batches_[i]);
    acknowledge();
  }

  [[nodiscard]] std::uint64_t lost() const noexcept { return lost_; }

  // Damage a take found since the last call (Errc::damaged): a ring entry
  // naming a sample no publisher could have written. The take passed over
  // it, as over a sample lost; the reader reports it.
  [[nodiscard]] std::optional<Error> take_damage() noexcept { return std::exchange(damage_, std::nullopt); }

 private:
  static constexpr std::size_t kNone = ~std::size_t{0};

  // The take protocol's first pass for a take of up to `max` samples from
  // next_: found(chunk, info) for each sample out, in order, up to the
  // first that is not; what the look at next_ found.
  template <class Found>
  Look::Is look_ahead(const Places& places, std::size_t max, bool for_hold, Found&& found) noexcept {
    const auto from = next_;  // local: `found` stores what could alias the member
    for (std::size_t i = 0; i < max; ++i) {
      const auto seen = look(places, from + i, for_hold);
      if (seen.is != Look::Is::out) return i == 0 ? seen.is : Look::Is::out;
      found(seen.chunk, seen.info);
    }
    return Look::Is::out;
  }
  // `n` samples from next_ were taken together: the cursor moves past
  // them. A reader that has read everything published is waited for again
  // (if it was passed over), and the publisher learns how far it is.
  void taken_together(std::uint64_t n) {
    advance(next_ + n);
    if (RingEntry::ahead(topic_->ring(next_).load(std::memory_order_acquire), next_) < 0) {
      caught_up();
      acknowledge();
    }
  }

  void skip_to(std::uint64_t seq) {
    lost_ += seq - next_;
    advance(seq);
  }
  // The next sample was not there to take: overwritten before it was
  // taken (lost to us), or its ring entry is damaged. Skips to the oldest
  // still in the ring, never past the head: false when there is nothing to
  // skip to, so a ring of forged entries is never walked on and on.
  //
  // A publisher stores a batch's entries (at most a ring's worth) before
  // the head that counts them, so an entry the head has not reached is at
  // most capacity - 1 past it, and one a lap or more ahead of the reader is
  // whole laps ahead. A sample the reader could not take, its entry naming
  // it or a later one, was published before the head was read: the head is
  // past it. Anything else is damage, reported once per take.
  bool skip_overwritten();
  void note_damage(std::uint64_t entry, std::int64_t ahead, std::uint64_t head);
  // Looks one take makes at most: a lap of the ring, and one more.
  [[nodiscard]] std::uint64_t max_looks() const noexcept { return topic_->geometry().capacity + 1; }

  // Whether a batch from `seq` is kept by the cursor: on a `block` topic,
  // from where it covers samples, while the publisher waits for this
  // subscriber. Called after the ring entries' (acquire) loads: a sample
  // published after the publisher stopped waiting finds `lagging` set.
  bool covers(std::uint64_t seq) {
    if (!may_cover(seq)) return false;
    const auto lagging = topic_->header().subscribers[slot_].lagging.load(std::memory_order_seq_cst);
    if (lagging == kWaitedFor) return true;
    if (lagging == kPassedOver && !passed_over_) sort_out_holds_for_lagging();
    return false;
  }
  [[nodiscard]] bool may_cover(std::uint64_t seq) const noexcept { return by_cursor_ && seq >= covered_from_; }
  // Before a batch the cursor is to keep is taken up to `end`, with `held`
  // samples out: the span from the cursor the publisher sees to `end`
  // (which a publisher that stops waiting holds for this subscriber), and
  // the samples held by bits besides, stay within max_held (what the
  // topic's memory is sized for). The cursor is moved on as far as the
  // batches out allow, and the oldest are held until they do. Then `end`
  // is published, before the look at `lagging` that decides the batch.
  void keep_within_reach(std::uint64_t end, std::size_t held) {
    // `held` was read before this counts the batches still out, so one
    // ending meanwhile counts as held by a bit: too many, never too few.
    auto over = [&] {
      std::size_t kept = 0;
      for (const auto i : live_)
        if (kept_by_cursor(batches_[i]) && batches_[i].out.load(std::memory_order_acquire))
          kept += batches_[i].chunks.size();
      return end - acked_ + (held > kept ? held - kept : 0) > max_held_;
    };
    if (over()) acknowledge();
    while (over()) {
      const auto oldest = std::find_if(live_.begin(), live_.end(), [&](auto i) { return kept_by_cursor(batches_[i]); });
      if (oldest == live_.end()) break;
      hold_all(batches_[*oldest]);
      acknowledge();
    }
    if (end > kept_end_) {
      kept_end_ = end;
      topic_->header().subscribers[slot_].kept_end.store(end, std::memory_order_seq_cst);
    }
  }
  // A batch the cursor kept is held from now on (its holds go when it
  // ends): the cursor may pass it. Its chunks cannot have been reused, the
  // cursor the publisher sees being at or before its first sample.
  void hold_all(TakenBatch& b) noexcept {
    for (const auto c : b.chunks) topic_->chunk(c).holders.fetch_or(bit_, std::memory_order_seq_cst);
    b.pinned = true;
  }
  static bool kept_by_cursor(const TakenBatch& b) noexcept { return !b.held && !b.pinned; }
  // The publisher stopped waiting for this subscriber and held, for it,
  // the chunks from its cursor to its kept_end (before it said
  // kPassedOver). Those of batches still out are released when they end
  // (even held ones: a hold may have gone just before the publisher's
  // came); those of samples taken one by one, by their last view (or here,
  // if it is gone); the rest, here. Once each time it is passed over.
  void sort_out_holds_for_lagging() noexcept;
  // Frees the slots of batches that ended (before any take: a pinned one's
  // holds go first).
  void retire_ended() noexcept {
    if (live_.empty()) return;  // no batch out: the one-at-a-time take's case
    std::size_t kept = 0;
    for (const auto i : live_) {
      auto& b = batches_[i];
      if (b.out.load(std::memory_order_acquire)) {
        live_[kept++] = i;
        continue;
      }
      if (b.pinned)
        for (const auto c : b.chunks) release(c);
      free_.push_back(i);
    }
    live_.resize(kept);
  }
  // When the next sample is out already (a reader behind its publisher),
  // asks for its chunk's lines now, so they travel while this one is read:
  // a chunk a page or more from the last is not one the hardware
  // prefetcher finds (docs/performance.md: "Prefetch the next sample's
  // chunk"). Relaxed: it only prefetches; the take loads
  // the entry again.
  void prefetch_next() const noexcept {
    const auto entry = topic_->ring(next_).load(std::memory_order_relaxed);
    if (RingEntry::ahead(entry, next_) != 0) return;
    prefetch_for_write(&topic_->chunk(RingEntry::chunk(entry)));  // for the hold
    __builtin_prefetch(topic_->payload(RingEntry::chunk(entry)));
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
  // A subscriber the publisher stopped waiting for is waited for again once
  // it has read everything.
  //
  // A publisher that looked for the slowest cursor before `lagging` was
  // cleared may overwrite what it had published then: the cursor covers
  // samples from the head seen after (as at subscribe).
  void caught_up() {
    auto& h = topic_->header();
    auto& lagging = h.subscribers[slot_].lagging;
    // Not while the publisher is still setting its holds: the next look.
    if (lagging.load(std::memory_order_acquire) != kPassedOver) return;
    if (!passed_over_) sort_out_holds_for_lagging();
    lagging.store(0, std::memory_order_seq_cst);
    covered_from_ = h.head.load(std::memory_order_seq_cst);
    passed_over_ = false;
  }

  std::shared_ptr<Topic> topic_;
  std::atomic<std::uint32_t>* views_;
  std::vector<TakenBatch> batches_;  // one per sample of max_held at most
  std::vector<std::uint32_t> free_;  // batches_ not out
  std::vector<std::uint32_t> live_;  // batches_ out, or ended but not retired yet; in the order taken
  std::vector<bool> in_batch_;       // sort_out_holds_for_lagging's, per chunk
  bool by_cursor_ = false;           // a `block` topic's subscriber, not the observer
  std::uint64_t max_held_ = 0;
  std::uint64_t covered_from_ = 0;   // the first sample the cursor may keep
  std::uint64_t kept_end_ = 0;       // the slot's kept_end, as last stored
  bool passed_over_ = false;         // lagging seen, and the holds sorted out
  std::size_t slot_ = kNone;
  std::uint64_t bit_ = 0;
  std::uint64_t next_ = 0;
  std::uint64_t acked_ = 0;  // the cursor the publisher sees
  // Samples read between two acknowledgements at most: an eighth of the
  // ring, up to 16. A reader that stops half-way between two costs a
  // `block` publisher at most that much of the ring.
  std::uint64_t ack_every_ = 1;
  std::uint64_t lost_ = 0;
  std::optional<Error> damage_;
  std::optional<SleepFences> fences_;  // from when the slot is taken to when it is let go
};

}  // namespace prime::shm::detail
