// Shm topics within one process: zero copy, cursors, history, QoS, held-sample
// budgets, checks, registry, names and permissions. Cross-process behaviour is
// in process_test.cpp.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <time.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <numeric>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/shm.hpp"
#include "prime/shm/detail/registry.hpp"
#include "prime/shm/detail/topic.hpp"
#include "shm/domain.hpp"
#include "shm/mappings.hpp"
#include "shm/mapped_topic.hpp"
#include "support/failure.hpp"
#include "support/futex_calls.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

struct Pose {
  double x, y, theta;
  std::uint64_t stamp_ns;
};

struct Scan {
  bounded_string<32> frame;
  bounded_vector<float, 360> ranges;
};

class ShmTest : public ::testing::Test {
 protected:
  shm::Core core{unique_domain("unit")};
};

TEST_F(ShmTest, APublishedSampleIsReadInPlaceWhereItWasWritten) {
  auto publisher = core.publisher<Pose>("robot/pose");
  auto reader = core.subscribe<Pose>("robot/pose").subscribe();
  auto loan = publisher.loan();
  ASSERT_TRUE(loan) << loan.error().describe();
  const Pose* written = loan->get();
  **loan = Pose{1, 2, 3, 4};
  std::move(*loan).publish();

  auto sample = reader.try_read();
  ASSERT_TRUE(sample);
  EXPECT_EQ(sample->value.get(), written) << "the subscriber reads the very bytes the publisher wrote";
  EXPECT_EQ(sample->value->theta, 3);
  const auto [begin, end] = mapping_of("robot%2Fpose");
  ASSERT_NE(begin, 0u) << "the topic's segment is mapped from /dev/shm";
  const auto at = reinterpret_cast<std::uintptr_t>(sample->value.get());
  EXPECT_TRUE(at >= begin && at + sizeof(Pose) <= end) << "the sample lies inside the shared segment";
}

TEST_F(ShmTest, AHeldSampleIsNeverOverwritten) {
  const shm::TopicQos qos{.capacity = 2, .max_held = 2};
  auto publisher = core.publisher<std::uint64_t>("counter", qos);
  auto reader = core.subscribe<std::uint64_t>("counter", {}, qos).subscribe();
  ASSERT_TRUE(publisher.publish(7));
  auto held = reader.try_read();
  ASSERT_TRUE(held);
  for (std::uint64_t i = 0; i < 100; ++i) ASSERT_TRUE(publisher.publish(100 + i));
  EXPECT_EQ(*held->value, 7u) << "the publisher wrote 100 samples around the one still held";
}

TEST_F(ShmTest, AReaderKeepsToItsMaxHeldSoThePublisherNeverRunsShort) {
  const shm::TopicQos qos{.capacity = 2, .max_subscribers = 1, .max_held = 2};
  auto publisher = core.publisher<int>("greedy", qos);
  auto reader = core.subscribe<int>("greedy", {}, qos).subscribe();
  auto errors = core.errors().subscribe();
  std::vector<shm::View<int>> hoard;
  for (int i = 0; i < 100; ++i) {
    ASSERT_TRUE(publisher.publish(i)) << "publish " << i << ": the reader may not hold more than the topic has room for";
    while (auto s = reader.try_read()) hoard.push_back(s->value);
  }
  ASSERT_EQ(hoard.size(), 2u) << "the reader stops taking at its max_held";
  EXPECT_EQ(*hoard[0], 0);
  EXPECT_EQ(*hoard[1], 1);
  auto said = errors.try_read();
  ASSERT_TRUE(said) << "reading past the budget is reported";
  EXPECT_EQ(said->value.code, Errc::held_limit);
  EXPECT_NE(said->value.message.find("topic 'greedy': a reader holds its max_held of 2 samples"), std::string::npos)
      << said->value.message;
  EXPECT_FALSE(errors.try_read()) << "once, not on every read";

  auto waited = reader.read_for(20ms);
  ASSERT_FALSE(waited);
  EXPECT_EQ(waited.error().code, Errc::held_limit) << waited.error().describe();

  hoard.erase(hoard.begin());  // release one
  auto next = reader.try_read();
  ASSERT_TRUE(next) << "a released view makes room for the next read";
  EXPECT_EQ(*next->value, 98) << "the oldest still in the ring; what was overwritten meanwhile is counted lost";
  EXPECT_EQ(reader.lost(), 96u);
}

TEST_F(ShmTest, AWaitingReadAtItsBudgetGoesOnWhenAnotherThreadReleasesAView) {
  const shm::TopicQos qos{.capacity = 4, .max_held = 1};
  auto publisher = core.publisher<int>("handoff", qos);
  auto reader = core.subscribe<int>("handoff", {}, qos).subscribe();
  ASSERT_TRUE(publisher.publish(1));
  ASSERT_TRUE(publisher.publish(2));
  auto first = reader.try_read();
  ASSERT_TRUE(first);
  std::atomic<bool> released{false};
  std::jthread worker{[&, view = std::move(first->value)]() mutable {
    while (!released.load()) std::this_thread::yield();
    { auto gone = std::move(view); }
  }};
  std::jthread release_soon{[&] { released = true; }};
  auto second = reader.read_for(5s);
  ASSERT_TRUE(second) << second.error().describe();
  EXPECT_EQ(*second->value, 2);
}

TEST_F(ShmTest, LatestNeedsOneSampleOfTheBudgetAndSkipsToTheNewest) {
  const shm::TopicQos qos{.capacity = 8, .max_held = 1};
  auto publisher = core.publisher<int>("pose1", qos);
  auto reader = core.subscribe<int>("pose1", {}, qos).subscribe();
  EXPECT_FALSE(reader.latest());
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(publisher.publish(i));
  auto latest = reader.latest();
  ASSERT_TRUE(latest);
  EXPECT_EQ(*latest->value, 4);
  latest.reset();
  EXPECT_EQ(*reader.latest()->value, 4) << "asked again with nothing new: the same";
  ASSERT_TRUE(publisher.publish(5));
  EXPECT_EQ(*reader.latest()->value, 5) << "the one held was let go first, so a budget of one is enough";
  EXPECT_EQ(reader.lost(), 0u) << "skipped to the newest: read past, not lost";
}

// A collector's chain may still read the value latest() gave it (a copy of
// the reader's) when the next call asks for the newest: at a budget of one,
// letting go of the reader's copy then frees nothing, so it keeps the value
// it has rather than losing it and finding nothing.
TEST_F(ShmTest, LatestKeepsItsValueWhileACopyOfItLivesAtTheBudget) {
  const shm::TopicQos qos{.capacity = 8, .max_held = 1};
  auto publisher = core.publisher<int>("pose2", qos);
  auto reader = core.subscribe<int>("pose2", {}, qos).subscribe();
  ASSERT_TRUE(publisher.publish(1));
  auto in_use = reader.latest();  // a chain still reading it
  ASSERT_TRUE(in_use);
  ASSERT_TRUE(publisher.publish(2));
  auto kept = reader.latest();
  ASSERT_TRUE(kept) << "the value it had, not nothing";
  EXPECT_EQ(*kept->value, 1);
  EXPECT_EQ(*in_use->value, 1) << "and the copy out is intact";
  in_use.reset();
  kept.reset();
  auto newest = reader.latest();
  ASSERT_TRUE(newest) << "once the copies are gone, the newest";
  EXPECT_EQ(*newest->value, 2);
  EXPECT_EQ(reader.lost(), 0u);
}

