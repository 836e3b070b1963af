// Waking a subscriber asleep in another process. A publish orders its head
// store before its look for sleepers only lightly; a subscriber on its way
// to sleep makes up for that (membarrier), or, where a seccomp filter
// refuses it, asks publishers to fence fully. Either way no publish may be
// slept through.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

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
void expect_every_publish_wakes_the_echo(const std::string& domain, bool no_membarrier) {
  shm::Core core{domain};
  auto ping = core.publisher<std::uint64_t>("ping");
  auto pong = core.subscribe<std::uint64_t>("pong").subscribe();
  std::vector<std::string> args{"echo_asleep", domain, "ping", "pong", std::to_string(kRounds)};
  if (no_membarrier) args.emplace_back("no_membarrier");
  PeerProcess echo{args};
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
  EXPECT_EQ(mapped.header().fence_every_publish.load(), no_membarrier ? 1u : 0u);
}

TEST(ShmWakes, ASubscriberOnItsWayToSleepIsWokenByAPublishLandingMeanwhile) {
  expect_every_publish_wakes_the_echo(unique_domain("wake-light"), false);
}

TEST(ShmWakes, ASubscriberRefusedMembarrierHasPublishersFenceFullyAndIsWokenByEveryPublish) {
  expect_every_publish_wakes_the_echo(unique_domain("wake-full"), true);
}

}  // namespace
}  // namespace prime::test
