// sync and interpolate_at over topics another process publishes: the
// conformance scenarios again, with every value crossing shared memory from
// a real shm_peer ("emitter"), which publishes each when this process calls
// its "emit" service, so the order of publication is this test's.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <tuple>

#include "prime/liberty.hpp"
#include "prime/shm.hpp"
#include "shm/domain.hpp"
#include "shm/mappings.hpp"
#include "shm/messages.hpp"
#include "shm/peer_process.hpp"
#include "support/sync_scenarios.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

class ShmSyncAcrossProcesses : public ::testing::Test {
 protected:
  // Publishes `ms` on the emitter's topic `input` (0: lidar, 1: odom, 2: odom_x), stamped t0 + ms.
  void emit(int input, int ms) {
    const auto stamp = std::chrono::duration_cast<Clock::duration>(at(t0, ms).time_since_epoch()).count();
    auto sent = service.call({input, ms, static_cast<std::int64_t>(stamp)});
    ASSERT_TRUE(sent) << sent.error().describe();
  }
  auto topic(const std::string& name) { return core.subscribe<int>(name, {}, kEmitterTopics); }

  void play(SyncPolicy policy, const SyncScenario& scenario) {
    auto fused = sync(policy, topic("lidar"), topic("odom"));
    auto reader = fused.subscribe();
    test::play(scenario, t0, [&](int input, int ms) { emit(input, ms); }, reader);
  }

  const std::string domain = unique_domain("sync");
  PeerProcess emitter{{"emitter", domain}};
  shm::Core core{domain};
  shm::ServiceChain<Emit, std::int64_t> service = [&] {
    EXPECT_TRUE(emitter.says("serving"));
    return core.chain<Emit, std::int64_t>("emit", {.timeout = 5s});
  }();
  const Clock::time_point t0 = Clock::now();
};

TEST_F(ShmSyncAcrossProcesses, ExactTime) { play(exact_time, kExactTimeScenario); }

TEST_F(ShmSyncAcrossProcesses, WithinTolerance) { play(within_tolerance(3ms), kWithinToleranceScenario); }

TEST_F(ShmSyncAcrossProcesses, ApproximateTime) { play(approximate_time(), kApproximateTimeScenario); }

TEST_F(ShmSyncAcrossProcesses, ApproximateTimeHoldsViewsThatReadInPlaceWithinTheBudget) {
  auto fused = sync(approximate_time(), topic("lidar"), topic("odom"));
  auto reader = fused.subscribe();
  for (const int ms : {0, 10, 20}) emit(1, ms);
  for (const int ms : {9, 30}) emit(0, ms);
  auto set = reader.read_for(5s);
  ASSERT_TRUE(set) << set.error().describe();
  const auto& [lidar, odom] = set->value;
  EXPECT_EQ(*lidar, 9);
  EXPECT_EQ(*odom, 10);
  EXPECT_TRUE(inside_mapping_of("lidar", lidar.get())) << "the scan is read where the emitter wrote it";
  EXPECT_TRUE(inside_mapping_of("odom", odom.get()));
}

TEST_F(ShmSyncAcrossProcesses, AChainTakingTheSetOfViewsReadsEveryPartInPlace) {
  using Set = Synced<shm::View<int>, shm::View<int>>;
  liberty::Core local;
  auto fused = sync(approximate_time({.min_interval = {20ms, 20ms}}), topic("lidar"), topic("odom"));
  auto checked = fused | local.chain([](const Set& set) {
                   const auto& [lidar, odom] = set;
                   const bool in_place = inside_mapping_of("lidar", lidar.get()) && inside_mapping_of("odom", odom.get());
                   return std::tuple<int, int, bool, Clock::duration>{*lidar, *odom, in_place, set.skew()};
                 });
  auto reader = checked.subscribe();
  emit(1, 10);
  emit(0, 12);  // no odometry can come before 30 ms: decided at once
  auto got = reader.read_for(5s);
  ASSERT_TRUE(got) << got.error().describe();
  EXPECT_EQ(got->value, (std::tuple<int, int, bool, Clock::duration>{12, 10, true, 2ms}))
      << "(lidar, odom, read in place, skew)";
}

TEST_F(ShmSyncAcrossProcesses, LatestOfEachMadeByAnyInput) {
  auto fused = sync(latest_of_each_on(kAnyInput), topic("lidar"), topic("odom"));
  auto reader = fused.subscribe();
  emit(0, 1);
  emit(1, 10);  // whichever the sync sees second makes the first set
  auto set = reader.read_for(5s);
  ASSERT_TRUE(set) << set.error().describe();
  EXPECT_EQ((static_cast<std::tuple<int, int>>(set->value)), (std::tuple<int, int>{1, 10}));
  emit(1, 20);  // an odometry value makes a set too
  set = reader.read_for(5s);
  ASSERT_TRUE(set) << set.error().describe();
  EXPECT_EQ((static_cast<std::tuple<int, int>>(set->value)), (std::tuple<int, int>{1, 20}));
  EXPECT_EQ(set->stamp, at(t0, 20));
}

TEST_F(ShmSyncAcrossProcesses, InterpolateAt) {
  const InterpolationScenario scenario;
  auto fused = interpolate_at(topic("lidar"), core.subscribe<double>("odom_x", {}, kEmitterTopics), {.max_gap = scenario.max_gap});
  auto reader = fused.subscribe();
  test::play(scenario, t0, [&](int input, int ms) { emit(input == 0 ? 0 : 2, ms); }, reader);
}

}  // namespace
}  // namespace prime::test
