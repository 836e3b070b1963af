#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cstdint>

namespace prime::detail {

// Durations counted in fixed buckets, for percentiles at no cost to the one
// thread that records: a record is a few arithmetic steps and two relaxed
// stores, with no allocation and no lock. Buckets are 1/16 of a power of two
// wide (a percentile is within 6.25 % of the truth, rounded up); durations
// from 0 to 2^63 ns fit. Any thread may read while the recorder records: it
// sees each bucket's count as of some recent moment.
//
// One recording thread; readers on any thread.
class DurationHistogram {
 public:
  static constexpr int kSubBits = 4;
  static constexpr int kSub = 1 << kSubBits;
  static constexpr int kBuckets = (64 - kSubBits + 1) * kSub;

  // Records `d` (a negative one counts as 0). The recording thread only.
  void record(std::chrono::nanoseconds d) noexcept {
    const auto ns = d.count() < 0 ? std::uint64_t{0} : static_cast<std::uint64_t>(d.count());
    auto& bucket = counts_[index(ns)];
    bucket.store(bucket.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    count_.store(count_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    if (ns > max_.load(std::memory_order_relaxed)) max_.store(ns, std::memory_order_relaxed);
  }

  [[nodiscard]] std::uint64_t count() const noexcept { return count_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::chrono::nanoseconds max() const noexcept {
    return std::chrono::nanoseconds{static_cast<std::int64_t>(max_.load(std::memory_order_relaxed))};
  }

  // The smallest bucket bound that at least `q` (0..1) of the records are
  // at or under, never above the largest record; 0 before the first.
  [[nodiscard]] std::chrono::nanoseconds percentile(double q) const noexcept {
    std::array<std::uint64_t, kBuckets> seen;
    std::uint64_t total = 0;
    for (int i = 0; i < kBuckets; ++i) total += seen[i] = counts_[i].load(std::memory_order_relaxed);
    if (total == 0) return std::chrono::nanoseconds{0};
    const auto wanted = std::max<std::uint64_t>(1, static_cast<std::uint64_t>(q * static_cast<double>(total) + 0.999999));
    std::uint64_t below = 0;
    for (int i = 0; i < kBuckets; ++i) {
      below += seen[i];
      if (below >= wanted)
        return std::chrono::nanoseconds{
            static_cast<std::int64_t>(std::min(upper(i), max_.load(std::memory_order_relaxed)))};
    }
    return max();
  }

  // The bucket of `ns`: values under kSub have one each; above, each power
  // of two is cut in kSub.
  static constexpr int index(std::uint64_t ns) noexcept {
    if (ns < kSub) return static_cast<int>(ns);
    const int power = 63 - std::countl_zero(ns);  // >= kSubBits
    const int shift = power - kSubBits;
    return (shift + 1) * kSub + static_cast<int>((ns >> shift) & (kSub - 1));
  }
  // The largest value of bucket `i`.
  static constexpr std::uint64_t upper(int i) noexcept {
    if (i < kSub) return static_cast<std::uint64_t>(i);
    const int shift = i / kSub - 1;
    const auto first = (std::uint64_t{kSub} + static_cast<std::uint64_t>(i % kSub)) << shift;
    return first + ((std::uint64_t{1} << shift) - 1);
  }

 private:
  std::array<std::atomic<std::uint64_t>, kBuckets> counts_{};
  std::atomic<std::uint64_t> count_{0};
  std::atomic<std::uint64_t> max_{0};
};

}  // namespace prime::detail