// A tool joins only a running system: a domain nobody is in is refused,
// and the registry the attempt made is removed again.
TEST_F(ShmTest, JoiningOnlyIfAliveRefusesADomainNobodyIsIn) {
  const auto nobody = unique_domain("nobody");
  try {
    shm::Core tool{nobody, {.participant = "tool", .only_if_alive = true}};
    ADD_FAILURE() << "joined a domain nobody is in";
  } catch (const Failure& f) {
    EXPECT_EQ(f.error().code, Errc::not_found);
    EXPECT_NE(f.error().message.find("has no live participant"), std::string::npos) << f.error().message;
  }
  EXPECT_EQ(segments_of(nobody), 0) << "nothing left behind";
  shm::Core tool{core.domain(), {.participant = "tool", .only_if_alive = true}};  // this test's core is alive
  EXPECT_GE(tool.registry().participants.size(), 2u);
}

TEST_F(ShmTest, ALateJoinerGetsTheHistoryItAsksFor) {
  const shm::TopicQos qos{.capacity = 8};
  auto publisher = core.publisher<int>("map", qos);
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(publisher.publish(i));
  auto last3 = core.subscribe<int>("map", {.history = 3}, qos).subscribe().read_all();
  ASSERT_EQ(last3.size(), 3u);
  EXPECT_EQ(*last3[0].value, 17);
  EXPECT_EQ(*last3[2].value, 19);
  auto reader = core.subscribe<int>("map", {.history = 100}, qos).subscribe();
  std::vector<int> capped;
  while (auto s = reader.try_read()) capped.push_back(*s->value);
  EXPECT_EQ(capped.size(), 8u) << "history is at most the capacity";
  EXPECT_TRUE(core.subscribe<int>("map", {}, qos).subscribe().read_all().empty()) << "no history by default";
}

// A ring whose capacity is not a power of two is indexed by remainder, not
// by mask: it wraps in order, and a slow reader loses exactly what was
// overwritten.
TEST_F(ShmTest, ARingOfCapacityNotAPowerOfTwoWrapsInOrder) {
  const shm::TopicQos qos{.capacity = 5};
  auto publisher = core.publisher<int>("odd", qos);
  auto reader = core.subscribe<int>("odd", {}, qos).subscribe();
  for (int round = 0; round < 7; ++round) {  // 35 sequences: seven laps of the ring
    for (int i = 0; i < 5; ++i) ASSERT_TRUE(publisher.publish(round * 5 + i));
    for (int i = 0; i < 5; ++i) {
      auto s = reader.try_read();
      ASSERT_TRUE(s) << "round " << round;
      EXPECT_EQ(*s->value, round * 5 + i);
    }
  }
  for (int i = 35; i < 48; ++i) ASSERT_TRUE(publisher.publish(i));
  std::vector<int> kept;
  while (auto s = reader.try_read()) kept.push_back(*s->value);
  EXPECT_EQ(kept, (std::vector<int>{43, 44, 45, 46, 47}));
  EXPECT_EQ(reader.lost(), 8u);
}

TEST_F(ShmTest, DropOldestNeverWaitsAndTellsTheSlowSubscriberWhatItLost) {
  const shm::TopicQos qos{.capacity = 4};
  auto publisher = core.publisher<int>("lidar", qos);
  auto reader = core.subscribe<int>("lidar", {}, qos).subscribe();
  for (int i = 0; i < 1000; ++i) ASSERT_TRUE(publisher.publish(i));
  const auto kept = reader.read_all();
  ASSERT_EQ(kept.size(), 4u);
  EXPECT_EQ(*kept.front().value, 996);
  EXPECT_EQ(reader.lost(), 996u);
  EXPECT_EQ(kept.front().value.sequence(), 996u);
}

TEST_F(ShmTest, BlockWaitsForTheSlowestSubscriberAndLosesNothing) {
  constexpr int kCount = 20000;
  const shm::TopicQos qos{.capacity = 8, .overflow = Overflow::block};
  auto publisher = core.publisher<int>("cmds", qos);
  auto topic = core.subscribe<int>("cmds", {}, qos);
  auto a = topic.subscribe();
  auto b = topic.subscribe();
  std::jthread producer{[&] {
    for (int i = 0; i < kCount; ++i) ASSERT_TRUE(publisher.publish(i));
  }};
  auto read_all_of = [](Reader<shm::View<int>>& reader, bool yield) {
    int wrong = 0;
    for (int i = 0; i < kCount; ++i) {
      auto v = reader.read_for(5s);
      if (!v || *v->value != i) ++wrong;
      if (yield) std::this_thread::yield();  // b lags behind a: the publisher waits for the slowest
    }
    return wrong;
  };
  int wrong_b = 0;
  std::jthread slow{[&] { wrong_b = read_all_of(b, true); }};
  EXPECT_EQ(read_all_of(a, false), 0);
  slow.join();
  EXPECT_EQ(wrong_b, 0);
  EXPECT_EQ(a.lost() + b.lost(), 0u);
}

// A reader tells a `block` publisher how far it has read in steps (an eighth
// of the ring), not per sample, and all of it before it waits: the publisher
// never waits for samples a waiting reader has read.
TEST_F(ShmTest, WhatAReaderHasReadIsAcknowledgedBeforeItWaits) {
  const shm::TopicQos qos{.capacity = 32, .overflow = Overflow::block, .block_timeout = 50ms};
  auto publisher = core.publisher<int>("steps", qos);
  auto reader = core.subscribe<int>("steps", {}, qos).subscribe();
  auto errors = core.errors().subscribe();
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(publisher.publish(i));
  for (int i = 0; i < 3; ++i) ASSERT_EQ(*reader.try_read()->value, i);  // fewer than a step of 4
  ASSERT_FALSE(reader.read_for(1ms)) << "nothing more was published";
  // The ring holds 32 from sequence 3 on: all of them go without waiting.
  for (int i = 3; i < 35; ++i) ASSERT_TRUE(publisher.publish(i));
  EXPECT_FALSE(errors.try_read()) << "the publisher waited for the reader";
  for (int i = 3; i < 35; ++i) ASSERT_EQ(*reader.try_read()->value, i);
  EXPECT_EQ(reader.lost(), 0u);
}

// A publisher gives chunks that left the ring back several at a time. One
// that goes while some are on their way gives them back first: the next
// publisher finds every chunk but the ring's free, and can publish on while
// the reader holds its max_held (the topic has no chunk to spare).
TEST_F(ShmTest, APublisherGoneWhileChunksLeaveTheRingStrandsNone) {
  const shm::TopicQos qos{.capacity = 4, .max_subscribers = 1, .max_held = 1};
  auto reader = core.subscribe<int>("strand", {}, qos).subscribe();
  const MappedTopic mapped{core.domain(), "strand"};
  for (int publishes : {5, 6, 7, 8, 9}) {
    {
      auto first = core.publisher<int>("strand", qos);
      for (int i = 0; i < publishes; ++i) ASSERT_TRUE(first.publish(i));
    }
    const auto census = mapped.census();
    EXPECT_EQ(census.ring_only, 4u) << "after " << publishes << " publishes";
    EXPECT_EQ(census.other, 0u) << "after " << publishes << " publishes";
  }
  auto second = core.publisher<int>("strand", qos);
  std::optional<Sample<shm::View<int>>> held;
  for (int i = 0; i < 100; ++i) {
    auto sent = second.publish(i);
    ASSERT_TRUE(sent) << "publish " << i << ": " << sent.error().describe();
    held.reset();
    held = reader.try_read();  // one view held across the next publish
  }
}

