// Shm topics within one process: zero copy, cursors, history, QoS, checks,
// registry and permissions. Cross-process behaviour is in process_test.cpp.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <time.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/shm.hpp"
#include "shm/domain.hpp"
#include "support/failure.hpp"

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

// The address range of this process's mapping of a /dev/shm file whose name
// contains `part`, read from /proc/self/maps.
std::pair<std::uintptr_t, std::uintptr_t> mapping_of(const std::string& part) {
  std::ifstream maps{"/proc/self/maps"};
  std::string line;
  while (std::getline(maps, line)) {
    if (line.find("/dev/shm/") == std::string::npos || line.find(part) == std::string::npos) continue;
    std::uintptr_t begin = 0, end = 0;
    std::sscanf(line.c_str(), "%lx-%lx", &begin, &end);
    return {begin, end};
  }
  return {0, 0};
}

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
  auto publisher = core.publisher<std::uint64_t>("counter", {.capacity = 2, .max_held = 2});
  auto reader = core.subscribe<std::uint64_t>("counter").subscribe();
  ASSERT_TRUE(publisher.publish(7));
  auto held = reader.try_read();
  ASSERT_TRUE(held);
  for (std::uint64_t i = 0; i < 100; ++i) ASSERT_TRUE(publisher.publish(100 + i));
  EXPECT_EQ(*held->value, 7u) << "the publisher wrote 100 samples around the one still held";
}

TEST_F(ShmTest, SubscribersWhoHoldTooManySamplesAreAClearErrorNotCorruption) {
  auto publisher = core.publisher<int>("greedy", {.capacity = 2, .max_subscribers = 1, .max_held = 1});
  auto reader = core.subscribe<int>("greedy").subscribe();
  std::vector<shm::View<int>> hoard;
  std::optional<Error> refused;
  for (int i = 0; i < 10 && !refused; ++i) {
    if (auto sent = publisher.publish(i); !sent) refused = sent.error();
    while (auto s = reader.try_read()) hoard.push_back(s->value);
  }
  ASSERT_TRUE(refused) << "chunks are finite: hoarding must end in an error";
  EXPECT_EQ(refused->code, Errc::limit_exceeded);
  EXPECT_NE(refused->message.find("greedy"), std::string::npos) << refused->message;
  for (std::size_t i = 0; i < hoard.size(); ++i) EXPECT_EQ(*hoard[i], static_cast<int>(i));
  hoard.clear();
  EXPECT_TRUE(publisher.publish(99)) << "released views free their chunks";
}

TEST_F(ShmTest, EverySubscriberHasItsOwnCursor) {
  auto publisher = core.publisher<int>("ticks");
  auto topic = core.subscribe<int>("ticks");
  auto fast = topic.subscribe();
  auto slow = topic.subscribe();
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(publisher.publish(i));
  EXPECT_EQ(fast.read_all().size(), 5u);
  ASSERT_TRUE(publisher.publish(5));
  EXPECT_EQ(fast.read_all().size(), 1u);
  const auto all = slow.read_all();
  ASSERT_EQ(all.size(), 6u);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(*all[i].value, i);
}

TEST_F(ShmTest, ALateJoinerGetsTheHistoryItAsksFor) {
  auto publisher = core.publisher<int>("map", {.capacity = 8});
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(publisher.publish(i));
  auto last3 = core.subscribe<int>("map", {.history = 3}).subscribe().read_all();
  ASSERT_EQ(last3.size(), 3u);
  EXPECT_EQ(*last3[0].value, 17);
  EXPECT_EQ(*last3[2].value, 19);
  auto capped = core.subscribe<int>("map", {.history = 100}).subscribe().read_all();
  EXPECT_EQ(capped.size(), 8u) << "history is at most the capacity";
  EXPECT_TRUE(core.subscribe<int>("map").subscribe().read_all().empty()) << "no history by default";
}

TEST_F(ShmTest, DropOldestNeverWaitsAndTellsTheSlowSubscriberWhatItLost) {
  auto publisher = core.publisher<int>("lidar", {.capacity = 4});
  auto reader = core.subscribe<int>("lidar").subscribe();
  for (int i = 0; i < 1000; ++i) ASSERT_TRUE(publisher.publish(i));
  const auto kept = reader.read_all();
  ASSERT_EQ(kept.size(), 4u);
  EXPECT_EQ(*kept.front().value, 996);
  EXPECT_EQ(reader.lost(), 996u);
  EXPECT_EQ(kept.front().value.sequence(), 996u);
}

