// The matching rules of `sync`, offered values in a fixed order (the
// conformance suite covers sync end to end, where worker timing varies).
#include <gtest/gtest.h>

#include <array>

#include <chrono>
#include <tuple>

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
    for (auto& s : reader.read_all()) all.push_back(s.value);
    return all;
  }

  const Clock::time_point t0 = Clock::now();
  LocalSource<Pair> out{"out", {}, {}, Graph{}};
  Reader<Pair> reader = out.subscribe();
};

TEST_F(SyncRules, ApproximateTimePrefersTheClosestValueAlreadyThere) {
  auto s = matcher(approximate_time(3ms));
  offer<1>(*s, 100, 0ms);
  offer<1>(*s, 102, 2ms);
  offer<0>(*s, 3, 3ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{3, 102}}));
}

TEST_F(SyncRules, ApproximateTimeDropsWhatCanNeverMatch) {
  auto s = matcher(approximate_time(3ms));
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

TEST_F(SyncRules, WaitingValuesAreBoundedByTheDepth) {
  SyncPolicy policy = exact_time;
  policy.depth = 4;
  auto s = matcher(policy);
  for (int i = 0; i < 100; ++i) offer<0>(*s, i, std::chrono::milliseconds{i});
  offer<1>(*s, 0, 0ms);  // long gone: only the last 4 were kept
  offer<1>(*s, 99, 99ms);
  EXPECT_EQ(matches(), (std::vector<Pair>{{99, 99}}));
}

}  // namespace
}  // namespace prime::test
