// Shm batches of views (BatchReader, Views) within one process: read in
// place, in order, within the budget; on a `block` topic kept by the
// cursor, so a batch out holds the publisher back and a stuck one is
// passed over with its samples intact; let go of from any thread.
// Across processes: process_test.cpp.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <thread>
#include <vector>

#include "prime/shm.hpp"
#include "shm/domain.hpp"
#include "shm/mapped_topic.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// A value that says whether it was overwritten: b is always ~a.
struct Pair {
  std::uint64_t a, b;
};
Pair pair(std::uint64_t a) { return {a, ~a}; }

class ViewsTest : public ::testing::Test {
 protected:
  shm::Core core{unique_domain("views")};

  // Chunks some subscriber holds by its bit (not the publisher's).
  static std::size_t held_by_subscribers(const MappedTopic& topic) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < topic.header().chunk_count; ++i)
      n += (topic.holders(i) & ~shm::detail::kPublisherBit) != 0 ? 1 : 0;
    return n;
  }
};

TEST_F(ViewsTest, ABatchIsReadInPlaceInOrderWithSequencesAndStamps) {
  auto publisher = core.publisher<std::uint64_t>("imu");
  auto batches = core.subscribe<std::uint64_t>("imu").batches();
  std::vector<const std::uint64_t*> written;
  for (std::uint64_t i = 0; i < 6; ++i) {
    auto loan = publisher.loan();
    ASSERT_TRUE(loan);
    written.push_back(loan->get());
    **loan = 10 * i;
    std::move(*loan).publish(Clock::time_point{Clock::duration{1000 + i}});
  }
  auto first = batches.read(4, Clock::now() + 1s);
  ASSERT_TRUE(first) << first.error().describe();
  ASSERT_EQ(first->size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ((*first)[i], 10 * i);
    EXPECT_EQ(&(*first)[i], written[i]) << "read where the publisher wrote it";
    EXPECT_EQ(first->sequence(i), i);
    EXPECT_EQ(first->stamp(i), Clock::time_point{Clock::duration{1000 + i}});
  }
  auto rest = batches.try_read(100);
  ASSERT_EQ(rest.size(), 2u) << "what is published, not what was asked for";
  EXPECT_EQ(rest[1], 50u);
  EXPECT_TRUE(batches.try_read(100).empty());
  auto none = batches.read(100, Clock::now() + 10ms);
  ASSERT_FALSE(none);
  EXPECT_EQ(none.error().code, Errc::timeout);
}

TEST_F(ViewsTest, BatchesCountAgainstMaxHeldUntilTheyEnd) {
  const shm::TopicQos qos{.capacity = 16, .max_held = 4};
  auto publisher = core.publisher<std::uint64_t>("budget", qos);
  auto batches = core.subscribe<std::uint64_t>("budget", {}, qos).batches();
  for (std::uint64_t i = 0; i < 10; ++i) ASSERT_TRUE(publisher.publish(i));
  auto a = batches.try_read(3);
  auto b = batches.try_read(3);
  ASSERT_EQ(a.size(), 3u);
  ASSERT_EQ(b.size(), 1u) << "the budget's last sample";
  EXPECT_TRUE(batches.try_read(3).empty());
  auto waited = batches.read(3, Clock::now() + 10ms);
  ASSERT_FALSE(waited);
  EXPECT_EQ(waited.error().code, Errc::held_limit) << waited.error().describe();
  a = {};
  auto c = batches.try_read(10);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c[0], 4u);
  shm::Views<std::uint64_t> moved{std::move(c)};
  EXPECT_TRUE(c.empty());  // NOLINT(bugprone-use-after-move): a moved-from batch is empty
  EXPECT_EQ(moved[2], 6u);
}

