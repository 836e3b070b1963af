// Sources carried by bounded Redis streams.
#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <span>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "optimus/support/optimus_fixture.hpp"
#include "prime/optimus/detail/stream_protocol.hpp"
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

// The server numbers appends within the stream's epoch, so writers' batches
// interleave into one gapless sequence: a reader loses nothing, and sees
// each writer's values in its order.
TEST_F(OptimusSource, TwoWritersBatchesShareOneGaplessSequence) {
  optimus::Core first{options()};
  optimus::Core second{options()};
  const Qos qos{.capacity = 1000};
  auto one = first.publisher<int>("imu", qos);
  auto two = second.publisher<int>("imu", qos);
  auto reader = one.source().subscribe(qos);
  auto write = [](optimus::Publisher<int>& pub, int writer) {
    for (int b = 0; b < 10; ++b) {
      std::vector<Sample<int>> batch;
      for (int i = 0; i < 50; ++i) batch.push_back({writer * 1000 + b * 50 + i, Clock::now()});
      ASSERT_TRUE(pub.publish_all(batch));
    }
  };
  {
    std::jthread a{write, std::ref(one), 1};
    std::jthread b{write, std::ref(two), 2};
  }
  auto all = reader.read_all();
  ASSERT_EQ(all.size(), 1000u);
  int next[3] = {0, 1000, 2000};
  for (const auto& s : all) {
    const int writer = s.value / 1000;
    ASSERT_TRUE(writer == 1 || writer == 2) << s.value;
    EXPECT_EQ(s.value, next[writer]++) << "each writer's values in its order";
  }
  EXPECT_EQ(reader.lost(), 0u) << "no gap in the sequence";
}

// A stream deleted between two batches (as a server restart without
// persistence loses it) begins again in a later epoch: the reader's cursor
// comes before every new entry, so it reads them all.
TEST_F(OptimusSource, ABatchAfterItsStreamWasDeletedBeginsItAgainAndTheReaderFollows) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("imu", {.capacity = 1000});
  auto reader = pub.source().subscribe({.capacity = 1000});
  RawRedis raw{shared_redis().url()};
  std::vector<Sample<int>> batch;
  for (int i = 0; i < 600; ++i) batch.push_back({i, Clock::now()});
  ASSERT_TRUE(pub.publish_all(std::span{batch}.first(300)));
  ASSERT_EQ(reader.read_all().size(), 300u);
  const auto old_epoch = raw.command({"XREVRANGE", pub.source().key(), "+", "-", "COUNT", "1"});
  ASSERT_EQ(old_epoch->size(), 1u);
  const std::string old_id{optimus::detail::text((*old_epoch)[0][0])};
  ASSERT_EQ(raw.integer({"DEL", pub.source().key()}), 1);
  ASSERT_TRUE(pub.publish_all(std::span{batch}.last(300)));
  auto all = reader.read_all();
  ASSERT_EQ(all.size(), 300u);
  for (int i = 0; i < 300; ++i) ASSERT_EQ(all[static_cast<std::size_t>(i)].value, 300 + i);
  EXPECT_EQ(reader.lost(), 0u);
  const auto first = raw.command({"XRANGE", pub.source().key(), "-", "+", "COUNT", "1"});
  const auto old_id_parts = optimus::detail::entry_id(old_id);
  const auto new_id = optimus::detail::entry_id(optimus::detail::text((*first)[0][0]));
  ASSERT_TRUE(old_id_parts && new_id);
  EXPECT_GT(new_id->epoch, old_id_parts->epoch) << "a later epoch";
  EXPECT_EQ(new_id->seq, 1u) << "numbered from the start";
}

// A streaming publisher keeps one batch in flight: each call returns once
// the batch before it is appended, and flush appends the last.
TEST_F(OptimusSource, StreamedBatchesAreAppendedInOrderEachBeforeTheCallAfterItReturns) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("imu", {.capacity = 1000});
  auto reader = pub.source().subscribe({.capacity = 1000});
  auto stream = pub.streaming();
  std::vector<Sample<int>> batch(50, Sample<int>{0, Clock::now()});
  std::vector<Sample<int>> got;
  auto read = [&] {
    for (auto& s : reader.read_all()) got.push_back(s);
  };
  for (int b = 0; b < 10; ++b) {
    for (int i = 0; i < 50; ++i) batch[static_cast<std::size_t>(i)] = {b * 50 + i, Clock::time_point{std::chrono::milliseconds{b * 50 + i}}};
    ASSERT_TRUE(stream.publish_all(batch));
    read();
    ASSERT_GE(got.size(), static_cast<std::size_t>(b * 50)) << "every batch before this one is appended";
  }
  ASSERT_TRUE(stream.flush());
  read();
  ASSERT_EQ(got.size(), 500u);
  for (int i = 0; i < 500; ++i) {
    ASSERT_EQ(got[static_cast<std::size_t>(i)].value, i);
    ASSERT_EQ(got[static_cast<std::size_t>(i)].stamp, Clock::time_point{std::chrono::milliseconds{i}}) << "each keeps its stamp";
  }
  EXPECT_EQ(reader.lost(), 0u);
}