TEST_F(ShmTest, BoundedTypesCarryVariableContent) {
  auto publisher = core.publisher<Scan>("scan");
  auto reader = core.subscribe<Scan>("scan").subscribe();
  auto loan = publisher.loan();
  ASSERT_TRUE(loan);
  (*loan)->frame = "laser_front";
  (*loan)->ranges.clear();
  for (int i = 0; i < 360; ++i) (*loan)->ranges.push_back(static_cast<float>(i) / 10);
  std::move(*loan).publish();
  auto scan = reader.try_read();
  ASSERT_TRUE(scan);
  EXPECT_EQ(scan->value->frame, "laser_front");
  ASSERT_EQ(scan->value->ranges.size(), 360u);
  EXPECT_FLOAT_EQ(scan->value->ranges[359], 35.9f);
  EXPECT_TRUE(fails_with([] { bounded_string<4> too_long{"laser"}; }, Errc::too_large, "bounded_string<4>"));
}

TEST_F(ShmTest, RawByteTopicsCarryMessagesUpToTheirMaximum) {
  constexpr std::size_t kMax = 1 << 20;
  const shm::TopicQos qos{.capacity = 2, .max_message_size = kMax, .max_subscribers = 1, .max_held = 1};
  auto publisher = core.publisher<shm::Bytes>("camera", qos);
  auto reader = core.subscribe<shm::Bytes>("camera", {}, qos).subscribe();
  auto image = publisher.loan(640 * 480 * 3);
  ASSERT_TRUE(image);
  for (std::size_t i = 0; i < image->bytes().size(); ++i) image->bytes()[i] = std::byte(i % 251);
  std::move(*image).publish();
  auto received = reader.try_read();
  ASSERT_TRUE(received);
  const auto bytes = received->value.bytes();
  ASSERT_EQ(bytes.size(), 640u * 480 * 3);
  EXPECT_EQ(bytes[1000], std::byte(1000 % 251));

  auto oversized = publisher.loan(kMax + 1);
  ASSERT_FALSE(oversized);
  EXPECT_EQ(oversized.error().code, Errc::too_large);
  EXPECT_NE(oversized.error().message.find("camera"), std::string::npos);
  EXPECT_NE(oversized.error().message.find(std::to_string(kMax + 1) + " bytes exceeds its maximum of " +
                                           std::to_string(kMax)),
            std::string::npos)
      << oversized.error().message;
  received.reset();
  EXPECT_TRUE(reader.read_all().empty()) << "nothing was published by the refused loan";
}

TEST_F(ShmTest, ATopicTakesTheMemoryItsQosSaysAllReservedAtCreation) {
  const shm::TopicQos qos{.capacity = 16, .max_message_size = 4096, .max_subscribers = 2, .max_held = 3};
  const auto expected = shm::topic_memory<shm::Bytes>(qos);
  const std::size_t chunks = (16 + 2 * 3 + 2) * (128 + 4096);  // 24 chunks: a header's block and the payload
  EXPECT_GE(expected, chunks);
  EXPECT_LT(expected - chunks, 16384u) << "the rest is the topic's header, its ring and its infos, each from a page";
  auto publisher = core.publisher<shm::Bytes>("sized", qos);
  struct stat st {};
  ASSERT_EQ(::stat(("/dev/shm/" + shm::detail::segment_name(core.domain(), "topic", "sized")).c_str(), &st), 0);
  EXPECT_EQ(static_cast<std::size_t>(st.st_size), expected);
  EXPECT_GE(static_cast<std::size_t>(st.st_blocks) * 512, expected) << "every byte is allocated, not only sized";
  const auto by_default = shm::topic_memory<std::uint64_t>({});
  EXPECT_GE(by_default, (64u + 8 * 8 + 2) * 256);  // a header's block and a payload's
  EXPECT_LT(by_default, (64u + 8 * 8 + 2) * 256 + 16384)
      << "default QoS: about twice the ring's capacity in chunks, not nine times";
}

TEST_F(ShmTest, OpeningATopicWithAnotherTypeNamesTheTopicAndBothTypes) {
  auto publisher = core.publisher<Pose>("pose");
  EXPECT_TRUE(fails_with([&] { (void)core.subscribe<int>("pose"); }, Errc::type_mismatch,
                         "topic 'pose' carries prime::test::{anonymous}::Pose (32 bytes, align 8, layout 1), not int "
                         "(4 bytes, align 4, layout 1)"));
  shm::Core other{core.domain()};  // another participant, with no mapping of its own yet
  EXPECT_TRUE(fails_with([&] { (void)other.publisher<double>("pose"); }, Errc::type_mismatch, "not double"));
}

// A header that a foreign or broken program wrote would send offsets out of
// the segment, or divide by a capacity of 0: it is refused with what is
// wrong, and tools show the rest of the domain.
TEST_F(ShmTest, ADamagedTopicIsRefusedByNameAndPassedOverByTools) {
  auto fine = core.publisher<int>("fine");
  auto damaged = core.publisher<int>("damaged");
  MappedTopic{core.domain(), "damaged"}.header().capacity = 0;
  shm::Core other{core.domain()};  // with no mapping of its own yet
  EXPECT_TRUE(fails_with([&] { (void)other.subscribe<int>("damaged"); }, Errc::damaged,
                         "topic 'damaged': its shared memory is damaged (a capacity of 0)"));
  EXPECT_TRUE(fails_with([&] { (void)other.observe("damaged"); }, Errc::damaged, "a capacity of 0"));
  MappedTopic{core.domain(), "damaged"}.header().capacity = 1ull << 20;  // more chunks than the segment holds
  EXPECT_TRUE(fails_with([&] { (void)other.subscribe<int>("damaged"); }, Errc::damaged,
                         "does not follow from its capacity"));
  const auto seen = shm::inspect(core.domain());
  ASSERT_TRUE(seen);
  std::vector<std::string> names;
  for (const auto& t : seen->topics) names.push_back(t.name);
  EXPECT_EQ(names, std::vector<std::string>{"fine"});
  EXPECT_EQ(other.reclaim(), 0u) << "reclaiming passes over the damaged topic too";
  ASSERT_TRUE(other.subscribe<int>("fine").subscribe().try_read() == std::nullopt);
}

// A topic laid out by another version of Prime (another ring, chunk stride
// or header) is refused by that name, not read with this version's offsets;
// so is one that claims this version but whose chunks lie elsewhere.
TEST_F(ShmTest, ATopicOfAnotherLayoutIsRefusedByVersion) {
  auto publisher = core.publisher<int>("old");
  const auto layout = shm::detail::kTopicLayout;
  MappedTopic{core.domain(), "old"}.header().layout = layout - 1;
  shm::Core other{core.domain()};
  EXPECT_TRUE(fails_with([&] { (void)other.subscribe<int>("old"); }, Errc::type_mismatch,
                         "topic 'old': made by another version of Prime (layout " + std::to_string(layout - 1) +
                             ", this one reads " + std::to_string(layout) + ")"));
  MappedTopic{core.domain(), "old"}.header().layout = layout;
  MappedTopic{core.domain(), "old"}.header().chunk_stride -= shm::detail::kPayloadAlignment;
  EXPECT_TRUE(fails_with([&] { (void)other.subscribe<int>("old"); }, Errc::damaged,
                         "does not follow from its capacity"));
}

