// A periodic loop's arithmetic, without running one: when ticks are due,
// which tick follows a late run, and the histogram its statistics come from.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>

#include "prime/topology/loop.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;
using detail::DurationHistogram;
using detail::Schedule;

constexpr Clock::time_point kStart{1'000'000'000ns};

TEST(LoopSchedule, TickTimesAreTheStartPlusWholePeriods) {
  const Schedule s{kStart, 20ms, 15ms};
  EXPECT_EQ(s.at(0), kStart);
  EXPECT_EQ(s.at(1), kStart + 20ms);
  EXPECT_EQ(s.at(3'600'000), kStart + 20ms * 3'600'000) << "an hour and more at 1 kHz: exact, no drift";
}

TEST(LoopSchedule, TheFirstTickIsTheFirstMultipleOfThePeriodPlusThePhaseStillAhead) {
  const Clock::time_point now{1'000'000'007ns};
  EXPECT_EQ(Schedule::aligned(now, 10ns, 0ns, 10ns).start, Clock::time_point{1'000'000'010ns});
  EXPECT_EQ(Schedule::aligned(now, 10ns, 3ns, 10ns).start, Clock::time_point{1'000'000'013ns});
  EXPECT_EQ(Schedule::aligned(now, 10ns, 7ns, 10ns).start, now) << "a tick due now is not skipped";
  EXPECT_EQ(Schedule::aligned(now, 10ns, 8ns, 10ns).start, Clock::time_point{1'000'000'008ns});
}

TEST(LoopSchedule, ARunThatEndsInTimeIsFollowedByTheNextTick) {
  const Schedule s{kStart, 20ms, 20ms};
  EXPECT_EQ(s.next(0, kStart + 5ms, Missed::skip), 1u);
  EXPECT_EQ(s.next(0, kStart + 20ms - 1ns, Missed::skip), 1u);
  EXPECT_EQ(s.next(7, s.at(7) + 19ms, Missed::run), 8u);
}

TEST(LoopSchedule, SkippingGoesOnWithTheFirstTickStillAhead) {
  const Schedule s{kStart, 20ms, 20ms};
  EXPECT_EQ(s.next(2, s.at(2) + 20ms, Missed::skip), 4u) << "tick 3 was due as the run ended: missed";
  EXPECT_EQ(s.next(2, s.at(2) + 70ms, Missed::skip), 6u) << "ticks 3, 4 and 5 passed; 6 is ahead";
  EXPECT_GT(s.at(s.next(2, s.at(2) + 70ms, Missed::skip)), s.at(2) + 70ms);
  EXPECT_EQ(s.next(2, s.at(2) + 70ms, Missed::run), 3u) << "run: every missed tick, in order";
}

TEST(LoopHistogram, SmallDurationsAreExactAndLargeOnesWithinASixteenth) {
  for (std::uint64_t ns : {0ull, 1ull, 15ull, 16ull, 17ull, 1000ull, 123'456ull, 20'000'000ull, 1ull << 40}) {
    const auto i = DurationHistogram::index(ns);
    EXPECT_GE(DurationHistogram::upper(i), ns) << ns;
    if (ns < 32) {
      EXPECT_EQ(DurationHistogram::upper(i), ns) << "under 32 ns each bucket holds one value";
    }
    EXPECT_LE(DurationHistogram::upper(i) - ns, ns / 16) << ns;
    if (i > 0) {
      EXPECT_LT(DurationHistogram::upper(i - 1), ns) << "buckets do not overlap, at " << ns;
    }
  }
  EXPECT_EQ(DurationHistogram::index(~0ull), DurationHistogram::kBuckets - 1);
}

TEST(LoopHistogram, PercentilesComeFromTheCountsAndNeverExceedTheMax) {
  DurationHistogram h;
  EXPECT_EQ(h.percentile(0.5), 0ns) << "nothing recorded";
  for (int i = 1; i <= 100; ++i) h.record(std::chrono::microseconds{i});
  h.record(-5ns);  // counted as 0
  EXPECT_EQ(h.count(), 101u);
  EXPECT_EQ(h.max(), 100us);
  const auto p50 = h.percentile(0.5), p99 = h.percentile(0.99);
  EXPECT_GE(p50, 50us);
  EXPECT_LE(p50, 50us + 50us / 16);
  EXPECT_GE(p99, 99us);
  EXPECT_LE(p99, 100us) << "never above the largest record";
  EXPECT_EQ(h.percentile(1.0), 100us);
  EXPECT_EQ(h.percentile(0.0), 0ns) << "the -5 ns record";
}

}  // namespace
}  // namespace prime::test
