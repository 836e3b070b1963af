// Sources carried by bounded Redis streams.
#include <gtest/gtest.h>

#include <chrono>
#include <span>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "optimus/support/optimus_fixture.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using OptimusSource = OptimusTest;

TEST_F(OptimusSource, APublisherAndASubscriberInDifferentCoresShareAStream) {
  optimus::Core writer{options()};
  optimus::Core watcher{options()};
  auto pub = writer.publisher<std::string>("robot/status");
  auto reader = watcher.subscribe<std::string>("robot/status").subscribe();
  const auto stamp = Clock::now() - 1s;
  ASSERT_TRUE(pub.publish("idle", stamp));
  ASSERT_TRUE(pub.publish("moving"));
  auto first = reader.read_for(2s);
  ASSERT_TRUE(first) << first.error().describe();
  EXPECT_EQ(first->value, "idle");
  EXPECT_EQ(first->stamp, stamp) << "the sensor stamp travels with the value";
  EXPECT_EQ(reader.latest()->value, "moving");
}

TEST_F(OptimusSource, TheStreamIsTrimmedToItsCapacity) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("odom", {.capacity = 10});
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(pub.publish(i));
  RawRedis raw{shared_redis().url()};
  EXPECT_EQ(raw.integer({"XLEN", pub.source().key()}), 10);
}

TEST_F(OptimusSource, AReaderCountsWhatTrimmingTookFromIt) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("odom", {.capacity = 5});
  auto slow = pub.source().subscribe({.capacity = 100});
  for (int i = 0; i < 12; ++i) ASSERT_TRUE(pub.publish(i));
  auto kept = slow.read_all();
  ASSERT_EQ(kept.size(), 5u);
  EXPECT_EQ(kept.front().value, 7);
  EXPECT_EQ(slow.lost(), 7u);
}

TEST_F(OptimusSource, PipelinedPublishingAppendsEveryValueInOrder) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("imu", {.capacity = 1000});
  auto reader = pub.source().subscribe({.capacity = 1000});
  std::vector<Sample<int>> batch;
  for (int i = 0; i < 500; ++i) batch.push_back({i, Clock::now()});
  ASSERT_TRUE(pub.publish_all(batch));
  auto all = reader.read_all();
  ASSERT_EQ(all.size(), 500u);
  for (int i = 0; i < 500; ++i) ASSERT_EQ(all[static_cast<std::size_t>(i)].value, i);
  EXPECT_EQ(reader.lost(), 0u);
}

TEST_F(OptimusSource, BatchesContinueTheSequenceTrimTheStreamAndCountWhatTrimmingTook) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("imu", {.capacity = 100});
  auto reader = pub.source().subscribe({.capacity = 1000});
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(pub.publish(i));
  ASSERT_EQ(reader.read_all().size(), 10u);
  std::vector<Sample<int>> batch;
  for (int i = 10; i < 310; ++i) batch.push_back({i, Clock::time_point{std::chrono::milliseconds{i}}});
  ASSERT_TRUE(pub.publish_all(batch));  // two calls of the batch script, pipelined
  RawRedis raw{shared_redis().url()};
  EXPECT_EQ(raw.integer({"XLEN", pub.source().key()}), 100) << "trimmed to the capacity";
  auto kept = reader.read_all();
  ASSERT_EQ(kept.size(), 100u);
  for (std::size_t i = 0; i < kept.size(); ++i) {
    EXPECT_EQ(kept[i].value, 210 + static_cast<int>(i));
    EXPECT_EQ(kept[i].stamp, Clock::time_point{std::chrono::milliseconds{210 + i}}) << "each value keeps its stamp";
  }
  EXPECT_EQ(reader.lost(), 200u) << "the sequence went on from the single publishes: what trimming took is counted";
  ASSERT_TRUE(pub.publish(310));
  auto after = reader.read_all();
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(reader.lost(), 200u) << "and a single publish goes on from the batch";
}

TEST_F(OptimusSource, ABatchSurvivesTheServerForgettingItsScriptAndAppendsEachValueOnce) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("imu", {.capacity = 2000});
  auto reader = pub.source().subscribe({.capacity = 2000});
  RawRedis raw{shared_redis().url()};
  std::vector<Sample<int>> batch;
  for (int i = 0; i < 600; ++i) batch.push_back({i, Clock::now()});
  ASSERT_TRUE(pub.publish_all(std::span{batch}.first(300)));
  raw.command({"SCRIPT", "FLUSH"});  // as a restarted server would have
  ASSERT_TRUE(pub.publish_all(std::span{batch}.last(300)));
  auto all = reader.read_all();
  ASSERT_EQ(all.size(), 600u);
  for (int i = 0; i < 600; ++i) ASSERT_EQ(all[static_cast<std::size_t>(i)].value, i);
  EXPECT_EQ(reader.lost(), 0u);
}

TEST_F(OptimusSource, AForeignEntryInTheStreamIsReportedAndSkipped) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto pub = core.publisher<int>("odom");
  auto reader = pub.source().subscribe();
  RawRedis raw{shared_redis().url()};
  raw.command({"XADD", pub.source().key(), "*", "hello", "world"});
  raw.command({"XADD", pub.source().key(), "*", "n", "2", "t", "0", "d", "not a message"});
  ASSERT_TRUE(pub.publish(5));
  auto value = reader.read_for(2s);
  ASSERT_TRUE(value);
  EXPECT_EQ(value->value, 5);
  auto first = errors.read_for(2s), second = errors.read_for(2s);
  ASSERT_TRUE(first && second);
  EXPECT_EQ(first->value.code, Errc::type_mismatch);
  EXPECT_NE(first->value.message.find("not a Prime entry"), std::string::npos) << first->value.message;
  EXPECT_EQ(second->value.code, Errc::type_mismatch);
  EXPECT_NE(second->value.message.find("key '" + pub.source().key() + "'"), std::string::npos) << second->value.message;
}

TEST_F(OptimusSource, SubscribingWithAnotherTypeIsATypeMismatch) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("odom");
  EXPECT_TRUE(fails_with([&] { (void)core.subscribe<double>("odom"); }, Errc::type_mismatch, "source 'odom'"));
  EXPECT_NO_THROW((void)core.subscribe<int>("odom"));
}

TEST_F(OptimusSource, ABlockReaderHoldsTheWriterBackAcrossCores) {
  optimus::Core writer{options()};
  optimus::Core watcher{options()};
  auto pub = writer.publisher<int>("cmds", {.capacity = 4, .overflow = Overflow::block, .block_timeout = 5000ms});
  auto reader = watcher.subscribe<int>("cmds", {.capacity = 2, .overflow = Overflow::block}).subscribe();
  std::jthread producer{[&] {
    for (int i = 0; i < 50; ++i) ASSERT_TRUE(pub.publish(i));
  }};
  for (int i = 0; i < 50; ++i) {
    auto v = reader.read_for(5s);
    ASSERT_TRUE(v) << v.error().describe();
    ASSERT_EQ(v->value, i);
  }
  EXPECT_EQ(reader.lost(), 0u);
}

TEST_F(OptimusSource, ALinkedChainAndACollectorWorkOnAStream) {
  optimus::Core core{options()};
  Event<int> lidar;
  auto scans = core.source(lidar, "lidar");
  auto latest = collector(core, scans | core.chain([](int x) { return x * 2; }, "filter"));
  lidar.emit(1);
  lidar.emit(2);
  EXPECT_TRUE(eventually([&] {
    try {
      return latest(Token{}) == 4;
    } catch (const Failure&) {
      return false;
    }
  }));
}

}  // namespace
}  // namespace prime::test