// A topic's geometry (its capacity, counts, sizes, offsets and stride) is
// read once, when its header is checked: a write there afterwards (a
// foreign or broken program) sends no access out of the segment and changes
// nothing a participant does. Publishing and reading go on, one at a time
// and in batches, every value where it was written; a subscriber and a
// publisher that join afterwards take the topic as it was made.
TEST_F(ShmTest, AHeaderWrittenAfterItWasCheckedSendsNoAccessOutOfTheSegment) {
  const shm::TopicQos qos{.capacity = 8, .overflow = Overflow::block, .max_held = 8};
  std::optional<shm::Publisher<int>> publisher{core.publisher<int>("checked", qos)};
  auto reader = core.subscribe<int>("checked", {}, qos).subscribe();
  auto batches = core.subscribe<int>("checked", {}, qos).batches();
  {
    const MappedTopic mapped{core.domain(), "checked"};
    auto& h = mapped.header();
    constexpr std::uint64_t kFar = 1ull << 40;
    h.chunk_stride = h.chunk_count = h.capacity = h.max_message_size = kFar;
    h.ring_offset = h.info_offset = h.chunks_offset = kFar;
    h.max_subscribers = 1000;  // slots past the header's 62
    h.max_held = 1ull << 30;
    h.overflow = 7;
  }
  // Each round's samples stay held while the next is published: the chunks
  // the ring lets go of are then not free, and the publisher searches for others.
  std::vector<shm::View<int>> held;
  auto publish_and_read = [&](int first, auto&... readers) {
    for (int i = first; i < first + 4; ++i) ASSERT_TRUE(publisher->publish(i));
    auto batch = publisher->loan_some(4);
    ASSERT_TRUE(batch) << batch.error().describe();
    ASSERT_EQ(batch->size(), 4u);
    for (std::size_t k = 0; k < 4; ++k) (*batch)[k] = first + 4 + static_cast<int>(k);
    std::move(*batch).publish();
    held.clear();
    auto each = [&](auto& one) {
      for (int i = first; i < first + 8; ++i) {
        auto sample = one.try_read();
        ASSERT_TRUE(sample) << "value " << i;
        EXPECT_EQ(*sample->value, i);
        held.push_back(std::move(sample->value));
      }
    };
    (each(readers), ...);
    {
      const auto views = batches.try_read(8);
      ASSERT_EQ(views.size(), 8u);
      for (std::size_t k = 0; k < 8; ++k) EXPECT_EQ(views[k], first + static_cast<int>(k));
    }
    EXPECT_TRUE(batches.try_read(8).empty());  // and the publisher learns the batch is done with
  };
  // Enough rounds for the publisher's search for free chunks to pass every chunk.
  for (int round = 0; round < 40; ++round) publish_and_read(round * 8, reader);
  const auto joining = core.subscribe<int>("checked", {}, qos);
  EXPECT_EQ(joining.topic_qos().capacity, 8u) << "the topic as it was made";
  EXPECT_EQ(joining.topic_qos().overflow, Overflow::block);
  auto joined = joining.subscribe();
  publish_and_read(320, reader, joined);
  held.clear();
  publisher.reset();
  publisher.emplace(core.publisher<int>("checked", qos));
  publish_and_read(328, reader, joined);
  {
    auto some = publisher->loan_some(9);
    ASSERT_TRUE(some);
    EXPECT_EQ(some->size(), 8u) << "the ring's 8 places, under block";
  }
  std::vector<shm::Loan<int>> loans;
  for (int i = 0; i < 8; ++i) {
    auto loan = publisher->loan();
    ASSERT_TRUE(loan) << loan.error().describe();
    loans.push_back(std::move(*loan));
  }
  auto ninth = publisher->loan();
  ASSERT_FALSE(ninth);
  EXPECT_NE(ninth.error().message.find("all 8 places of its ring are loaned out"), std::string::npos)
      << ninth.error().describe();
}

// A sample whose size and stamp beside the ring belong to another sequence
// (the publisher is writing the next lap's there: a reader it passed over
// meets this) is lost, not read with another sample's size and stamp, by
// a reader of views and a reader of batches alike.
TEST_F(ShmTest, ASampleWhoseInfoIsAnotherLapsIsLostNotMisread) {
  const shm::TopicQos qos{.capacity = 8, .max_message_size = 64};
  auto publisher = core.publisher<shm::Bytes>("lap", qos);
  auto reader = core.subscribe<shm::Bytes>("lap", {}, qos).subscribe();
  auto batches = core.subscribe<shm::Bytes>("lap", {}, qos).batches();
  const std::vector<std::byte> ten(10, std::byte{7});
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(publisher.publish(std::span<const std::byte>{ten}));
  const MappedTopic mapped{core.domain(), "lap"};
  const auto info = mapped.info(1).word.load();
  mapped.info(1).word.store(shm::detail::SampleInfo::pack(1 + 8, 20));  // sequence 9's, a lap on

  auto first = reader.try_read();
  ASSERT_TRUE(first);
  EXPECT_EQ(first->value.sequence(), 0u);
  auto third = reader.try_read();
  ASSERT_TRUE(third);
  EXPECT_EQ(third->value.sequence(), 2u) << "sequence 1 is lost";
  EXPECT_EQ(third->value.bytes().size(), 10u);
  EXPECT_EQ(reader.lost(), 1u);

  const auto before = batches.try_read(8);
  ASSERT_EQ(before.size(), 1u) << "a batch ends before the sample";
  const auto after = batches.try_read(8);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(after.sequence(0), 2u);
  EXPECT_EQ(after.bytes(0).size(), 10u);
  mapped.info(1).word.store(info);
}

// A ring entry naming a chunk the topic does not have, or a size larger
// than its messages may be (written by a foreign or broken program), is
// not followed out of the segment: the sample is lost, or its bytes end at
// the topic's maximum. A larger maximum written in the header lets no
// larger message in.
TEST_F(ShmTest, ASampleDamagedInSharedMemoryIsLostOrCutNotReadOutOfTheSegment) {
  const shm::TopicQos qos{.capacity = 8, .max_message_size = 64, .overflow = Overflow::block};
  auto publisher = core.publisher<shm::Bytes>("raw", qos);
  auto reader = core.subscribe<shm::Bytes>("raw", {}, qos).subscribe();
  auto batches = core.subscribe<shm::Bytes>("raw", {}, qos).batches();
  const std::vector<std::byte> ten(10, std::byte{7});
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(publisher.publish(std::span<const std::byte>{ten}));
  const MappedTopic mapped{core.domain(), "raw"};
  const auto entry = mapped.ring(1).load();
  mapped.ring(1).store(shm::detail::RingEntry::pack(1, shm::detail::kNoChunk - 1));  // 2 GiB past the chunks
  mapped.info(2).word.store(shm::detail::SampleInfo::pack(2, shm::detail::SampleInfo::kSizeMask));  // 1 TiB
  mapped.header().max_message_size = 1ull << 40;

  auto oversized = publisher.loan(65);
  ASSERT_FALSE(oversized) << "the maximum is the topic's as it was made";
  EXPECT_NE(oversized.error().message.find("a message of 65 bytes exceeds its maximum of 64 bytes"), std::string::npos)
      << oversized.error().describe();

  auto first = reader.try_read();
  ASSERT_TRUE(first);
  EXPECT_EQ(first->value.bytes().size(), 10u);
  auto third = reader.try_read();
  ASSERT_TRUE(third);
  EXPECT_EQ(third->value.sequence(), 2u) << "the sample whose entry names no chunk of the topic is lost";
  EXPECT_EQ(reader.lost(), 1u);
  EXPECT_EQ(third->value.bytes().size(), 64u) << "a size past the maximum ends there";

  const auto before = batches.try_read(8);
  ASSERT_EQ(before.size(), 1u) << "a batch ends before the damaged entry";
  EXPECT_EQ(before.bytes(0).size(), 10u);
  const auto after = batches.try_read(8);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(after.sequence(0), 2u);
  EXPECT_EQ(after.bytes(0).size(), 64u);
  mapped.ring(1).store(entry);
}

