#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "prime/shm/detail/cursor.hpp"
#include "prime/shm/detail/doorbell.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// One reader's state in this process: its cursor, how many views of each
// chunk are out, and how many chunks those pin. A chunk's hold in shared
// memory (the subscriber's bit) goes when its last view does. The reader
// never takes a sample while it holds max_held: that budget is what the
// topic's memory was sized for, so keeping to it is what lets the publisher
// always find a free chunk.
//
// It lives while its reader does or any chunk is held (views may outlive
// the reader): one word counts both, so taking a sample and dropping its
// view cost one read-modify-write each, on a line no other process touches.
//
// Thread-safe for holding and dropping; one thread at a time takes.
class Subscriber {
 public:
  // For the reader, which calls abandon() when it goes.
  [[nodiscard]] static Subscriber* create(std::shared_ptr<Topic> topic, std::size_t history, bool observer) {
    return new Subscriber{std::move(topic), history, observer};
  }
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;

  // The reader is gone; the last held chunk's release ends the subscriber.
  void abandon() noexcept { end_share(kKeeper); }

  [[nodiscard]] Cursor& cursor() noexcept { return cursor_; }
  [[nodiscard]] const Topic& topic() const noexcept { return *cursor_.topic(); }
  [[nodiscard]] std::size_t max_held() const noexcept { return max_held_; }
  [[nodiscard]] std::size_t held() const noexcept { return refs_.load(std::memory_order_acquire) & kHeldMask; }
  [[nodiscard]] bool at_budget() const noexcept { return held() >= max_held_; }

  // The first view of a chunk just taken (the cursor counted it).
  void hold_taken(std::uint32_t) noexcept { refs_.fetch_add(1, std::memory_order_acq_rel); }
  // The first views of chunks just taken together: one read-modify-write
  // for them all.
  void hold_taken(std::span<const Taken> taken) noexcept { refs_.fetch_add(taken.size(), std::memory_order_acq_rel); }
  // The views of `chunk` out now (copies of one view each count).
  [[nodiscard]] std::uint32_t views_of(std::uint32_t chunk) const noexcept {
    return views_[chunk].load(std::memory_order_acquire);
  }
  // A copy of a view: the chunk is held already.
  void hold_again(std::uint32_t chunk) noexcept { views_[chunk].fetch_add(1, std::memory_order_relaxed); }

  void drop(std::uint32_t chunk) noexcept {
    // The only view of a chunk (the common case) cannot be copied while it
    // is destroyed, so seeing a count of 1 is enough to know it is the last.
    auto& views = views_[chunk];
    if (views.load(std::memory_order_acquire) == 1)
      views.store(0, std::memory_order_relaxed);  // before the hold goes: a later take stores 1
    else if (views.fetch_sub(1, std::memory_order_acq_rel) != 1)
      return;
    cursor_.release(chunk);
    let_go(1);
  }

  // A batch of `n` samples just taken (Cursor::take_batch): they count
  // against the budget until it ends.
  void hold_batch(std::size_t n) noexcept { refs_.fetch_add(n, std::memory_order_acq_rel); }
  // A batch ends, on any thread: its holds go, if it has any; the cursor
  // learns it is over (and frees its slot when it next looks).
  void end_batch(std::uint32_t index) noexcept {
    auto& batch = cursor_.batch(index);
    const auto n = batch.chunks.size();
    if (batch.held)
      for (const auto chunk : batch.chunks) cursor_.release(chunk);
    batch.out.store(false, std::memory_order_release);
    let_go(n);
  }

  // Rung when a view's release takes the reader below its budget.
  [[nodiscard]] Doorbell& released() noexcept { return released_; }

 private:
  // refs_: held chunks in the low half; the reader, and a drop ringing the
  // reader, one kKeeper each in the high half.
  static constexpr std::uint64_t kKeeper = 1ull << 32;
  static constexpr std::uint64_t kHeldMask = kKeeper - 1;

  // `n` samples no longer count against the budget: the last share of a
  // subscriber whose reader is gone ends it.
  void let_go(std::uint64_t n) noexcept {
    auto refs = refs_.load(std::memory_order_relaxed);
    while (true) {
      // Taking the reader below its budget while it is there: it may be
      // waiting for room, so the share becomes a keeper's until the
      // waiting reader has been rung.
      const bool ring = (refs & kHeldMask) >= max_held_ && refs > kHeldMask;
      const auto next = refs - n + (ring ? kKeeper : 0);
      if (!refs_.compare_exchange_weak(refs, next, std::memory_order_acq_rel, std::memory_order_relaxed)) continue;
      if (!ring) {
        if (next == 0) delete this;
        return;
      }
      released_.ring();
      end_share(kKeeper);
      return;
    }
  }

  Subscriber(std::shared_ptr<Topic> topic, std::size_t history, bool observer)
      : views_{std::make_unique<std::atomic<std::uint32_t>[]>(topic->geometry().chunk_count())},
        cursor_{std::move(topic), history, observer, views_.get()},
        max_held_{observer ? 1 : cursor_.topic()->geometry().max_held} {}
  ~Subscriber() = default;

  void end_share(std::uint64_t share) noexcept {
    if (refs_.fetch_sub(share, std::memory_order_acq_rel) == share) delete this;
  }

  std::unique_ptr<std::atomic<std::uint32_t>[]> views_;  // of each chunk taken one by one
  Cursor cursor_;
  const std::size_t max_held_;
  std::atomic<std::uint64_t> refs_{kKeeper};  // the reader's
  Doorbell released_;  // in this process's memory: the futex works alike
};

// The reader's hold on its Subscriber.
struct AbandonSubscriber {
  void operator()(Subscriber* s) const noexcept { s->abandon(); }
};
using SubscriberOwner = std::unique_ptr<Subscriber, AbandonSubscriber>;

}  // namespace prime::shm::detail
