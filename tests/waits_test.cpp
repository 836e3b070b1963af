// Waits named by a duration, to their end: one of "forever" (a duration's
// max(), longer than the clock has left) waits as long as it takes, where
// adding it to the clock would have overflowed into the past and ended it
// at once.
#include <gtest/gtest.h>

#include <chrono>
#include <optional>
#include <thread>

#include "prime/topology/local_source.hpp"
#include "support/threads.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

TEST(Waits, ADeadlineBeyondTheClocksEndIsItsEnd) {
  EXPECT_EQ(deadline_after(std::chrono::milliseconds::max()), Clock::time_point::max());
  EXPECT_EQ(deadline_after(std::chrono::hours::max()), Clock::time_point::max());
  const auto before = Clock::now();
  const auto in_a_second = deadline_after(1s);
  EXPECT_GE(in_a_second, before + 1s);
  EXPECT_LE(in_a_second, Clock::now() + 1s);
}

TEST(Waits, AReadForeverWaitsForTheValue) {
  LocalSource<int> source{"forever", {}, {}, Graph{}};
  auto reader = source.subscribe();
  std::optional<int> got;
  std::jthread read{[&] {
    if (auto s = reader.read_for(std::chrono::milliseconds::max())) got = s->value;
  }};
  ASSERT_TRUE(others_asleep_within()) << "the reader waits";
  source.publish(42);
  read.join();
  EXPECT_EQ(got, 42);
}

TEST(Waits, ABlockPublisherWithoutATimeoutWaitsForRoom) {
  LocalSource<int> source{
      "room", {.capacity = 1, .overflow = Overflow::block, .block_timeout = std::chrono::milliseconds::max()}, {}, Graph{}};
  auto reader = source.subscribe();
  source.publish(1);
  std::jthread second{[&] { source.publish(2); }};
  ASSERT_TRUE(others_asleep_within()) << "the publisher waits for room";
  EXPECT_EQ(reader.read_for(5s)->value, 1);
  auto next = reader.read_for(5s);
  ASSERT_TRUE(next) << "waited for, not dropped: " << next.error().describe();
  EXPECT_EQ(next->value, 2);
}

}  // namespace
}  // namespace prime::test
