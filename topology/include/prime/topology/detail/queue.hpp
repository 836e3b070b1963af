#pragma once

#include <algorithm>
#include <atomic>
#include <cassert>
#include <concepts>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <expected>
#include <mutex>
#include <optional>
#include <stop_token>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/topology/detail/shared_sample.hpp"
#include "prime/topology/detail/wait.hpp"
#include "prime/topology/qos.hpp"

namespace prime::detail {

// One reader's bounded buffer: a ring of `capacity` slots that never grows.
// Many writers (every producer of the source), one reader. A slot holds the
// reader's own value, or its claim on a value shared with other readers,
// which the reader copies or moves out after it has let the lock go.
//
// Thread-safe. Writers and the reader only touch the condition variables when
// the other side is known to be waiting, so a steady stream costs one
// uncontended lock per value on each side.
template <class T>
class Queue {
 public:
  enum class Pushed { delivered, dropped_oldest, timed_out, stopped, closed };
  // A move-only value has one reader, so it is never shared.
  using Entry = std::conditional_t<std::copy_constructible<T>, std::variant<Sample<T>, SharedSample<T>>,
                                   std::variant<Sample<T>>>;

  explicit Queue(const Qos& qos)
      : slots_(qos.capacity), overflow_{qos.overflow}, block_timeout_{qos.block_timeout}, spin_{qos.spin} {
    assert(qos.capacity > 0);
  }

  // Leaves `entry` as it was unless it was delivered.
  Pushed push(Entry&& entry, std::stop_token stop) {
    std::unique_lock lock{mutex_};
    if (closed_) return Pushed::closed;
    auto result = Pushed::delivered;
    if (size_ == slots_.size()) {
      if (overflow_ == Overflow::drop_oldest) {
        (void)take_front();
        ++lost_;
        result = Pushed::dropped_oldest;
      } else {
        ++waiting_writers_;
        const bool room = not_full_.wait_until(lock, stop, deadline_after(block_timeout_),
                                               [&] { return size_ < slots_.size() || closed_; });
        --waiting_writers_;
        if (closed_) return Pushed::closed;
        if (!room) {
          ++lost_;
          return stop.stop_requested() ? Pushed::stopped : Pushed::timed_out;
        }
      }
    }
    slots_[(head_ + size_) % slots_.size()].emplace(std::move(entry));
    ++size_;
    const bool wake_reader = waiting_readers_ > 0;
    lock.unlock();  // the woken reader should not find the lock still taken
    if (wake_reader) not_empty_.notify_one();
    return result;
  }

  [[nodiscard]] std::optional<Sample<T>> try_pop() {
    std::unique_lock lock{mutex_};
    if (size_ == 0) return std::nullopt;
    auto entry = take_front();
    wake_writers(lock);
    return resolve(std::move(entry));
  }

  [[nodiscard]] std::expected<Sample<T>, Errc> pop_until(Clock::time_point deadline, std::stop_token stop) {
    std::unique_lock lock{mutex_};
    if (auto waited = wait_for_value(lock, deadline, std::move(stop)); !waited) return std::unexpected(waited.error());
    auto entry = take_front();
    wake_writers(lock);
    return resolve(std::move(entry));
  }

  // Waits for one value, then takes up to `max` under one lock, wakes the
  // waiting writers once for all of them, and moves them into `out`. A value
  // whose copy for this reader throws is lost to it: the others still go
  // into `out`, and the first exception is rethrown after.
  [[nodiscard]] std::expected<std::size_t, Errc> pop_some(std::vector<Sample<T>>& out, std::size_t max,
                                                          Clock::time_point deadline, std::stop_token stop) {
    std::unique_lock lock{mutex_};
    if (auto waited = wait_for_value(lock, deadline, std::move(stop)); !waited) return std::unexpected(waited.error());
    taken_.clear();
    while (taken_.size() < max && size_ > 0) taken_.push_back(take_front());
    wake_writers(lock);
    std::exception_ptr failed;
    std::size_t n = 0;
    for (auto& entry : taken_) {
      try {
        out.push_back(resolve(std::move(entry)));
        ++n;
      } catch (...) {
        if (!failed) failed = std::current_exception();
      }
    }
    taken_.clear();
    if (failed) std::rethrow_exception(failed);
    return n;
  }

  // The reader is gone: writers stop waiting for it and drop what they bring.
  void close() {
    std::scoped_lock lock{mutex_};
    closed_ = true;
    not_full_.notify_all();
  }

  [[nodiscard]] std::uint64_t lost() const {
    std::scoped_lock lock{mutex_};
    return lost_;
  }

 private:
  Entry take_front() {
    auto& slot = slots_[head_];
    Entry entry = std::move(*slot);
    slot.reset();
    head_ = (head_ + 1) % slots_.size();
    --size_;
    return entry;
  }

  static Sample<T> resolve(Entry&& entry) {
    if constexpr (std::copy_constructible<T>)
      if (auto* shared = std::get_if<SharedSample<T>>(&entry)) return std::move(*shared).take();
    return std::get<Sample<T>>(std::move(entry));
  }

  // With the lock held on entry and on return: until a value is in the
  // buffer, spinning without the lock first, then asleep on the condition.
  std::expected<void, Errc> wait_for_value(std::unique_lock<std::mutex>& lock, Clock::time_point deadline,
                                           std::stop_token stop) {
    if (size_ > 0) return {};
    lock.unlock();
    auto filled = yielding([&] { return size_.load(std::memory_order_relaxed) > 0; });
    auto sleep = [&](Clock::time_point until) {
      std::unique_lock asleep{mutex_};
      ++waiting_readers_;
      const auto ready = [&] { return size_ > 0; };
      if (until == Clock::time_point::max())
        not_empty_.wait(asleep, stop, ready);
      else
        not_empty_.wait_until(asleep, stop, until, ready);
      --waiting_readers_;
    };
    const auto waited = spin_then_sleep(filled, sleep, spin_, deadline, stop);
    lock.lock();
    if (size_ > 0) return {};
    return std::unexpected(waited == Waited::stopped ? Errc::stopped : Errc::timeout);
  }

  void wake_writers(std::unique_lock<std::mutex>& lock) {
    const bool wake = waiting_writers_ > 0;
    lock.unlock();
    if (wake) not_full_.notify_all();
  }

  mutable std::mutex mutex_;
  std::condition_variable_any not_empty_;
  std::condition_variable_any not_full_;
  std::vector<std::optional<Entry>> slots_;
  std::vector<Entry> taken_;  // the reader's: what pop_some took, outside the lock
  std::size_t head_ = 0;
  std::atomic<std::size_t> size_ = 0;  // written under the lock; read without it only to spin
  std::uint64_t lost_ = 0;
  int waiting_readers_ = 0;
  int waiting_writers_ = 0;
  bool closed_ = false;
  const Overflow overflow_;
  const std::chrono::milliseconds block_timeout_;
  const std::chrono::microseconds spin_;
};

}  // namespace prime::detail