// Text in a topic's header (its type's name and description) that a
// foreign or broken program left without its end is read up to its room,
// not past it.
TEST_F(ShmTest, TextInSharedMemoryWithoutItsEndIsReadToItsRoomNotPast) {
  auto publisher = core.publisher<int>("texts");
  const MappedTopic mapped{core.domain(), "texts"};
  auto& h = mapped.header();
  std::memset(h.schema, 'x', sizeof h.schema);
  std::memset(h.type.name, 'y', sizeof h.type.name);
  const auto seen = shm::inspect(core.domain());
  ASSERT_TRUE(seen);
  ASSERT_EQ(seen->topics.size(), 1u);
  EXPECT_EQ(seen->topics[0].schema, std::string(shm::detail::kSchemaCapacity, 'x'));
  EXPECT_EQ(seen->topics[0].type, std::string(Fingerprint::kNameCapacity, 'y') + " (4 bytes, align 4, layout 1)");
}

TEST_F(ShmTest, OtherQosIsRefusedWhicheverSideOpensTheTopicFirst) {
  const shm::TopicQos sixteen{.capacity = 16}, thirty_two{.capacity = 32};
  {
    auto subscriber_first = core.subscribe<int>("odom", {}, sixteen);
    EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("odom", thirty_two); }, Errc::qos_mismatch,
                           "topic 'odom' exists with capacity 16"));
    EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("odom", thirty_two); }, Errc::qos_mismatch,
                           "this publisher asks for capacity 32"));
  }
  shm::Core other{unique_domain("order")};
  auto publisher_first = other.publisher<int>("odom", sixteen);
  EXPECT_TRUE(fails_with([&] { (void)other.subscribe<int>("odom", {}, thirty_two); }, Errc::qos_mismatch,
                         "topic 'odom' exists with capacity 16"));
  EXPECT_TRUE(fails_with([&] { (void)other.subscribe<int>("odom", {}, thirty_two); }, Errc::qos_mismatch,
                         "this subscriber asks for capacity 32"));
  EXPECT_NO_THROW((void)other.subscribe<int>("odom", {}, {.capacity = 16, .block_timeout = 5ms}))
      << "the block timeout is the publisher's own, not the topic's";
}

TEST_F(ShmTest, ATopicHasOneLivePublisher) {
  auto first = core.publisher<int>("cmd_vel");
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("cmd_vel"); }, Errc::in_use,
                         "topic 'cmd_vel' already has a publisher: participant 'shm_test' (pid " +
                             std::to_string(::getpid()) + ")"));
  shm::Core other{core.domain()};
  EXPECT_TRUE(fails_with([&] { (void)other.publisher<int>("cmd_vel"); }, Errc::in_use, "already has a publisher"))
      << "another participant of the same process is a live one too";
}

TEST_F(ShmTest, ALoanMayOutliveItsPublisher) {
  auto reader = core.subscribe<int>("late").subscribe();
  std::optional<shm::Loan<int>> loan;
  {
    auto publisher = core.publisher<int>("late");
    auto slot = publisher.loan();
    ASSERT_TRUE(slot);
    loan.emplace(std::move(*slot));
    **loan = 42;
  }
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("late"); }, Errc::in_use, "already has a publisher"))
      << "the publisher's role lasts while its loan does";
  std::move(*loan).publish();
  loan.reset();
  auto got = reader.try_read();
  ASSERT_TRUE(got);
  EXPECT_EQ(*got->value, 42);
  EXPECT_NO_THROW((void)core.publisher<int>("late")) << "the last loan ended the old publisher";
}

TEST_F(ShmTest, ABatchIsWrittenInPlaceAndReadInOneStepInOrderWithItsStamps) {
  const shm::TopicQos qos{.capacity = 16, .max_held = 16};
  auto publisher = core.publisher<Pose>("batch", qos);
  auto reader = core.subscribe<Pose>("batch", {}, qos).subscribe();
  auto batch = publisher.loan_some(5);
  ASSERT_TRUE(batch) << batch.error().describe();
  ASSERT_EQ(batch->size(), 5u);
  std::vector<const Pose*> written;
  std::vector<Clock::time_point> stamps;
  const auto t0 = Clock::now() - 1s;
  for (std::size_t i = 0; i < batch->size(); ++i) {
    (*batch)[i] = Pose{static_cast<double>(i), 0, 0, i};
    written.push_back(&(*batch)[i]);
    stamps.push_back(t0 + std::chrono::milliseconds{i});
  }
  EXPECT_FALSE(reader.try_read()) << "nothing is visible before the batch is published";
  std::move(*batch).publish(stamps);
  std::vector<Sample<shm::View<Pose>>> got;
  ASSERT_EQ(reader.read_some(got, 100, Clock::now() + 1s), 5u);
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].value.get(), written[i]) << "read where it was written";
    EXPECT_EQ(got[i].value->stamp_ns, i);
    EXPECT_EQ(got[i].stamp, stamps[i]);
  }
  EXPECT_EQ(reader.lost(), 0u);
}

// Every loan out takes a place in the ring: under block, a loan made while
// others are out waits for the room their publishes take too, and loans
// stop at the ring's capacity with an error that says so.
TEST_F(ShmTest, EveryLoanOutTakesItsPlaceInTheRing) {
  const shm::TopicQos qos{.capacity = 4, .overflow = Overflow::block, .block_timeout = 50ms, .max_held = 4};
  auto publisher = core.publisher<int>("loans-out", qos);
  auto reader = core.subscribe<int>("loans-out", {}, qos).subscribe();
  auto errors = core.errors().subscribe();
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(publisher.publish(i));
  auto last_place = publisher.loan();
  ASSERT_TRUE(last_place);
  EXPECT_FALSE(errors.try_read()) << "the ring had room for one more";
  ASSERT_EQ(*reader.try_read()->value, 0);
  auto freed_place = publisher.loan();  // the reader took sample 0: room for this one
  ASSERT_TRUE(freed_place);
  EXPECT_FALSE(errors.try_read()) << "the reader made room for the second loan";
  auto batch = publisher.loan_some(4);
  ASSERT_TRUE(batch);  // no room: waits 50 ms for the reader, then passes it over
  EXPECT_TRUE(errors.try_read()) << "two loans out fill the ring: the batch had to wait";
  EXPECT_EQ(batch->size(), 2u) << "the ring's other places are loaned out";
  auto beyond = publisher.loan();
  ASSERT_FALSE(beyond) << "4 loans out on a ring of 4";
  EXPECT_EQ(beyond.error().code, Errc::queue_full);
  EXPECT_NE(beyond.error().message.find("all 4 places of its ring are loaned out"), std::string::npos)
      << beyond.error().message;
  **last_place = 3;
  std::move(*last_place).publish();
  **freed_place = 4;
  std::move(*freed_place).publish();
  (*batch)[0] = 5;
  (*batch)[1] = 6;
  std::move(*batch).publish();
  for (int expected : {3, 4, 5, 6}) {  // passed over, the reader lost samples 1 and 2 to them
    auto v = reader.try_read();
    ASSERT_TRUE(v);
    EXPECT_EQ(*v->value, expected);
  }
  EXPECT_EQ(reader.lost(), 2u);
}

