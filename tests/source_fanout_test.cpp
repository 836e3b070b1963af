// How an in-process source hands one value to several readers: shared, moved
// to the last reader to take it and copied by the others, never by the
// publisher.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/topology/local_source.hpp"
#include "support/threads.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// A value that counts its copies and remembers which threads made them.
struct Counted {
  static inline std::atomic<int> copies = 0;
  static inline std::atomic<int> copies_begun = 0;
  static inline std::atomic<bool> hold_copies = false;  // a copy waits, before it reads, while this is set
  static inline std::mutex mutex;
  static inline std::set<std::thread::id> copied_on;

  int value = 0;
  std::vector<int> payload;

  Counted(int v, std::size_t size) : value{v}, payload(size, v) {}
  Counted(const Counted& other) : value{other.value}, payload{(begin_copy(), other.payload)} {
    ++copies;
    std::scoped_lock lock{mutex};
    copied_on.insert(std::this_thread::get_id());
  }
  Counted(Counted&&) noexcept = default;
  Counted& operator=(const Counted&) = delete;
  Counted& operator=(Counted&&) noexcept = default;
  ~Counted() = default;

  static void begin_copy() {
    ++copies_begun;
    hold_copies.wait(true);
  }

  [[nodiscard]] bool intact() const {
    for (int x : payload)
      if (x != value) return false;
    return true;
  }
};

class SourceFanOut : public ::testing::Test {
 protected:
  void SetUp() override {
    Counted::copies = 0;
    Counted::copies_begun = 0;
    Counted::hold_copies = false;
    Counted::copied_on.clear();
  }
  static LocalSource<Counted> source(Qos qos = {}) { return {"counted", qos, {}, Graph{}}; }
};

TEST_F(SourceFanOut, AValueForOneReaderIsNeverCopied) {
  auto counted = source();
  auto reader = counted.subscribe();
  for (int i = 0; i < 10; ++i) counted.publish({i, 64});
  for (int i = 0; i < 10; ++i) EXPECT_EQ(reader.try_read()->value.value, i);
  EXPECT_EQ(Counted::copies, 0);
}

TEST_F(SourceFanOut, AMoveOnlyValueReachesItsOneReader) {
  LocalSource<std::unique_ptr<int>> owned{"owned", {}, {}, Graph{}};
  auto reader = owned.subscribe();
  owned.publish(std::make_unique<int>(5));
  EXPECT_EQ(*reader.try_read()->value, 5);
  EXPECT_THROW((void)owned.subscribe(), Failure) << "a second reader would need a copy";
}

TEST_F(SourceFanOut, EveryReaderButTheLastToTakeTheValueCopiesIt) {
  auto counted = source();
  auto first = counted.subscribe();
  auto second = counted.subscribe();
  auto third = counted.subscribe();
  counted.publish({7, 64});
  EXPECT_EQ(Counted::copies, 0) << "the publisher copied";

  ASSERT_TRUE(first.try_read()->value.intact());
  EXPECT_EQ(Counted::copies, 1);
  ASSERT_TRUE(second.try_read()->value.intact());
  EXPECT_EQ(Counted::copies, 2);
  auto last = third.try_read();
  EXPECT_EQ(Counted::copies, 2) << "the last reader holding the value should get it moved";
  EXPECT_EQ(last->value.value, 7);
  EXPECT_TRUE(last->value.intact());
}

TEST_F(SourceFanOut, AValueALossyReaderDroppedIsMovedToTheOtherReader) {
  auto counted = source();
  auto lossy = counted.subscribe({.capacity = 1, .overflow = Overflow::drop_oldest});
  auto other = counted.subscribe();
  counted.publish({1, 64});
  counted.publish({2, 64});  // pushes value 1 out of the lossy reader's buffer
  EXPECT_EQ(lossy.lost(), 1u);

  EXPECT_EQ(other.try_read()->value.value, 1);
  EXPECT_EQ(Counted::copies, 0) << "value 1 had one claim left";
}

TEST_F(SourceFanOut, AValueAReaderLeftUnreadIsMovedToTheOtherReader) {
  auto counted = source();
  auto other = counted.subscribe();
  {
    auto gone = counted.subscribe();
    counted.publish({3, 64});
  }
  EXPECT_EQ(other.try_read()->value.value, 3);
  EXPECT_EQ(Counted::copies, 0);
}

