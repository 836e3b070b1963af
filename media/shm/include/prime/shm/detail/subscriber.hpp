#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>

#include "prime/shm/detail/cursor.hpp"
#include "prime/shm/detail/doorbell.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// One reader's state in this process: its cursor, how many views of each
// chunk are out, and how many chunks those pin. A chunk's hold in shared
// memory (the subscriber's bit) goes when its last view does. The reader
// never takes a sample while it holds max_held: that budget is what the
// topic's memory was sized for, so keeping to it is what lets the publisher
// always find a free chunk. Views own this jointly with the reader.
//
// Thread-safe for holding and dropping; one thread at a time takes.
class Subscriber {
 public:
  Subscriber(std::shared_ptr<Topic> topic, std::size_t history, bool observer)
      : cursor_{std::move(topic), history, observer},
        max_held_{observer ? 1 : cursor_.topic()->header().max_held},
        views_{std::make_unique<std::atomic<std::uint32_t>[]>(cursor_.topic()->header().chunk_count)} {}

  [[nodiscard]] Cursor& cursor() noexcept { return cursor_; }
  [[nodiscard]] const Topic& topic() const noexcept { return *cursor_.topic(); }
  [[nodiscard]] std::size_t max_held() const noexcept { return max_held_; }
  [[nodiscard]] std::size_t held() const noexcept { return held_.load(std::memory_order_acquire); }
  [[nodiscard]] bool at_budget() const noexcept { return held() >= max_held_; }

  void hold(std::uint32_t chunk) noexcept {
    if (views_[chunk].fetch_add(1, std::memory_order_relaxed) == 0) held_.fetch_add(1, std::memory_order_acq_rel);
  }
  void drop(std::uint32_t chunk) noexcept {
    if (views_[chunk].fetch_sub(1, std::memory_order_acq_rel) != 1) return;
    cursor_.release(chunk);
    if (held_.fetch_sub(1, std::memory_order_acq_rel) == max_held_) released_.ring();
  }

  // Rung when a view's release takes the reader below its budget.
  [[nodiscard]] Doorbell& released() noexcept { return released_; }

 private:
  Cursor cursor_;
  const std::size_t max_held_;
  std::unique_ptr<std::atomic<std::uint32_t>[]> views_;
  std::atomic<std::size_t> held_{0};
  Doorbell released_;  // in this process's memory: the futex works alike
};

}  // namespace prime::shm::detail
