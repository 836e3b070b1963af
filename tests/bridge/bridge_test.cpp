// Mixed media: a shared-memory topic forwarded into Redis, so that another
// machine can watch robot data. The topic is published by a real second
// process (shm_peer); the watcher reads the Redis stream through a core of
// its own, as a process on another host would.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "optimus/support/redis_server.hpp"
#include "prime/liberty.hpp"
#include "prime/optimus.hpp"
#include "prime/shm.hpp"
#include "shm/domain.hpp"
#include "shm/peer_process.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

struct Pose {
  double x, y, theta;
};

TEST(Bridge, AShmTopicForwardedIntoRedisReachesAWatcherWithValuesAndStamps) {
  RedisServer redis;
  const auto domain = unique_domain("bridge");
  shm::Core robot{domain};
  optimus::Core uplink{optimus::Options{.url = redis.url(), .domain = domain}};
  optimus::Core watcher{optimus::Options{.url = redis.url(), .domain = domain}};  // "another machine"
  auto watched = watcher.subscribe<Pose>("robot/pose").subscribe();

  auto poses = robot.publisher<Pose>("robot/pose");
  forward(robot.subscribe<Pose>("robot/pose"),
          [out = uplink.publisher<Pose>("robot/pose")](const shm::View<Pose>& pose, Clock::time_point stamp) {
            return out.publish(*pose, stamp);
          },
          "pose to redis");
  const auto t0 = Clock::now();
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(poses.publish({1.0 * i, 2.0 * i, 0.1 * i}, t0 + i * 1ms));

  for (int i = 0; i < 20; ++i) {
    auto pose = watched.read_for(10s);
    ASSERT_TRUE(pose) << pose.error().describe();
    EXPECT_EQ(pose->value.x, 1.0 * i);
    EXPECT_EQ(pose->value.theta, 0.1 * i);
    EXPECT_EQ(pose->stamp, t0 + i * 1ms) << "the sensor's stamp crosses both media";
  }
  EXPECT_EQ(watched.lost(), 0u);
}

TEST(Bridge, EverySampleOfAnotherProcessCrossesIntoRedisInOrder) {
  RedisServer redis;
  const auto domain = unique_domain("bridge-process");
  shm::Core robot{domain};
  optimus::Core uplink{optimus::Options{.url = redis.url(), .domain = domain}};
  optimus::Core watcher{optimus::Options{.url = redis.url(), .domain = domain}};
  auto watched = watcher.subscribe<std::uint64_t>("odom", {.capacity = 1024}).subscribe();
  const shm::TopicQos qos{.capacity = 1024, .overflow = Overflow::block, .block_timeout = 10s};
  forward(robot.subscribe<std::uint64_t>("odom", {}, qos),
          [out = uplink.publisher<std::uint64_t>("odom", {.capacity = 1024})](
              const shm::View<std::uint64_t>& v, Clock::time_point stamp) { return out.publish(*v, stamp); });

  PeerProcess driver{{"publish", domain, "odom", "0", "500", "1024", "block"}};
  ASSERT_TRUE(driver.says("published"));
  for (std::uint64_t i = 0; i < 500; ++i) {
    auto value = watched.read_for(10s);
    ASSERT_TRUE(value) << value.error().describe() << " at " << i;
    ASSERT_EQ(value->value, i);
  }
  EXPECT_EQ(watched.lost(), 0u);
}

TEST(Bridge, AnOptimusServiceRunsInsideALibertyChainFedByAShmTopic) {
  RedisServer redis;
  const auto domain = unique_domain("bridge-service");
  shm::Core robot{domain};
  liberty::Core local;
  optimus::Core cloud{optimus::Options{.url = redis.url(), .domain = domain}};
  auto plan = cloud.chain([](double x) { return x * 10; }, "remote-planner");  // a service, called via Redis
  auto pipeline = local.chain([](const shm::View<Pose>& p) { return p->x + 1; }, "prepare") | plan |
                  local.chain([](double v) { return static_cast<int>(v); }, "act");
  auto publisher = robot.publisher<Pose>("pose");
  auto actions = (robot.subscribe<Pose>("pose") | pipeline).subscribe();
  ASSERT_TRUE(publisher.publish({4.0, 0, 0}));
  auto action = actions.read_for(10s);
  ASSERT_TRUE(action) << action.error().describe();
  EXPECT_EQ(action->value, 50);
  const auto text = (robot.subscribe<Pose>("pose") | pipeline).graph().text();
  EXPECT_NE(text.find("remote-planner [chain, optimus]"), std::string::npos) << text;
}

}  // namespace
}  // namespace prime::test