// Both batches sent in the epoch of a stream deleted meanwhile are refused:
// the call that reads the first refusal sends both again, in order, in a
// new epoch.
TEST_F(OptimusSource, StreamedBatchesRefusedAsTheirStreamWasDeletedGoAgainInOrder) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("imu", {.capacity = 1000});
  auto reader = pub.source().subscribe({.capacity = 1000});
  RawRedis raw{shared_redis().url()};
  auto stream = pub.streaming();
  std::vector<Sample<int>> all;
  for (int i = 0; i < 90; ++i) all.push_back({i, Clock::now()});
  const std::span values{all};
  ASSERT_TRUE(stream.publish_all(values.first(30)));
  ASSERT_TRUE(stream.flush());
  ASSERT_EQ(reader.read_all().size(), 30u);
  ASSERT_EQ(raw.integer({"DEL", pub.source().key()}), 1);
  ASSERT_TRUE(stream.publish_all(values.subspan(30, 30)));  // in flight, to be refused
  ASSERT_TRUE(stream.publish_all(values.last(30)));         // refused too, and both sent again
  ASSERT_TRUE(stream.flush());
  auto after = reader.read_all();
  ASSERT_EQ(after.size(), 60u);
  for (int i = 0; i < 60; ++i) ASSERT_EQ(after[static_cast<std::size_t>(i)].value, 30 + i);
  EXPECT_EQ(reader.lost(), 0u);
}

// Another handle of the source saw the stream go on in a later epoch while
// a streamed batch was in flight in the earlier one: that batch, refused,
// goes again before the next is sent, so the streamed values stay in order.
TEST_F(OptimusSource, AStreamedBatchRefusedAfterAnotherHandleMovedOnStaysBeforeTheNext) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto pub = core.publisher<int>("imu", {.capacity = 1000});
  auto reader = pub.source().subscribe({.capacity = 1000});
  RawRedis raw{shared_redis().url()};
  auto stream = pub.streaming();
  std::vector<Sample<int>> streamed, other;
  for (int i = 0; i < 30; ++i) streamed.push_back({i, Clock::now()});
  for (int i = 100; i < 105; ++i) other.push_back({i, Clock::now()});
  const std::span values{streamed};
  ASSERT_TRUE(stream.publish_all(values.first(10)));
  ASSERT_TRUE(stream.flush());
  // The stream goes on in a later epoch (an id far ahead: "*" may still
  // number in the stream's first millisecond).
  raw.command({"XADD", pub.source().key(), "99999999999999-0", "hello", "world"});
  ASSERT_TRUE(stream.publish_all(values.subspan(10, 10)));  // in flight in the earlier one: to be refused
  ASSERT_TRUE(pub.publish_all(other));                       // refused, and appended in the later one
  ASSERT_TRUE(stream.publish_all(values.last(10)));
  ASSERT_TRUE(stream.flush());
  std::vector<int> mine, theirs;
  for (const auto& s : reader.read_all()) (s.value < 100 ? mine : theirs).push_back(s.value);
  ASSERT_EQ(mine.size(), 30u);
  for (int i = 0; i < 30; ++i) EXPECT_EQ(mine[static_cast<std::size_t>(i)], i) << "the streamed values in their order";
  EXPECT_EQ(theirs, (std::vector<int>{100, 101, 102, 103, 104}));
  EXPECT_TRUE(errors.read_for(2s)) << "the entry not Prime's is reported";
}

TEST_F(OptimusSource, AServerErrorOnAStreamedBatchIsTheNextCallsOrTheCoresWhenThePublisherGoes) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto pub = core.publisher<int>("imu", {.capacity = 100});
  RawRedis raw{shared_redis().url()};
  std::vector<Sample<int>> batch(10, Sample<int>{1, Clock::now()});
  {
    auto stream = pub.streaming();
    ASSERT_TRUE(stream.publish_all(batch));
    ASSERT_TRUE(stream.flush());
    raw.command({"DEL", pub.source().key()});
    raw.command({"SET", pub.source().key(), "not a stream"});
    ASSERT_TRUE(stream.publish_all(batch)) << "sent; its replies not read yet";
    auto next = stream.publish_all(batch);
    ASSERT_FALSE(next);
    EXPECT_EQ(next.error().code, Errc::type_mismatch);
    EXPECT_NE(next.error().message.find("source 'imu'"), std::string::npos) << next.error().message;
    EXPECT_NE(next.error().message.find("WRONGTYPE"), std::string::npos) << next.error().message;
    EXPECT_TRUE(stream.flush()) << "nothing is in flight after an error";
    ASSERT_TRUE(stream.publish_all(batch));
  }  // its last batch's error goes to the core
  auto reported = errors.read_for(2s);
  ASSERT_TRUE(reported);
  EXPECT_NE(reported->value.message.find("WRONGTYPE"), std::string::npos) << reported->value.message;
}