// The cursor the publisher sees stays at a batch still out: a `block`
// publisher waits for it as for a sample not read yet, and goes on once the
// batch has ended and the reader looks for more.
TEST_F(ViewsTest, ABlockPublisherWaitsForABatchOutAndGoesOnWhenItEnds) {
  const shm::TopicQos qos{.capacity = 4, .overflow = Overflow::block, .block_timeout = 1h, .max_held = 4};
  auto publisher = core.publisher<Pair>("kept", qos);
  auto batches = core.subscribe<Pair>("kept", {}, qos).batches();
  for (std::uint64_t i = 0; i < 4; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  auto batch = batches.try_read(4);
  ASSERT_EQ(batch.size(), 4u);
  const MappedTopic mapped{core.domain(), "kept"};
  EXPECT_EQ(held_by_subscribers(mapped), 0u) << "kept by the cursor: no hold written";
  std::jthread more{[&] {
    for (std::uint64_t i = 4; i < 8; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  }};
  ASSERT_TRUE(mapped.the_publisher_sleeps()) << "the ring is the batch's until it ends";
  EXPECT_EQ(mapped.header().head.load(), 4u);
  for (std::uint64_t i = 0; i < 4; ++i) EXPECT_EQ(batch[i].a, i);
  batch = {};
  std::uint64_t expected = 4;
  while (expected < 8) {
    auto next = batches.read(4, Clock::now() + 10s);
    ASSERT_TRUE(next) << next.error().describe();
    for (std::size_t i = 0; i < next->size(); ++i) EXPECT_EQ((*next)[i].a, expected++);
  }
  EXPECT_EQ(batches.lost(), 0u);
}

// A reader that reads on while an old batch is out: the batch is held
// (bits written) once the reader waits for more, or takes a batch too far
// past it, so the cursor and the publisher go on.
TEST_F(ViewsTest, AnOldBatchOutNeverHoldsThePublisherBackWhileTheReaderReadsOn) {
  constexpr std::uint64_t kTotal = 20000;
  const shm::TopicQos qos{.capacity = 8, .overflow = Overflow::block, .block_timeout = 10s, .max_held = 8};
  auto publisher = core.publisher<Pair>("reach", qos);
  auto batches = core.subscribe<Pair>("reach", {}, qos).batches();
  auto errors = core.errors().subscribe();
  ASSERT_TRUE(publisher.publish(pair(0)));
  ASSERT_TRUE(publisher.publish(pair(1)));
  auto old = batches.try_read(2);  // kept out throughout
  ASSERT_EQ(old.size(), 2u);
  const MappedTopic mapped{core.domain(), "reach"};
  EXPECT_EQ(held_by_subscribers(mapped), 0u) << "kept by the cursor so far";
  std::jthread produce{[&] {
    for (std::uint64_t i = 2; i < kTotal; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  }};
  for (std::uint64_t expected = 2; expected < kTotal;) {
    auto b = batches.read(3, Clock::now() + 5s);
    ASSERT_TRUE(b) << b.error().describe() << " at " << expected;
    for (std::size_t i = 0; i < b->size(); ++i) ASSERT_EQ((*b)[i].a, expected++);
  }
  produce.join();
  EXPECT_FALSE(errors.try_read()) << "the publisher never waited block_timeout for this reader";
  EXPECT_EQ(batches.lost(), 0u);
  EXPECT_EQ(old[0].a, 0u);
  EXPECT_EQ(old[1].b, ~1ull) << "held, not overwritten";
  EXPECT_EQ(held_by_subscribers(mapped), 2u) << "the old batch's two chunks";
  old = {};
  EXPECT_TRUE(batches.try_read(1).empty());  // a look that frees what ended
  EXPECT_EQ(held_by_subscribers(mapped), 0u);
}

// Stuck with a batch out: the publisher stops waiting after block_timeout,
// holds the batch's chunks for it, and goes on; the batch stays whole, and
// every hold is gone once the reader has caught up and let go.
TEST_F(ViewsTest, AStuckBatchIsPassedOverWithItsSamplesIntactAndNoHoldLeft) {
  const shm::TopicQos qos{
      .capacity = 8, .overflow = Overflow::block, .block_timeout = 50ms, .max_subscribers = 1, .max_held = 8};
  auto publisher = core.publisher<Pair>("stuck", qos);
  auto batches = core.subscribe<Pair>("stuck", {}, qos).batches();
  for (std::uint64_t i = 0; i < 8; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  auto stuck = batches.try_read(8);
  ASSERT_EQ(stuck.size(), 8u);
  for (std::uint64_t i = 8; i < 1000; ++i)
    ASSERT_TRUE(publisher.publish(pair(i))) << i << ": the chunks held for the stuck reader are within its max_held";
  for (std::uint64_t i = 0; i < 8; ++i) {
    EXPECT_EQ(stuck[i].a, i);
    EXPECT_EQ(stuck[i].b, ~i);
  }
  const MappedTopic mapped{core.domain(), "stuck"};
  EXPECT_EQ(held_by_subscribers(mapped), 8u) << "held for it by the publisher";
  stuck = {};
  std::uint64_t last = 7;
  while (true) {
    auto b = batches.try_read(8);
    if (b.empty()) break;
    for (std::size_t i = 0; i < b.size(); ++i) {
      EXPECT_GT(b[i].a, last);
      EXPECT_EQ(b[i].b, ~b[i].a);
      last = b[i].a;
    }
  }
  EXPECT_EQ(last, 999u);
  EXPECT_EQ(batches.lost(), 1000u - 8 - 8) << "the ring's last 8 were still there";
  EXPECT_EQ(held_by_subscribers(mapped), 0u) << "no hold of the publisher's, nor of the reader's, is left";
  EXPECT_EQ(mapped.header().subscribers[0].lagging.load(), shm::detail::kWaitedFor) << "waited for again";
  std::jthread more{[&] {
    for (std::uint64_t i = 1000; i < 1100; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  }};
  for (std::uint64_t expected = 1000; expected < 1100;) {
    auto b = batches.read(8, Clock::now() + 10s);
    ASSERT_TRUE(b) << b.error().describe();
    for (std::size_t i = 0; i < b->size(); ++i) ASSERT_EQ((*b)[i].a, expected++) << "lossless again";
  }
  EXPECT_EQ(batches.lost(), 1000u - 8 - 8);
}

// Batches out lie between the cursor the publisher sees and the reader's
// kept_end, a span that with the reader's other holds stays within
// max_held (older batches are held once a new one would reach further): so
// the span a publisher holds for a reader it passes over covers all of
// them, and fits the chunks the topic has for it.
TEST_F(ViewsTest, BatchesOutStayWithinMaxHeldOfTheCursorSoAPassedOverReaderKeepsThemAll) {
  const shm::TopicQos qos{
      .capacity = 16, .overflow = Overflow::block, .block_timeout = 50ms, .max_subscribers = 1, .max_held = 4};
  auto publisher = core.publisher<Pair>("reach", qos);
  auto batches = core.subscribe<Pair>("reach", {}, qos).batches();
  for (std::uint64_t i = 0; i < 16; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  auto a = batches.try_read(2);
  ASSERT_EQ(batches.try_read(2).size(), 2u);  // read and let go of at once
  auto b = batches.try_read(2);
  ASSERT_EQ(a.size(), 2u);
  ASSERT_EQ(b.size(), 2u);
  EXPECT_EQ(b[0].a, 4u);
  for (std::uint64_t i = 16; i < 300; ++i) ASSERT_TRUE(publisher.publish(pair(i))) << i;
  for (std::uint64_t i = 0; i < 2; ++i) {
    EXPECT_EQ(a[i].a, i);
    EXPECT_EQ(a[i].b, ~i);
    EXPECT_EQ(b[i].a, 4 + i);
    EXPECT_EQ(b[i].b, ~(4 + i));
  }
}

// A batch the cursor keeps reads each sample's size and stamp beside the
// ring, a held one in its chunk: either way they are the batch's own, and
// stay so after the publisher has written other samples' over them.
TEST_F(ViewsTest, ABatchKeepsEachSamplesSizeAndStampAfterTheRingHasMovedOn) {
  for (const auto overflow : {Overflow::block, Overflow::drop_oldest}) {
    SCOPED_TRACE(overflow == Overflow::block ? "block" : "drop_oldest");
    const shm::TopicQos qos{.capacity = 4,
                            .max_message_size = 64,
                            .overflow = overflow,
                            .block_timeout = 20ms,
                            .max_subscribers = 1,
                            .max_held = 4};
    const auto topic = overflow == Overflow::block ? "sized-block" : "sized-lossy";
    auto publisher = core.publisher<shm::Bytes>(topic, qos);
    auto batches = core.subscribe<shm::Bytes>(topic, {}, qos).batches();
    const std::vector<std::byte> bytes(64, std::byte{7});
    auto publish = [&](std::uint64_t i) {
      ASSERT_TRUE(publisher.publish(std::span{bytes}.first(1 + i % 64), Clock::time_point{Clock::duration{5000 + i}}));
    };
    for (std::uint64_t i = 0; i < 4; ++i) publish(i);
    auto out = batches.try_read(4);
    ASSERT_EQ(out.size(), 4u);
    for (std::uint64_t i = 4; i < 40; ++i) publish(i);  // over every ring entry, many times
    for (std::uint64_t i = 0; i < 4; ++i) {
      EXPECT_EQ(out.bytes(i).size(), 1 + i);
      EXPECT_EQ(out.stamp(i), Clock::time_point{Clock::duration{5000 + i}});
    }
    out = {};
    auto later = batches.try_read(4);
    ASSERT_EQ(later.size(), 4u);
    for (std::uint64_t i = 0; i < 4; ++i) {
      EXPECT_EQ(later.sequence(i), 36 + i);
      EXPECT_EQ(later.bytes(i).size(), 1 + (36 + i) % 64);
      EXPECT_EQ(later.stamp(i), Clock::time_point{Clock::duration{5036 + i}});
    }
  }
}

TEST_F(ViewsTest, ADropOldestTopicsBatchesAreHeldAndNeverOverwritten) {
  const shm::TopicQos qos{.capacity = 4, .max_held = 4};
  auto publisher = core.publisher<Pair>("lossy", qos);
  auto batches = core.subscribe<Pair>("lossy", {}, qos).batches();
  for (std::uint64_t i = 0; i < 4; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  auto held = batches.try_read(4);
  ASSERT_EQ(held.size(), 4u);
  for (std::uint64_t i = 4; i < 100; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  for (std::uint64_t i = 0; i < 4; ++i) EXPECT_EQ(held[i].b, ~i);
  held = {};
  auto later = batches.try_read(4);
  ASSERT_EQ(later.size(), 4u);
  EXPECT_EQ(later[0].a, 96u);
  EXPECT_EQ(batches.lost(), 92u);
}

TEST_F(ViewsTest, ABatchMayOutliveItsReader) {
  auto publisher = core.publisher<std::uint64_t>("outlive");
  shm::Views<std::uint64_t> kept;
  {
    auto batches = core.subscribe<std::uint64_t>("outlive").batches();
    ASSERT_TRUE(publisher.publish(42));
    kept = batches.try_read(1);
  }
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_EQ(kept[0], 42u);
}

// Batches handed to other threads and let go of there, while the reader
// reads on and the publisher fills a small ring: every value arrives once,
// in order, whole.
TEST_F(ViewsTest, BatchesLetGoOfOnOtherThreadsLoseAndTearNothing) {
  constexpr std::uint64_t kTotal = 200000;
  const shm::TopicQos qos{.capacity = 16, .overflow = Overflow::block, .block_timeout = 1h, .max_held = 16};
  auto publisher = core.publisher<Pair>("handoff", qos);
  auto batches = core.subscribe<Pair>("handoff", {}, qos).batches();
  std::jthread produce{[&] {
    for (std::uint64_t i = 0; i < kTotal; ++i) ASSERT_TRUE(publisher.publish(pair(i)));
  }};
  std::uint64_t expected = 0;
  std::atomic<std::uint64_t> torn{0};
  std::vector<std::jthread> letting_go;
  while (expected < kTotal) {
    auto b = batches.read(5, Clock::now() + 10s);
    ASSERT_TRUE(b) << b.error().describe() << " at " << expected;
    for (std::size_t i = 0; i < b->size(); ++i) {
      if ((*b)[i].a != expected || (*b)[i].b != ~expected) torn.fetch_add(1);
      ++expected;
    }
    if (expected % 3 == 0) {
      letting_go.emplace_back([kept = std::move(*b), &torn]() mutable {
        for (std::size_t i = 0; i < kept.size(); ++i)
          if (kept[i].b != ~kept[i].a) torn.fetch_add(1);
      });
      if (letting_go.size() > 4) letting_go.erase(letting_go.begin());
    }
  }
  letting_go.clear();
  EXPECT_EQ(torn.load(), 0u);
  EXPECT_EQ(batches.lost(), 0u);
}

}  // namespace
}  // namespace prime::test