// Under drop_oldest a loan's publish overwrites nothing a subscriber must
// have taken: a publisher may keep more loans out than the ring holds
// (double buffering on a ring of one), as long as the topic has chunks to
// spare, and is told so when it has none.
TEST_F(ShmTest, UnderDropOldestLoansOutAreBoundedByTheChunksNotTheRing) {
  const shm::TopicQos qos{.capacity = 1, .max_subscribers = 1, .max_held = 1};
  auto publisher = core.publisher<int>("double-buffer", qos);
  auto reader = core.subscribe<int>("double-buffer", {}, qos).subscribe();
  auto front = publisher.loan();
  auto back = publisher.loan();
  ASSERT_TRUE(front && back) << "two loans out on a ring of one";
  **front = 1;
  **back = 2;
  std::move(*front).publish();
  std::move(*back).publish();
  auto latest = reader.try_read();
  ASSERT_TRUE(latest);
  EXPECT_EQ(*latest->value, 2);
  EXPECT_EQ(reader.lost(), 1u);
  latest.reset();
  std::vector<shm::Loan<int>> out;
  std::optional<Error> refused;
  while (!refused) {
    auto loan = publisher.loan();
    if (loan) out.push_back(std::move(*loan));
    else refused = loan.error();
    ASSERT_LE(out.size(), 8u) << "the topic has 4 chunks";
  }
  EXPECT_GE(out.size(), 2u);
  EXPECT_EQ(refused->code, Errc::queue_full);
  EXPECT_NE(refused->message.find("this publisher has " + std::to_string(out.size()) + " loaned out"), std::string::npos)
      << refused->message;
  out.pop_back();  // dropped unpublished: its chunk is free again
  EXPECT_TRUE(publisher.loan());
}

TEST_F(ShmTest, ABatchIsAsLargeAsTheRingHasRoomForUnderBlock) {
  const shm::TopicQos qos{.capacity = 8, .overflow = Overflow::block, .block_timeout = 50ms, .max_held = 8};
  auto publisher = core.publisher<int>("room", qos);
  auto reader = core.subscribe<int>("room", {}, qos).subscribe();
  auto first = publisher.loan_some(100);
  ASSERT_TRUE(first);
  EXPECT_EQ(first->size(), 8u) << "never more than the ring's capacity";
  for (std::size_t i = 0; i < first->size(); ++i) (*first)[i] = static_cast<int>(i);
  std::move(*first).publish();
  std::vector<Sample<shm::View<int>>> got;
  ASSERT_EQ(reader.read_some(got, 3, Clock::now() + 1s), 3u);
  got.clear();
  auto second = publisher.loan_some(100);
  ASSERT_TRUE(second);
  EXPECT_EQ(second->size(), 3u) << "the subscriber has taken 3: room for 3 more";
  for (std::size_t i = 0; i < second->size(); ++i) (*second)[i] = static_cast<int>(8 + i);
  std::move(*second).publish();
  for (int expected = 3; expected < 11; ++expected) {
    auto v = reader.try_read();
    ASSERT_TRUE(v);
    EXPECT_EQ(*v->value, expected);
  }
  EXPECT_EQ(reader.lost(), 0u);
}

// A batch hands every chunk it pushes out of the ring to the next loans:
// the publisher keeps them by its bit (spares), so the next batch takes
// them without claiming each again by a read-modify-write. With room for
// only 64 spares, a batch of 128 let 64 go, and the next claimed them back.
TEST_F(ShmTest, ABatchKeepsEveryChunkItPushesOutOfTheRingForTheNextLoans) {
  constexpr std::size_t kRing = 128;
  const shm::TopicQos qos{.capacity = kRing, .max_subscribers = 1, .max_held = kRing};
  auto publisher = core.publisher<int>("wide", qos);
  const MappedTopic mapped{core.domain(), "wide"};
  for (int round = 0; round < 3; ++round) {
    auto batch = publisher.loan_some(kRing);
    ASSERT_TRUE(batch) << batch.error().describe();
    ASSERT_EQ(batch->size(), kRing) << "round " << round;
    for (std::size_t i = 0; i < kRing; ++i) (*batch)[i] = static_cast<int>(i);
    std::move(*batch).publish();
    const auto census = mapped.census();
    EXPECT_EQ(census.ring_only, kRing) << "round " << round;
    // Round 0 pushed nothing out: the publisher keeps its claimed-ahead few.
    if (round > 0) {
      EXPECT_EQ(census.other, kRing) << "round " << round << ": the chunks pushed out are kept";
    }
  }
}

TEST_F(ShmTest, ABatchDroppedUnpublishedGivesItsSlotsBack) {
  const shm::TopicQos qos{.capacity = 8, .max_held = 2};
  auto publisher = core.publisher<int>("dropped", qos);
  auto reader = core.subscribe<int>("dropped", {}, qos).subscribe();
  for (int round = 0; round < 100; ++round) {
    auto batch = publisher.loan_some(8);
    ASSERT_TRUE(batch) << "round " << round << ": " << batch.error().describe();
    EXPECT_EQ(batch->size(), 8u);
  }
  ASSERT_TRUE(publisher.publish(5));
  auto v = reader.try_read();
  ASSERT_TRUE(v);
  EXPECT_EQ(*v->value, 5) << "nothing of the dropped batches was published";
  EXPECT_FALSE(reader.try_read());
}

TEST_F(ShmTest, ABatchNeedsOneStampPerSlotAndMayOutliveItsPublisher) {
  auto reader = core.subscribe<int>("late-batch").subscribe();
  std::optional<shm::Batch<int>> batch;
  {
    auto publisher = core.publisher<int>("late-batch");
    EXPECT_FALSE(publisher.loan_some(0)) << "a batch of nothing is refused";
    auto slots = publisher.loan_some(3);
    ASSERT_TRUE(slots);
    batch.emplace(std::move(*slots));
  }
  for (std::size_t i = 0; i < batch->size(); ++i) (*batch)[i] = 40 + static_cast<int>(i);
  const std::vector<Clock::time_point> two(2, Clock::now());
  EXPECT_TRUE(fails_with([&] { std::move(*batch).publish(two); }, Errc::invalid_argument, "3 slots published with 2 stamps"));
  std::move(*batch).publish();
  batch.reset();
  for (int expected = 40; expected < 43; ++expected) {
    auto v = reader.try_read();
    ASSERT_TRUE(v);
    EXPECT_EQ(*v->value, expected);
  }
  EXPECT_NO_THROW((void)core.publisher<int>("late-batch")) << "the batch ended the old publisher";
}