TEST_F(ShmTest, BlockWaitsForTheSlowestSubscriberAndLosesNothing) {
  constexpr int kCount = 20000;
  auto publisher = core.publisher<int>("cmds", {.capacity = 8, .overflow = Overflow::block});
  auto topic = core.subscribe<int>("cmds");
  auto a = topic.subscribe();
  auto b = topic.subscribe();
  std::jthread producer{[&] {
    for (int i = 0; i < kCount; ++i) ASSERT_TRUE(publisher.publish(i));
  }};
  auto read_all_of = [](Reader<shm::View<int>>& reader, std::chrono::microseconds pause) {
    int wrong = 0;
    for (int i = 0; i < kCount; ++i) {
      auto v = reader.read_for(5s);
      if (!v || *v->value != i) ++wrong;
      if (i % 1000 == 0) std::this_thread::sleep_for(pause);
    }
    return wrong;
  };
  int wrong_b = 0;
  std::jthread slow{[&] { wrong_b = read_all_of(b, 2ms); }};  // b lags behind a
  EXPECT_EQ(read_all_of(a, 0us), 0);
  slow.join();
  EXPECT_EQ(wrong_b, 0);
  EXPECT_EQ(a.lost() + b.lost(), 0u);
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
  EXPECT_TRUE(fails_with([] { bounded_string<4> too_long{"laser"}; }, Errc::limit_exceeded, "bounded_string<4>"));
}

TEST_F(ShmTest, RawByteTopicsCarryMessagesUpToTheirMaximum) {
  constexpr std::size_t kMax = 1 << 20;
  auto publisher = core.publisher<shm::Bytes>("camera", {.capacity = 2, .max_message_size = kMax});
  auto reader = core.subscribe<shm::Bytes>("camera", {}, {.capacity = 2, .max_message_size = kMax}).subscribe();
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
  EXPECT_EQ(oversized.error().code, Errc::limit_exceeded);
  EXPECT_NE(oversized.error().message.find("camera"), std::string::npos);
  EXPECT_NE(oversized.error().message.find(std::to_string(kMax + 1) + " bytes exceeds its maximum of " +
                                           std::to_string(kMax)),
            std::string::npos)
      << oversized.error().message;
  EXPECT_TRUE(reader.read_all().empty()) << "nothing was published by the refused loan";
}

TEST_F(ShmTest, OpeningATopicWithAnotherTypeNamesTheTopicAndBothTypes) {
  auto publisher = core.publisher<Pose>("pose");
  EXPECT_TRUE(fails_with([&] { (void)core.subscribe<int>("pose"); }, Errc::type_mismatch,
                         "topic 'pose' carries prime::test::{anonymous}::Pose (32 bytes, align 8, layout 1), not int "
                         "(4 bytes, align 4, layout 1)"));
  shm::Core other{core.domain()};  // another participant, with no mapping of its own yet
  EXPECT_TRUE(fails_with([&] { (void)other.publisher<double>("pose"); }, Errc::type_mismatch, "not double"));
}

TEST_F(ShmTest, APublisherAskingForOtherQosIsRefusedWithBoth) {
  auto sub = core.subscribe<int>("odom", {}, {.capacity = 16});
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("odom", {.capacity = 32}); }, Errc::limit_exceeded,
                         "topic 'odom' exists with capacity 16"));
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("odom", {.capacity = 32}); }, Errc::limit_exceeded,
                         "this publisher asks for capacity 32"));
}

TEST_F(ShmTest, ATopicHasOneLivePublisher) {
  auto first = core.publisher<int>("cmd_vel");
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("cmd_vel"); }, Errc::limit_exceeded,
                         "topic 'cmd_vel' already has a publisher: pid " + std::to_string(::getpid())));
}

TEST_F(ShmTest, SubscribersBeyondTheMaximumAreRefused) {
  auto topic = core.subscribe<int>("busy", {}, {.max_subscribers = 2});
  auto a = topic.subscribe();
  auto b = topic.subscribe();
  EXPECT_TRUE(fails_with([&] { (void)topic.subscribe(); }, Errc::limit_exceeded,
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
  std::jthread later{[&] {
    std::this_thread::sleep_for(50ms);
    (void)publisher.publish(5);
  }};
  auto value = reader.read_for(5s);
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(*value->value, 5);
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

TEST_F(ShmTest, TheRegistryListsParticipantsAndTopicsWithPidsAndQos) {
  auto publisher = core.publisher<int>("status", {.capacity = 32, .overflow = Overflow::block});
  auto reader = core.subscribe<int>("status").subscribe();
  const auto registry = core.registry();
  ASSERT_EQ(registry.participants.size(), 1u);
  EXPECT_EQ(registry.participants[0].pid, static_cast<std::uint32_t>(::getpid()));
  ASSERT_EQ(registry.topics.size(), 1u);
  const auto& topic = registry.topics[0];
  EXPECT_EQ(topic.name, "status");
  EXPECT_EQ(topic.type, "int (4 bytes, align 4, layout 1)");
  EXPECT_EQ(topic.qos.capacity, 32u);
  EXPECT_EQ(topic.qos.overflow, Overflow::block);
  EXPECT_EQ(topic.publisher_pid, static_cast<std::uint32_t>(::getpid()));
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
  auto count = [&] {
    int n = 0;
    for (const auto& entry : std::filesystem::directory_iterator{"/dev/shm"})
      n += entry.path().filename().string().find("prime." + domain + ".") == 0 ? 1 : 0;
    return n;
  };
  {
    shm::Core first{domain};
    auto topic = first.subscribe<int>("a");
    {
      shm::Core second{domain};
      auto other = second.subscribe<int>("b");
    }
    EXPECT_EQ(count(), 3) << "registry and two topics stay while a participant remains";
  }
  EXPECT_EQ(count(), 0);
}

}  // namespace
}  // namespace prime::test
