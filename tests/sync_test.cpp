// The matching rules of `sync`, offered values in a fixed order (the
// conformance suite covers sync end to end, where worker timing varies).
#include <gtest/gtest.h>

#include <array>

#include <chrono>
#include <cstdint>
#include <tuple>

#include "prime/topology/interpolate.hpp"
#include "prime/topology/sync.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;
using Pair = std::tuple<int, int>;

class SyncRules : public ::testing::Test {
 protected:
  auto matcher(SyncPolicy policy) {
    return std::make_unique<detail::Synchronizer<int, int>>(policy, std::array<std::size_t, 2>{policy.depth, policy.depth}, out);
  }
  template <std::size_t I>
  void offer(detail::Synchronizer<int, int>& s, int value, std::chrono::milliseconds at) {
    s.offer<I>({value, t0 + at}, {});
  }
  std::vector<Pair> matches() {
    std::vector<Pair> all;
    for (auto& s : reader.read_all()) all.push_back(static_cast<const Pair&>(s.value));
    return all;
  }

  const Clock::time_point t0 = Clock::now();
  LocalSource<Synced<int, int>> out{"out", {}, {}, Graph{}};
  Reader<Synced<int, int>> reader = out.subscribe();
};

TEST_F(SyncRules, WithinTolerancePrefersTheClosestValueAlreadyThere) {
  auto s = matcher(within_tolerance(3ms));
  offer<1>(*s, 100, 0ms);
  offer<1>(*s, 102, 2ms);
  offer<0>(*s, 3, 3ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{3, 102}}));
}

TEST_F(SyncRules, WithinToleranceDropsWhatCanNeverMatch) {
  auto s = matcher(within_tolerance(3ms));
  offer<0>(*s, 1, 0ms);
  offer<0>(*s, 2, 10ms);
  offer<1>(*s, 11, 11ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{2, 11}}));
}

TEST_F(SyncRules, ExactTimeNeedsEqualStamps) {
  auto s = matcher(exact_time);
  offer<0>(*s, 1, 10ms);
  offer<1>(*s, 9, 9ms);
  offer<1>(*s, 11, 11ms);
  EXPECT_TRUE(matches().empty());
  offer<0>(*s, 2, 11ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{2, 11}}));
}

TEST_F(SyncRules, LatestOfEachWaitsUntilEverySourceHasSpoken) {
  auto s = matcher(latest_of_each);
  offer<0>(*s, 1, 0ms);
  EXPECT_TRUE(matches().empty());
  offer<1>(*s, 10, 1ms);
  offer<1>(*s, 20, 2ms);
  EXPECT_TRUE(matches().empty()) << "only the first source triggers";
  offer<0>(*s, 2, 3ms);
  offer<0>(*s, 3, 4ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{2, 20}, {3, 20}}));
}

TEST_F(SyncRules, LatestOfEachCanBeMadeByAnyInputOrAChosenOne) {
  auto any = matcher(latest_of_each_on(kAnyInput));
  offer<0>(*any, 1, 0ms);
  offer<1>(*any, 10, 1ms);
  offer<1>(*any, 20, 2ms);
  offer<0>(*any, 2, 3ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{1, 10}, {1, 20}, {2, 20}})) << "every value of either input makes a set";
  auto second = matcher(latest_of_each_on(1));
  offer<0>(*second, 3, 4ms);
  offer<1>(*second, 30, 5ms);
  offer<0>(*second, 4, 6ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{3, 30}})) << "only the second input's values make sets";
}

TEST_F(SyncRules, ASetCarriesEachPartsStamp) {
  auto s = matcher(approximate_time());
  offer<0>(*s, 1, 10ms);
  offer<1>(*s, 2, 12ms);
  offer<0>(*s, 3, 40ms);  // both inputs have moved past the candidates: the set is decided
  offer<1>(*s, 4, 41ms);
  auto sets = reader.read_all();
  ASSERT_FALSE(sets.empty());
  EXPECT_EQ(sets[0].value.stamp<0>(), t0 + 10ms);
  EXPECT_EQ(sets[0].value.stamp<1>(), t0 + 12ms);
  EXPECT_EQ(sets[0].value.skew(), 2ms);
  EXPECT_EQ(sets[0].stamp, t0 + 12ms) << "the sample's stamp is the newest part's";
  const auto [a, b] = sets[0].value;
  EXPECT_EQ(a + b, 3);
}