// The destructor waits for the batch in flight: a large one is appended
// when it returns.
TEST_F(OptimusSource, AStreamingPublisherAppendsItsLastBatchBeforeItGoes) {
  optimus::Core core{options()};
  auto pub = core.publisher<int>("imu", {.capacity = 20000});
  auto reader = pub.source().subscribe({.capacity = 20000});
  std::vector<Sample<int>> batch;
  for (int i = 0; i < 20000; ++i) batch.push_back({i, Clock::now()});
  {
    auto stream = pub.streaming();
    ASSERT_TRUE(stream.publish_all(batch));
  }
  EXPECT_EQ(reader.read_all().size(), 20000u);
}

// An entry not Prime's does not stop a writer: its batches go on after it,
// in its epoch. Appended with "*" it is in a later epoch, or, in the
// stream's first millisecond, in the stream's own; an id far ahead makes
// sure of a later one.
TEST_F(OptimusSource, BatchesGoOnAfterAnEntryNotPrimes) {
  for (const auto& [name, id] : {std::pair{"imu", "*"}, std::pair{"imu-ahead", "99999999999999-0"}}) {
    SCOPED_TRACE(std::string{"the entry's id: "} + id);
    optimus::Core core{options()};
    auto errors = core.errors().subscribe();
    auto pub = core.publisher<int>(name, {.capacity = 100});
    auto reader = pub.source().subscribe({.capacity = 100});
    RawRedis raw{shared_redis().url()};
    std::vector<Sample<int>> batch;
    for (int i = 0; i < 20; ++i) batch.push_back({i, Clock::now()});
    ASSERT_TRUE(pub.publish_all(std::span{batch}.first(10)));
    raw.command({"XADD", pub.source().key(), id, "hello", "world"});
    ASSERT_TRUE(pub.publish_all(std::span{batch}.last(10)));
    auto all = reader.read_all();
    ASSERT_EQ(all.size(), 20u);
    for (int i = 0; i < 20; ++i) ASSERT_EQ(all[static_cast<std::size_t>(i)].value, i);
    EXPECT_EQ(reader.lost(), 1u) << "the entry skipped, and only it";
    auto error = errors.read_for(2s);
    ASSERT_TRUE(error);
    EXPECT_NE(error->value.message.find("not a Prime entry"), std::string::npos) << error->value.message;
  }
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

// A `block` reader that reads nothing for longer than its lease is struck
// off by the next writer (its fields leave the readers hash, with the count
// of what was dropped for it). Reading again, it registers again and says so.
TEST_F(OptimusSource, ABlockReaderStruckOffForNotReadingSaysSoWhenItReadsAgain) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto pub = core.publisher<int>("cmds", {.capacity = 4, .overflow = Overflow::block, .block_timeout = 20ms});
  auto reader = pub.source().subscribe({.capacity = 1, .overflow = Overflow::block});
  ASSERT_TRUE(pub.publish(1));
  ASSERT_TRUE(pub.publish(2));  // no room: dropped for it
  auto dropped = errors.read_for(5s);
  ASSERT_TRUE(dropped);
  EXPECT_EQ(dropped->value.code, Errc::overflow) << dropped->value.describe();
  RawRedis raw{shared_redis().url()};
  const auto readers = domain + ":readers:cmds";
  ASSERT_TRUE(eventually([&] { return raw.command({"KEYS", readers + ":lease:*"})->size() == 0; }, 10s))
      << "the server runs the lease out";
  ASSERT_TRUE(pub.publish(3));
  EXPECT_EQ(raw.integer({"HLEN", readers}), 0) << "struck off, with its count";
  auto first = reader.read_for(5s);
  ASSERT_TRUE(first) << first.error().describe();
  EXPECT_EQ(first->value, 1);
  auto struck = errors.read_for(5s);
  ASSERT_TRUE(struck) << "reading again, it said it had been struck off";
  EXPECT_NE(struck->value.message.find("taken for gone"), std::string::npos) << struck->value.describe();
  EXPECT_EQ(raw.integer({"HLEN", readers}), 1) << "and is registered again";
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
