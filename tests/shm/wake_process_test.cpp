// Waking a subscriber asleep in another process: a publish that lands while
// the subscriber is on its way to sleep must wake it (the publisher stores
// the head, then looks for sleepers; the sleeper raises its bit, then looks
// at the head).
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <string>

#include "prime/shm.hpp"
#include "shm/domain.hpp"
#include "shm/mapped_topic.hpp"
#include "shm/peer_process.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

constexpr std::uint64_t kRounds = 100000;

// Publishes 0, 1, 2... on `ping`, each as soon as the echo's answer to the
// one before is read here (spinning), so that it lands while the echo is on
// its way back to sleep. A publish the echo slept through would leave it
// asleep until its 30 s deadline, and this side failing at its 5 s.
TEST(ShmWakes, ASubscriberOnItsWayToSleepIsWokenByAPublishLandingMeanwhile) {
  const auto domain = unique_domain("wake");
  shm::Core core{domain};
  auto ping = core.publisher<std::uint64_t>("ping");
  auto pong = core.subscribe<std::uint64_t>("pong").subscribe();
  PeerProcess echo{{"echo_asleep", domain, "ping", "pong", std::to_string(kRounds)}};
  ASSERT_TRUE(echo.says("subscribed"));
  const MappedTopic mapped{domain, "ping"};
  ASSERT_TRUE(mapped.a_subscriber_sleeps());
  for (std::uint64_t i = 0; i < kRounds; ++i) {
    ASSERT_TRUE(ping.publish(i));
    auto answer = pong.read_for(5s);
    ASSERT_TRUE(answer) << "round " << i << ": " << answer.error().describe();
    ASSERT_EQ(*answer->value, i);
  }
  EXPECT_TRUE(echo.says("done"));
}

}  // namespace
}  // namespace prime::test