TEST_F(SyncRules, ApproximateTimeWaitsUntilNoLaterValueCouldMakeABetterSet) {
  auto s = matcher(approximate_time());
  offer<0>(*s, 1, 10ms);
  offer<1>(*s, 100, 13ms);
  EXPECT_TRUE(matches().empty()) << "input 0 may still send a value nearer 13 ms";
  offer<0>(*s, 2, 12ms);
  EXPECT_TRUE(matches().empty()) << "and now it may still send one nearer yet";
  offer<0>(*s, 3, 30ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{2, 100}})) << "12 ms is the nearest 13 ms will get: decided";
}

TEST_F(SyncRules, ApproximateTimeDecidesSoonerKnowingTheInputsIntervals) {
  auto s = matcher(approximate_time({.min_interval = {10ms, 10ms}}));
  offer<0>(*s, 1, 10ms);
  offer<1>(*s, 100, 11ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{1, 100}}))
      << "input 0's next is at 20 ms at the earliest, input 1's at 21 ms: no better set can come";
}

TEST_F(SyncRules, ApproximateTimeNeverMakesASetWiderThanItsMaximum) {
  auto s = matcher(approximate_time({.max_span = 5ms, .min_interval = {1ms, 1ms}}));
  offer<0>(*s, 1, 0ms);
  offer<1>(*s, 100, 20ms);
  offer<0>(*s, 2, 21ms);
  offer<1>(*s, 101, 40ms);
  offer<0>(*s, 3, 60ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{2, 100}})) << "0 ms had no partner within 5 ms";
}

TEST_F(SyncRules, ApproximateTimeWithAnAgePenaltyTakesAnEarlierWiderSet) {
  // A scan at 0 ms and odometry at 10 (span 10, from 0 ms), or the same
  // odometry with a scan at 12 (span 2, from 10 ms).
  for (const double penalty : {0.0, 1.0}) {
    auto s = matcher(approximate_time({.min_interval = {1ms, 1ms}, .age_penalty = penalty}));
    offer<0>(*s, 1, 0ms);
    offer<1>(*s, 100, 10ms);
    offer<0>(*s, 2, 12ms);
    if (penalty == 0)
      EXPECT_EQ(matches(), (std::vector<Pair>{{2, 100}})) << "without a penalty the least span wins";
    else
      EXPECT_EQ(matches(), (std::vector<Pair>{{1, 100}})) << "10 ms of span against 2 ms plus 10 ms of age";
  }
}

TEST_F(SyncRules, WaitingValuesAreBoundedByTheDepth) {
  SyncPolicy policy = exact_time;
  policy.depth = 4;
  auto s = matcher(policy);
  for (int i = 0; i < 100; ++i) offer<0>(*s, i, std::chrono::milliseconds{i});
  offer<1>(*s, 0, 0ms);  // long gone: only the last 4 were kept
  offer<1>(*s, 99, 99ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{99, 99}}));
}

// An unsigned value that goes down (an encoder counting back) is
// interpolated as it goes, not around the type's range.
TEST(Interpolation, AnUnsignedValueGoingDownIsInterpolatedWithoutWrappingAround) {
  EXPECT_EQ(detail::interpolated<unsigned>(10u, 4u, 0.5), 7u);
  EXPECT_EQ(detail::interpolated<std::uint64_t>(1000, 0, 0.25), 750u);
  EXPECT_EQ(detail::interpolated<int>(-10, 10, 0.75), 5);
  EXPECT_DOUBLE_EQ(detail::interpolated<double>(1.0, 0.0, 0.25), 0.75);
}

}  // namespace
}  // namespace prime::test
