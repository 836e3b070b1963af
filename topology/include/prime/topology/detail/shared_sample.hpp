#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <stop_token>
#include <utility>

#include "prime/logic/sample.hpp"
#include "prime/topology/detail/wait.hpp"

namespace prime::detail {

// One published value handed to several readers without copying it at
// publish time: every reader's queue holds a SharedSample of the same value,
// and each reader takes it when it reads. Of the readers that take it, all
// but the last to come copy it, on their own threads; the last gets it moved,
// after waiting for any copy still being made (less time than a copy of its
// own). So the publisher never copies, a reader that drops the value unread
// costs no copy, and n readers make n - 1 copies however their reads overlap.
//
// A SharedSample is one reader's claim: dropping it untaken (a queue that
// drops its oldest value, a closed queue, a push that timed out) gives the
// claim up, so the readers left can still move the value.
template <class T>
class SharedSample {
 public:
  // The first of `readers` claims on `sample`. Make the other `readers - 1`
  // with `claim`, and hand one to each reader.
  [[nodiscard]] static SharedSample share(Sample<T>&& sample, std::size_t readers) {
    return SharedSample{new Box{std::move(sample), static_cast<std::uint32_t>(readers)}};
  }
  [[nodiscard]] SharedSample claim() const noexcept { return SharedSample{box_}; }

  SharedSample(SharedSample&& other) noexcept : box_{std::exchange(other.box_, nullptr)} {}
  SharedSample& operator=(SharedSample&& other) noexcept {
    std::swap(box_, other.box_);
    return *this;
  }
  SharedSample(const SharedSample&) = delete;
  SharedSample& operator=(const SharedSample&) = delete;
  ~SharedSample() {
    if (box_ == nullptr) return;
    (void)box_->arrive();
    box_->done_with_value();
    box_->let_go();
  }

  // The value: moved to the last claim taken or given up, a copy for the
  // others. Consumes the claim.
  [[nodiscard]] Sample<T> take() && {
    Box* box = std::exchange(box_, nullptr);
    struct LetGo {
      Box* box;
      ~LetGo() { box->let_go(); }
    } const after{box};
    if (box->arrive()) {
      box->wait_for_copies();
      return std::move(box->sample);
    }
    struct Done {
      Box* box;
      ~Done() { box->done_with_value(); }
    } const after_copy{box};
    return box->sample;
  }

 private:
  // A copy under way is waited for by spinning this long, then asleep.
  static constexpr std::chrono::microseconds kCopySpin{5};

  struct Box {
    Box(Sample<T>&& s, std::uint32_t readers)
        : sample{std::move(s)}, to_come{readers}, using_value{readers}, holders{readers} {}

    // Counts this claim as taken or given up; true if it is the last.
    bool arrive() noexcept { return to_come.fetch_sub(1, std::memory_order_acq_rel) == 1; }

    // Release: a copy finished reading `sample` before the last claim moves it.
    void done_with_value() noexcept {
      if (using_value.fetch_sub(1, std::memory_order_release) == 2) using_value.notify_one();
    }

    // For the last claim: returns once every other claim is done with `sample`.
    void wait_for_copies() noexcept {
      const auto alone = [this] { return using_value.load(std::memory_order_acquire) == 1; };
      const auto sleep = [this](Clock::time_point) {
        const auto now = using_value.load(std::memory_order_acquire);
        if (now != 1) using_value.wait(now, std::memory_order_acquire);
      };
      (void)spin_then_sleep(yielding(alone), sleep, kCopySpin, Clock::time_point::max(), std::stop_token{});
    }

    // The box goes with the last claim to let go; until then a claim may
    // still wake the last one.
    void let_go() noexcept {
      if (holders.fetch_sub(1, std::memory_order_acq_rel) == 1) delete this;
    }

    Sample<T> sample;
    std::atomic<std::uint32_t> to_come;      // claims neither taken nor given up
    std::atomic<std::uint32_t> using_value;  // claims not yet done with `sample` (still to come, or copying)
    std::atomic<std::uint32_t> holders;      // claims that may still touch the box
  };

  explicit SharedSample(Box* box) noexcept : box_{box} {}

  Box* box_;
};

}  // namespace prime::detail