TEST_F(ShmTest, ASubscriberPassedOverIsWaitedForAgainOnceABatchReadCatchesUp) {
  const shm::TopicQos qos{.capacity = 8, .overflow = Overflow::block, .block_timeout = 50ms, .max_held = 8};
  auto publisher = core.publisher<int>("laggard", qos);
  auto reader = core.subscribe<int>("laggard", {}, qos).subscribe();
  auto errors = core.errors().subscribe();
  int n = 0;
  while (n < 9) ASSERT_TRUE(publisher.publish(n++));  // the 9th waits 50 ms, then passes the reader over
  ASSERT_TRUE(errors.try_read()) << "passed over once";
  std::vector<Sample<shm::View<int>>> got;
  std::size_t last = 0;
  while (got.empty() || *got.back().value != 8) {  // the first read skips what was lost, the next takes the rest
    auto read = reader.read_some(got, 8, Clock::now() + 1s);
    ASSERT_TRUE(read) << read.error().describe();
    last = *read;
  }
  EXPECT_GT(last, 1u) << "it caught up in a batch, not one sample at a time";
  got.clear();
  while (n < 18) ASSERT_TRUE(publisher.publish(n++));  // the 9th after the catch-up waits for it again
  auto again = errors.try_read();
  ASSERT_TRUE(again) << "caught up by a batch read, the reader is waited for (and passed over) again";
  EXPECT_NE(again->value.message.find("read nothing for 50 ms"), std::string::npos) << again->value.message;
}

TEST_F(ShmTest, AViewCarriesTheStampThePublisherGaveIt) {
  auto publisher = core.publisher<int>("stamped");
  auto reader = core.subscribe<int>("stamped").subscribe();
  const auto taken = Clock::now() - 30ms;
  ASSERT_TRUE(publisher.publish(1, taken));
  auto got = reader.try_read();
  ASSERT_TRUE(got);
  EXPECT_EQ(got->value.stamp(), taken);
  EXPECT_EQ(got->stamp, taken);
}

TEST_F(ShmTest, SequencesGoOnAcrossTheRingsTwoToTheFortiethWrap) {
  using shm::detail::RingEntry;
  constexpr std::uint64_t kWrap = 1ull << 40;
  static_assert(RingEntry::ahead(RingEntry::pack(kWrap + 2, 7), kWrap - 3) == 5);
  static_assert(RingEntry::ahead(RingEntry::pack(kWrap - 3, 7), kWrap + 2) == -5);
  static_assert(RingEntry::chunk(RingEntry::pack(kWrap + 2, 7)) == 7);

  // A topic whose first sequence lies just short of the wrap: publish, read
  // and overwrite across it.
  const shm::TopicQos qos{.capacity = 4, .max_message_size = sizeof(std::uint64_t), .max_subscribers = 8, .max_held = 8};
  auto registry = shm::detail::Registry::join(unique_domain("wrap"), {}, "test");
  auto topic = shm::detail::Topic::open(registry, "wrapping", Fingerprint::of<std::uint64_t>(), qos, "u64", kWrap - 6);
  shm::Publisher<std::uint64_t> publisher{topic, 1s, shm::PublishFence::full, {}};
  shm::SubscriptionReader<std::uint64_t> reader{topic, {}, {}};
  for (std::uint64_t i = 0; i < 12; ++i) {
    ASSERT_TRUE(publisher.publish(i));
    auto got = reader.try_read();
    ASSERT_TRUE(got) << "sample " << i;
    EXPECT_EQ(*got->value, i);
    EXPECT_EQ(got->value.sequence(), kWrap - 6 + i);
  }
  for (std::uint64_t i = 12; i < 20; ++i) ASSERT_TRUE(publisher.publish(i));
  std::vector<std::uint64_t> kept;
  while (auto got = reader.try_read()) kept.push_back(*got->value);
  EXPECT_EQ(kept, (std::vector<std::uint64_t>{16, 17, 18, 19})) << "a lapped reader past the wrap keeps the newest";
  EXPECT_EQ(reader.lost(), 4u);
}

TEST_F(ShmTest, SubscribersBeyondTheMaximumAreRefused) {
  auto topic = core.subscribe<int>("busy", {}, {.max_subscribers = 2});
  auto a = topic.subscribe();
  auto b = topic.subscribe();
  EXPECT_TRUE(fails_with([&] { (void)topic.subscribe(); }, Errc::too_many_subscribers,
                         "topic 'busy' has its maximum of 2 subscribers"));
  { auto gone = std::move(a); }
  EXPECT_NO_THROW((void)topic.subscribe()) << "a subscriber that leaves frees its slot";
}

TEST_F(ShmTest, AnIdleSubscriberSleepsAndBurnsNoCpu) {
  auto publisher = core.publisher<int>("silence");
  auto reader = core.subscribe<int>("silence").subscribe();
  timespec before{}, after{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &before);
  auto nothing = reader.read_for(1s);
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &after);
  ASSERT_FALSE(nothing);
  EXPECT_EQ(nothing.error().code, Errc::timeout);
  const auto cpu = std::chrono::seconds{after.tv_sec - before.tv_sec} + std::chrono::nanoseconds{after.tv_nsec - before.tv_nsec};
  EXPECT_LT(cpu, 20ms) << "a second of silence cost " << std::chrono::duration<double, std::milli>(cpu).count()
                       << " ms of CPU: the reader should sleep on the futex";
}

TEST_F(ShmTest, ASleepingSubscriberWakesForANewSample) {
  auto publisher = core.publisher<int>("wake");
  auto reader = core.subscribe<int>("wake", {.spin = 0us}).subscribe();
  const MappedTopic mapped{core.domain(), "wake"};
  std::jthread later{[&] {
    if (mapped.a_subscriber_sleeps()) (void)publisher.publish(5);
  }};
  auto value = reader.read_for(20s);
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(*value->value, 5);
}

TEST_F(ShmTest, PublishingWithNoSleeperMakesNoSystemCall) {
  auto publisher = core.publisher<int>("quiet");
  auto reader = core.subscribe<int>("quiet").subscribe();
  const auto before = futex_calls();
  for (int i = 0; i < 1000; ++i) {
    ASSERT_TRUE(publisher.publish(i));
    ASSERT_TRUE(reader.try_read());
  }
  EXPECT_EQ(futex_calls(), before);
  std::atomic<std::uint32_t> word{0};  // the count is live: a wake is one call
  shm::detail::futex_wake_all(word);
  EXPECT_EQ(futex_calls(), before + 1);
}

TEST_F(ShmTest, ASubscriptionIsASourceOfTheTopology) {
  liberty::Core local;
  auto publisher = core.publisher<Pose>("pose");
  auto poses = core.subscribe<Pose>("pose");
  auto speed = poses | local.chain([](const Pose& p) { return p.x * 2; }, "speed");
  auto latest = collector(local, speed);
  auto reader = speed.subscribe();
  ASSERT_TRUE(publisher.publish({1.5, 0, 0, 0}));
  auto value = reader.read_for(5s);
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(value->value, 3.0);
  EXPECT_NE(speed.graph().text().find("pose [source, shm] -> speed [chain, liberty]"), std::string::npos)
      << speed.graph().text();
}

