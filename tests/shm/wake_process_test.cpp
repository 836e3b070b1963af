// Waking a subscriber asleep in another process: a publish that lands while
// the subscriber is on its way to sleep must wake it (the publisher stores
// the head, then looks for sleepers; the sleeper raises its bit, then looks
// at the head). A publisher fences that fully (the default) or lightly
// (PublishFence::light): then a subscriber about to sleep makes up for it
// with membarrier, at a bounded rate, or asks for full fences where it may
// not or sleeps too often. In every case no publish may be slept through.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "prime/shm.hpp"
#include "shm/domain.hpp"
#include "shm/mapped_topic.hpp"
#include "shm/peer_process.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

constexpr std::uint64_t kRounds = 100000;
// What a sleeping subscriber may ask for at most: 1000 heavy fences a second.
constexpr std::uint64_t kHeavyPerSecond = 1000;

struct Echo {
  std::uint64_t heavy_fences;
  std::uint64_t ms;
};

// Publishes 0, 1, 2... on `ping`, each as soon as the echo's answer to the
// one before is read here (spinning), so that it lands while the echo is on
// its way back to sleep. A publish the echo slept through would leave it
// asleep until its 30 s deadline, and this side failing at its 5 s.
void ping_pong(shm::Publisher<std::uint64_t>& ping, Reader<shm::View<std::uint64_t>>& pong, std::uint64_t first,
               std::uint64_t rounds, std::chrono::milliseconds pace = 0ms) {
  for (auto i = first; i < first + rounds; ++i) {
    if (pace > 0ms) std::this_thread::sleep_for(pace);  // a slow publisher, not a synchronisation
    ASSERT_TRUE(ping.publish(i));
    auto answer = pong.read_for(5s);
    ASSERT_TRUE(answer) << "round " << i << ": " << answer.error().describe();
    ASSERT_EQ(*answer->value, i);
  }
}

Echo done(PeerProcess& echo) {
  const auto line = echo.line_starting("done ");
  if (!line) return {~0ull, 0};
  char* end = nullptr;
  const auto fences = std::strtoull(line->c_str() + 5, &end, 10);
  return {fences, std::strtoull(end, nullptr, 10)};
}

// The echo answers one round more than `rounds`: the test looks at the
// topic while the echo still waits for it (once it ends, its subscriber's
// bits go with it).
PeerProcess start_echo(const std::string& domain, std::uint64_t rounds, bool no_membarrier = false) {
  std::vector<std::string> args{"echo_asleep", domain, "ping", "pong", std::to_string(rounds + 1)};
  if (no_membarrier) args.emplace_back("no_membarrier");
  return PeerProcess{args};
}

TEST(ShmWakes, ASubscriberOnItsWayToSleepIsWokenByAPublishLandingMeanwhile) {
  const auto domain = unique_domain("wake");
  shm::Core core{domain};
  auto ping = core.publisher<std::uint64_t>("ping");
  auto pong = core.subscribe<std::uint64_t>("pong").subscribe();
  auto echo = start_echo(domain, kRounds);
  ASSERT_TRUE(echo.says("subscribed"));
  const MappedTopic mapped{domain, "ping"};
  ASSERT_TRUE(mapped.a_subscriber_sleeps());
  EXPECT_EQ(mapped.header().light_publisher.load(), 0u);
  ping_pong(ping, pong, 0, kRounds + 1);
  // A publisher that fences fully costs its subscribers no membarrier.
  EXPECT_EQ(done(echo).heavy_fences, 0u);
}

// The echo sleeps about a hundred thousand times a second: past its bound of
// heavy fences it asks the publisher for full fences, and stops asking once
// it sleeps rarely again.
TEST(ShmWakes, ALightPublisherWakesEverySleeperAndItsSubscribersBoundTheirInterrupts) {
  const auto domain = unique_domain("wake-light");
  shm::Core core{domain};
  auto ping = core.publisher<std::uint64_t>("ping", {.publish_fence = shm::PublishFence::light});
  auto pong = core.subscribe<std::uint64_t>("pong").subscribe();
  constexpr std::uint64_t kSlowRounds = 20;
  auto echo = start_echo(domain, kRounds + kSlowRounds);
  ASSERT_TRUE(echo.says("subscribed"));
  const MappedTopic mapped{domain, "ping"};
  ASSERT_TRUE(mapped.a_subscriber_sleeps());
  ASSERT_EQ(mapped.header().light_publisher.load(), 1u);
  ping_pong(ping, pong, 0, kRounds);
  EXPECT_NE(mapped.header().full_fences_wanted.load(), 0u) << "a subscriber sleeping this often asks for full fences";
  ping_pong(ping, pong, kRounds, kSlowRounds, 20ms);
  EXPECT_EQ(mapped.header().full_fences_wanted.load(), 0u) << "sleeping 50 times a second, it stops asking";
  ping_pong(ping, pong, kRounds + kSlowRounds, 1);
  const auto echoed = done(echo);
  ASSERT_NE(echoed.heavy_fences, ~0ull);
  EXPECT_GT(echoed.heavy_fences, 0u);
  EXPECT_LE(echoed.heavy_fences, kHeavyPerSecond * (echoed.ms / 1000 + 1)) << "over " << echoed.ms << " ms";
}

TEST(ShmWakes, ASubscriberRefusedMembarrierHasALightPublisherFenceFullyAndIsWokenByEveryPublish) {
  const auto domain = unique_domain("wake-refused");
  shm::Core core{domain};
  auto ping = core.publisher<std::uint64_t>("ping", {.publish_fence = shm::PublishFence::light});
  auto pong = core.subscribe<std::uint64_t>("pong").subscribe();
  auto echo = start_echo(domain, kRounds, true);
  ASSERT_TRUE(echo.says("subscribed"));
  const MappedTopic mapped{domain, "ping"};
  ASSERT_TRUE(mapped.a_subscriber_sleeps());
  EXPECT_NE(mapped.header().full_fences_wanted.load(), 0u) << "asked when it subscribed";
  ping_pong(ping, pong, 0, kRounds);
  EXPECT_NE(mapped.header().full_fences_wanted.load(), 0u) << "asked for good";
  ping_pong(ping, pong, kRounds, 1);
  EXPECT_NE(done(echo).heavy_fences, ~0ull);
}

}  // namespace
}  // namespace prime::test