TEST_F(SourceFanOut, TheLastReaderWaitsForACopyUnderWayAndGetsTheValueMoved) {
  auto counted = source();
  auto first = counted.subscribe();
  auto last = counted.subscribe();
  Counted::hold_copies = true;
  counted.publish({5, 64});

  std::optional<Sample<Counted>> copied;
  std::jthread copying{[&] { copied = first.try_read(); }};
  while (Counted::copies_begun == 0) std::this_thread::yield();  // the first reader's copy is under way
  std::jthread release{[&, reading = ::gettid()] {
    (void)asleep_within(reading);  // once the read below waits (a reader that copied too waits as well)
    Counted::hold_copies = false;
    Counted::hold_copies.notify_all();
  }};
  auto moved = last.try_read();
  copying.join();

  EXPECT_EQ(Counted::copies, 1) << "the last reader copied the value instead of waiting for the copy under way";
  ASSERT_TRUE(moved && copied);
  EXPECT_TRUE(moved->value.intact());
  EXPECT_TRUE(copied->value.intact());
  EXPECT_EQ(moved->value.value, 5);
}

// Readers on their own threads take one value at overlapping moments: the
// last to come waits for the copies under way and gets the value moved, so
// n readers make n - 1 copies however their reads overlap.
TEST_F(SourceFanOut, ReadersOnTheirOwnThreadsGetEveryValueIntactAndMakeOneCopyFewerThanThereAreReaders) {
  constexpr int kReaders = 3;
  constexpr int kValues = 2000;
  auto counted = source({.capacity = 16, .overflow = Overflow::block});
  std::vector<Reader<Counted>> readers;
  for (int r = 0; r < kReaders; ++r) readers.push_back(counted.subscribe());

  std::atomic<int> intact = 0;
  std::mutex mutex;
  std::set<std::thread::id> reader_threads;
  {
    std::vector<std::jthread> threads;
    for (auto& reader : readers)
      threads.emplace_back([&] {
        {
          std::scoped_lock lock{mutex};
          reader_threads.insert(std::this_thread::get_id());
        }
        for (int i = 0; i < kValues; ++i) {
          auto s = reader.read_for(30s);
          if (s && s->value.value == i && s->value.intact()) ++intact;
        }
      });
    for (int i = 0; i < kValues; ++i) counted.publish({i, 4096});
  }
  EXPECT_EQ(intact, kReaders * kValues);
  EXPECT_EQ(Counted::copies, (kReaders - 1) * kValues) << "each reader but the last needs a copy of its own";
  for (const auto& id : Counted::copied_on) EXPECT_TRUE(reader_threads.contains(id)) << "a copy made off the readers' threads";
}

// A value whose copy throws when told to.
struct Fragile {
  static inline std::atomic<bool> copies_fail = false;
  int v = 0;
  explicit Fragile(int value) : v{value} {}
  Fragile(const Fragile& other) : v{other.v} {
    if (copies_fail) throw std::runtime_error{"no memory for a copy"};
  }
  Fragile(Fragile&&) noexcept = default;
  Fragile& operator=(const Fragile&) = default;
  Fragile& operator=(Fragile&&) noexcept = default;
};

// Two chains after one source: one reader's copy throws. That value is lost
// to that reader, which says so; nothing else is, and the worker goes on.
TEST(SourceFanOutFaults, AReadersCopyThatThrowsLosesThatValueToItAlone) {
  liberty::Core core;
  Event<Fragile> event;
  auto errors = core.errors().subscribe();
  auto input = core.source(event, "input");
  auto first = (input | core.chain([](Fragile f) { return f.v; }, "first")).subscribe();
  auto second = (input | core.chain([](Fragile f) { return f.v; }, "second")).subscribe();
  Fragile::copies_fail = true;
  event.emit(Fragile{1});
  auto report = errors.read_for(5s);
  ASSERT_TRUE(report);
  EXPECT_NE(report->value.message.find("no memory for a copy"), std::string::npos) << report->value.describe();
  Fragile::copies_fail = false;
  event.emit(Fragile{2});
  std::vector<int> got;
  for (auto* reader : {&first, &second})
    while (true) {
      auto value = reader->read_for(5s);
      ASSERT_TRUE(value) << value.error().describe();
      got.push_back(value->value);
      if (value->value == 2) break;
    }
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, (std::vector<int>{1, 2, 2})) << "1 reached the reader that got it moved, 2 both";
}

}  // namespace
}  // namespace prime::test