TEST_F(ShmTest, ASyncOfTopicsHoldsNoMoreThanTheirMaxHeld) {
  const shm::TopicQos qos{.capacity = 64, .max_held = 4};  // less than the sync's depth of 32
  auto lidar = core.publisher<int>("sync/lidar", qos);
  auto odom = core.publisher<int>("sync/odom", qos);
  auto sets = sync(exact_time, core.subscribe<int>("sync/lidar", {}, qos), core.subscribe<int>("sync/odom", {}, qos));
  auto newest = collector(core, sets);
  auto reader = sets.subscribe();
  const auto t0 = Clock::now();
  for (int i = 0; i < 500; ++i) {
    const auto stamp = t0 + std::chrono::milliseconds{i};
    ASSERT_TRUE(lidar.publish(i, stamp)) << i;
    ASSERT_TRUE(odom.publish(1000 + i, stamp)) << i;
    auto set = reader.read_for(5s);
    ASSERT_TRUE(set) << set.error().describe();
    EXPECT_EQ(*std::get<0>(set->value), i);
    EXPECT_EQ(*std::get<1>(set->value), 1000 + i);
    if (i % 10 == 0) {
      auto [l, o] = newest(Token{});
      EXPECT_EQ(*o, *l + 1000);
    }
  }
  EXPECT_TRUE(fails_with([&] { (void)sync(exact_time, core.subscribe<int>("sync/lidar", {}, qos),
                                          core.subscribe<int>("thin", {}, {.max_held = 2})); },
                         Errc::invalid_argument, "source 'thin' lets a reader hold 2 values (max_held); a sync needs at least 4"));
  EXPECT_TRUE(fails_with([&] { (void)sync(exact_time, core.subscribe<int>("sync/lidar", {}, qos),
                                          core.subscribe<int>("thinnest", {}, {.max_held = 1})); },
                         Errc::invalid_argument, "source 'thinnest' lets a reader hold 1 values (max_held); a sync needs at least 4"));
}

TEST_F(ShmTest, TheRegistryListsParticipantsAndTopicsWithPidsAndQos) {
  const shm::TopicQos qos{.capacity = 32, .overflow = Overflow::block};
  auto publisher = core.publisher<int>("status", qos);
  auto reader = core.subscribe<int>("status", {}, qos).subscribe();
  const auto registry = core.registry();
  ASSERT_EQ(registry.participants.size(), 1u);
  EXPECT_EQ(registry.participants[0].pid, static_cast<std::uint32_t>(::getpid()));
  EXPECT_TRUE(registry.participants[0].alive);
  ASSERT_EQ(registry.topics.size(), 1u);
  const auto& topic = registry.topics[0];
  EXPECT_EQ(topic.name, "status");
  EXPECT_EQ(topic.type, "int (4 bytes, align 4, layout 1)");
  EXPECT_EQ(topic.qos.capacity, 32u);
  EXPECT_EQ(topic.qos.overflow, Overflow::block);
  EXPECT_EQ(topic.publisher_pid, static_cast<std::uint32_t>(::getpid()));
  EXPECT_EQ(topic.publisher, "shm_test");
  EXPECT_EQ(topic.subscriber_pids, std::vector<std::uint32_t>{static_cast<std::uint32_t>(::getpid())});
}

mode_t mode_of_segment(const std::string& part) {
  std::ifstream maps{"/proc/self/maps"};
  std::string line;
  while (std::getline(maps, line)) {
    const auto at = line.find("/dev/shm/");
    if (at == std::string::npos || line.find(part) == std::string::npos) continue;
    struct stat st {};
    if (::stat(line.substr(at).c_str(), &st) == 0) return st.st_mode & 0777;
  }
  return 0;
}

TEST(ShmPermissions, SegmentsAre0600ByDefaultAndConfigurable) {
  shm::Core mine{unique_domain("perm")};
  auto a = mine.subscribe<int>("private_topic");
  EXPECT_EQ(mode_of_segment("private_topic"), 0600u);
  shm::Core shared{unique_domain("perm"), {.permissions = 0660}};
  auto b = shared.subscribe<int>("group_topic");
  EXPECT_EQ(mode_of_segment("group_topic"), 0660u);
}

TEST(ShmDomain, TheLastParticipantToLeaveRemovesTheSegments) {
  const auto domain = unique_domain("leave");
  {
    shm::Core first{domain};
    auto topic = first.subscribe<int>("a");
    {
      shm::Core second{domain};
      auto other = second.subscribe<int>("b");
    }
    EXPECT_EQ(segments_of(domain), 3) << "registry and two topics stay while a participant remains";
  }
  EXPECT_EQ(segments_of(domain), 0);
}

TEST(ShmDomain, NamesAreEscapedSoDomainsAndTopicsNeverCollide) {
  using shm::detail::segment_name;
  EXPECT_NE(segment_name("a.topic", "topic", "x"), segment_name("a", "topic", "topic.x"));
  EXPECT_EQ(segment_name("robot", "topic", "lidar/scan.v2"), "prime.robot.topic.lidar%2Fscan%2Ev2");
  const auto a = unique_domain("dots") + ".topic";
  const auto b = a.substr(0, a.size() - std::string{".topic"}.size());
  shm::Core one{a};
  shm::Core two{b};
  auto x = one.publisher<int>("x");
  EXPECT_NO_THROW((void)two.publisher<double>("topic.x")) << "another domain's topic, not the same segment";
}

TEST(ShmDomain, AnEscapedNameReadsBackAndAnOddOneStaysAsItIs) {
  using shm::detail::unescape;
  EXPECT_EQ(unescape("lidar%2Fscan%2Ev2"), "lidar/scan.v2");
  EXPECT_EQ(unescape("odd%zz%4"), "odd%zz%4") << "no name segment_name made: taken as it is, not an exception";
  EXPECT_EQ(unescape("%+1x"), "%+1x");
}

// Two servers that start at once both find the segment of a server gone
// for good, made for other limits, and each replaces it. The one that comes
// second, having mapped the old segment before the first replaced it, must
// not remove the new one (its server would serve a segment no client finds).
TEST(ShmSegment, ASegmentReplacedMeanwhileIsNotRemovedByWhoeverFoundTheOldOne) {
  const auto name = shm::detail::segment_name(unique_domain("replaced"), "service", "x");
  const auto make = [&](std::byte value) {
    return shm::detail::Segment::open(
        name, {}, 4096, "test segment", [](std::byte* data, std::size_t) { return data[0] != std::byte{0}; },
        [&](std::byte* data, std::size_t) { data[0] = value; });
  };
  std::optional<shm::detail::Segment> old{make(std::byte{1})};
  auto first = shm::detail::Segment::open_existing(name);   // each server maps what it finds
  auto second = shm::detail::Segment::open_existing(name);
  ASSERT_TRUE(first && second);
  first->remove_name("test segment");
  auto fresh = make(std::byte{2});
  second->remove_name("test segment");  // late: what it found is gone already
  EXPECT_TRUE(fresh.linked()) << "the new segment keeps its name";
  auto found = shm::detail::Segment::open_existing(name);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->data()[0], std::byte{2});
  fresh.remove_name("test segment");
  EXPECT_FALSE(shm::detail::Segment::open_existing(name));
}

TEST(ShmDomain, AParticipantStaysWhileAnythingItMadeLives) {
  const auto domain = unique_domain("outlive");
  shm::Core watcher{domain};
  std::optional<Reader<shm::View<int>>> reader;
  {
    shm::Core core{domain, {.participant = "short-lived"}};
    reader.emplace(core.subscribe<int>("t").subscribe());
  }
  auto names = [&] {
    std::vector<std::string> alive;
    for (const auto& p : watcher.registry().participants)
      if (p.alive) alive.push_back(p.name);
    return alive;
  };
  EXPECT_EQ(names().size(), 2u) << "its reader still reads, so its slots must not be reclaimed";
  EXPECT_EQ(watcher.reclaim(), 0u);
  reader.reset();
  EXPECT_EQ(names().size(), 1u);
}

}  // namespace
}  // namespace prime::test
