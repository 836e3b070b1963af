// Asynchronous sources, readers, workers, collectors and sync: every behaviour
// written once, run on every medium.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <expected>
#include <mutex>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "conformance/media.hpp"
#include "support/failure.hpp"
#include "support/lifetime.hpp"
#include "support/sync_scenarios.hpp"
#include "support/threads.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;
constexpr auto kPatience = 5s;  // generous: only a broken implementation waits this long

int twice(int x) { return 2 * x; }

// Waits (with a deadline) until `done` holds; for effects a worker has on the world.
template <class F>
bool eventually(F done) {
  const auto deadline = Clock::now() + kPatience;
  while (!done()) {
    if (Clock::now() > deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

template <class M>
class SourceTest : public MediumTest<M> {
 protected:
  // Plays a sync scenario through two feeds of this medium.
  void play(SyncPolicy policy, const SyncScenario& scenario) {
    auto lidar = this->template feed<int>("lidar");
    auto odom = this->template feed<int>("odom");
    auto fused = sync(policy, lidar.source, odom.source);
    auto reader = fused.subscribe();
    const auto t0 = Clock::now();
    test::play(scenario, t0, [&](int input, int ms) { (input == 0 ? lidar : odom).emit(ms, at(t0, ms)); }, reader);
  }
  // A worker waits (asleep) for what never comes, as `why` says: destroying
  // the core ends that wait at once.
  void expect_destroying_the_core_ends_the_wait(const char* why) {
    ASSERT_TRUE(others_asleep_within()) << why;
    const auto t0 = Clock::now();
    this->core.reset();
    EXPECT_LT(Clock::now() - t0, 10s) << "stop ended the wait";
  }
  // `source` linked to a chain "check" that throws "negative range" for a value below 0.
  template <class S>
  auto checked(const S& source) {
    return source | this->core->chain(
                        [](int x) {
                          if (x < 0) throw std::invalid_argument{"negative range"};
                          return x;
                        },
                        "check");
  }
};
TYPED_TEST_SUITE(SourceTest, Media, MediumName);

TYPED_TEST(SourceTest, ReaderSeesValuesInOrderWithTheirStamps) {
  auto lidar = this->template feed<int>("lidar");
  auto reader = lidar.source.subscribe();
  const auto t0 = Clock::now();
  lidar.emit(1, t0);
  lidar.emit(2, t0 + 1ms);
  auto first = reader.try_read();
  ASSERT_TRUE(first);
  EXPECT_EQ(first->value, 1);
  EXPECT_EQ(first->stamp, t0);
  auto rest = reader.read_all();
  ASSERT_EQ(rest.size(), 1u);
  EXPECT_EQ(rest[0].value, 2);
  EXPECT_FALSE(reader.try_read());
}

TYPED_TEST(SourceTest, ReadSomeAskedForNothingTakesNothingAndWaitsForNothing) {
  auto lidar = this->template feed<int>("lidar");
  auto reader = lidar.source.subscribe();
  decltype(reader.read_all()) got;  // a Shm reader's are views
  auto none = reader.read_some(got, 0, Clock::now() + kPatience);
  ASSERT_TRUE(none) << none.error().describe();
  EXPECT_EQ(*none, 0u);
  lidar.emit(1);
  lidar.emit(2);
  none = reader.read_some(got, 0, Clock::now() + kPatience);
  ASSERT_TRUE(none) << none.error().describe();
  EXPECT_EQ(*none, 0u);
  EXPECT_TRUE(got.empty());
  EXPECT_EQ(reader.read_all().size(), 2u) << "both still unread";
}

TYPED_TEST(SourceTest, EachReaderHasItsOwnCursor) {
  auto lidar = this->template feed<int>("lidar");
  auto early = lidar.source.subscribe();
  lidar.emit(1);
  auto late = lidar.source.subscribe();
  lidar.emit(2);
  EXPECT_EQ(early.read_all().size(), 2u);
  auto late_values = late.read_all();
  ASSERT_EQ(late_values.size(), 1u) << "a reader sees what is published after it subscribed";
  EXPECT_EQ(late_values[0].value, 2);
}

TYPED_TEST(SourceTest, LatestSkipsToTheNewestAndKeepsIt) {
  auto odom = this->template feed<int>("odom");
  auto reader = odom.source.subscribe();
  EXPECT_FALSE(reader.latest());
  odom.emit(1);
  odom.emit(2);
  odom.emit(3);
  EXPECT_EQ(reader.latest()->value, 3);
  EXPECT_EQ(reader.latest()->value, 3) << "nothing newer: the same latest value";
  EXPECT_FALSE(reader.try_read());
}

TYPED_TEST(SourceTest, ABufferOfNoCapacityIsRefusedByName) {
  Event<int> event;
  EXPECT_TRUE(fails_with([&] { (void)this->core->source(event, "lidar", {.capacity = 0}); }, Errc::invalid_argument,
                         "source 'lidar': capacity must be at least 1"));
  auto source = this->core->source(event, "odom");
  EXPECT_TRUE(fails_with([&] { (void)source.subscribe({.capacity = 0}); }, Errc::invalid_argument, "source 'odom'"));
}

TYPED_TEST(SourceTest, BlockingReadTimesOutAtItsDeadline) {
  auto odom = this->template feed<int>("odom");
  auto reader = odom.source.subscribe();
  auto nothing = reader.read_for(20ms);
  ASSERT_FALSE(nothing);
  EXPECT_EQ(nothing.error().code, Errc::timeout);
  EXPECT_NE(nothing.error().message.find("odom"), std::string::npos) << "the error names the source";
}

TYPED_TEST(SourceTest, BlockingReadWakesWhenAValueArrives) {
  auto odom = this->template feed<int>("odom");
  auto reader = odom.source.subscribe();
  std::jthread producer{[&, reading = ::gettid()] {
    if (asleep_within(reading)) odom.emit(42);  // once the read below waits
  }};
  auto value = reader.read_for(kPatience);
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(value->value, 42);
}

TYPED_TEST(SourceTest, BlockingReadEndsOnStopRequest) {
  auto odom = this->template feed<int>("odom");
  auto reader = odom.source.subscribe();
  std::stop_source stop;
  std::jthread stopper{[&, reading = ::gettid()] {
    if (asleep_within(reading)) stop.request_stop();  // once the read below waits
  }};
  auto value = reader.read_for(kPatience, stop.get_token());
  ASSERT_FALSE(value);
  EXPECT_EQ(value.error().code, Errc::stopped);
}

TYPED_TEST(SourceTest, DropOldestKeepsTheNewestAndCountsTheLost) {
  auto scans = this->template feed<int>("scans", {.capacity = 4, .overflow = Overflow::drop_oldest});
  auto reader = scans.source.subscribe();
  for (int i = 0; i < 10; ++i) scans.emit(i);
  auto kept = reader.read_all();
  ASSERT_EQ(kept.size(), 4u) << "bounded: never more than the capacity";
  EXPECT_EQ(kept.front().value, 6);
  EXPECT_EQ(kept.back().value, 9);
  EXPECT_EQ(reader.lost(), 6u);
}

TYPED_TEST(SourceTest, BlockWaitsForTheReaderAndLosesNothing) {
  auto cmds = this->template feed<int>("cmds", {.capacity = 2, .overflow = Overflow::block});
  auto reader = cmds.source.subscribe();
  std::jthread producer{[&] {
    for (int i = 0; i < 100; ++i) cmds.emit(i);
  }};
  for (int i = 0; i < 100; ++i) {
    auto value = reader.read_for(kPatience);
    ASSERT_TRUE(value) << value.error().describe();
    EXPECT_EQ(value->value, i);
  }
  EXPECT_EQ(reader.lost(), 0u);
}

TYPED_TEST(SourceTest, BlockGivesUpOnAStuckReaderAtTheTimeoutAndReportsIt) {
  auto errors = this->core->errors().subscribe();
  auto cmds = this->template feed<int>(
      "cmds", {.capacity = 1, .overflow = Overflow::block, .block_timeout = std::chrono::milliseconds{20}});
  auto stuck = cmds.source.subscribe();
  cmds.emit(1);
  cmds.emit(2);  // no room: waits 20 ms, then gives up on this reader for one value
  auto report = errors.read_for(kPatience);
  ASSERT_TRUE(report);
  EXPECT_EQ(report->value.code, Errc::overflow);
  EXPECT_NE(report->value.message.find("cmds"), std::string::npos);
  // Which value the stuck reader loses is the medium's: an in-process buffer
  // refuses the new one, a shared ring overwrites the oldest.
  auto kept = stuck.read_all();
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_TRUE(kept[0].value == 1 || kept[0].value == 2);
  EXPECT_EQ(stuck.lost(), 1u);
}

TYPED_TEST(SourceTest, ALinkedChainRunsInAWorkerAndKeepsTheStamp) {
  auto& core = *this->core;
  auto lidar = this->template feed<int>("lidar");
  auto doubled = lidar.source | core.chain(twice);
  auto reader = doubled.subscribe();
  const auto stamp = Clock::now() - 1s;
  lidar.emit(21, stamp);
  auto value = reader.read_for(kPatience);
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(value->value, 42);
  EXPECT_EQ(value->stamp, stamp) << "the stamp is the sensor's, not the worker's";
}

TYPED_TEST(SourceTest, ChainsLinkedFirstShareOneWorkerEachLinkHasItsOwn) {
  auto& core = *this->core;
  auto lidar = this->template feed<int>("lidar");
  std::atomic<std::thread::id> a_thread, b_thread, c_thread;
  auto a = core.chain([&](int x) { return a_thread = std::this_thread::get_id(), x; });
  auto b = core.chain([&](int x) { return b_thread = std::this_thread::get_id(), x; });
  auto c = core.chain([&](int x) { return c_thread = std::this_thread::get_id(), x; });
  auto fused = lidar.source | (a | b);  // one link: one worker
  auto staged = fused | c;              // another link: another worker
  auto reader = staged.subscribe();
  lidar.emit(1);
  ASSERT_TRUE(reader.read_for(kPatience));
  if constexpr (runs_linked_blocks_in_one_worker<TypeParam>()) {
    EXPECT_EQ(a_thread.load(), b_thread.load());
  }
  EXPECT_NE(b_thread.load(), c_thread.load());
  EXPECT_NE(a_thread.load(), std::this_thread::get_id());
}

TYPED_TEST(SourceTest, AWorkerReportsABlocksExceptionAndKeepsRunning) {
  auto& core = *this->core;
  auto errors = core.errors().subscribe();
  auto lidar = this->template feed<int>("lidar");
  auto reader = this->checked(lidar.source).subscribe();
  lidar.emit(-1);
  lidar.emit(7);
  auto value = reader.read_for(kPatience);
  ASSERT_TRUE(value);
  EXPECT_EQ(value->value, 7) << "the worker went on after the exception";
  auto report = errors.read_for(kPatience);
  ASSERT_TRUE(report);
  EXPECT_EQ(report->value.code, Errc::block_failed);
  EXPECT_NE(report->value.message.find("negative range"), std::string::npos);
  EXPECT_NE(report->value.message.find("lidar | check"), std::string::npos) << report->value.message;
}

// An error source of the block policy whose reader never reads: each error
// waits for room, and the one that says an error found none goes to stderr,
// not into the same full source again (and again, without end). The worker
// goes on.
TYPED_TEST(SourceTest, AnErrorSourceThatNeverMakesRoomHoldsNoWorkerForever) {
  auto& core = *this->core;
  auto stalled = core.errors({.capacity = 1, .overflow = Overflow::block, .block_timeout = 20ms}).subscribe();
  auto lidar = this->template feed<int>("lidar");
  auto reader = this->checked(lidar.source).subscribe();
  lidar.emit(-1);  // fills the error source
  lidar.emit(-2);  // finds no room
  lidar.emit(7);
  auto value = reader.read_for(kPatience);
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(value->value, 7) << "the worker went on";
  auto first = stalled.try_read();
  ASSERT_TRUE(first);
  EXPECT_NE(first->value.message.find("negative range"), std::string::npos) << first->value.message;
}

// An errors source that no one reads takes nothing from stderr: an error
// that reaches no reader is printed there, as it is with no errors source.
TYPED_TEST(SourceTest, AnErrorNoReaderTakesGoesToStderr) {
  auto& core = *this->core;
  const auto unread = core.errors();
  auto lidar = this->template feed<int>("lidar");
  auto reader = this->checked(lidar.source).subscribe();
  testing::internal::CaptureStderr();
  lidar.emit(-1);
  lidar.emit(7);
  auto value = reader.read_for(kPatience);  // the worker reported -1's error before it handed on 7
  const auto printed = testing::internal::GetCapturedStderr();
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_NE(printed.find("negative range"), std::string::npos) << "stderr: " << printed;
  (void)unread;
}

TYPED_TEST(SourceTest, CollectorGivesTheLatestValueOnAToken) {
  auto& core = *this->core;
  auto odom = this->template feed<int>("odom");
  auto now = collector(core, odom.source | core.chain(twice));
  static_assert(std::same_as<typename decltype(now)::input_type, Token>);
  EXPECT_TRUE(fails_with([&] { (void)now(Token{}); }, Errc::no_data, "collector of 'odom | chain'"));
  odom.emit(1);
  odom.emit(2);
  ASSERT_TRUE(eventually([&] {
    try {
      return now(Token{}) == 4;
    } catch (const Failure&) {
      return false;
    }
  }));
  EXPECT_EQ(now(Token{}), 4) << "still the latest";
}

TYPED_TEST(SourceTest, CollectorOfAllUnreadGivesEachValueOnce) {
  auto& core = *this->core;
  auto odom = this->template feed<int>("odom");
  auto unread = collector(core, odom.source, all_unread);
  odom.emit(1);
  odom.emit(2);
  const auto values = unread(Token{});
  EXPECT_EQ(std::vector<int>(values.begin(), values.end()), (std::vector<int>{1, 2}));
  EXPECT_TRUE(unread(Token{}).empty());
}

TYPED_TEST(SourceTest, CollectorFeedsASynchronousChain) {
  auto& core = *this->core;
  auto odom = this->template feed<int>("odom");
  auto control = collector(core, odom.source) | core.chain(twice);
  odom.emit(5);
  EXPECT_EQ(control(Token{}), 10);
}

TYPED_TEST(SourceTest, SyncLatestOfEachPairsTheFirstSourceWithTheNewestOfTheOthers) {
  auto lidar = this->template feed<int>("lidar");
  auto odom = this->template feed<double>("odom");
  auto fused = sync(latest_of_each, lidar.source, odom.source);
  auto reader = fused.subscribe();
  odom.emit(0.5);
  odom.emit(1.5);
  // Each source has its own worker: lidar values pair with whatever odom the
  // sync has seen, and soon that is the newest, 1.5.
  int sent = 0;
  ASSERT_TRUE(eventually([&] {
    lidar.emit(++sent);
    auto pair = reader.read_for(10ms);
    if (!pair) return false;
    EXPECT_EQ(std::get<0>(pair->value), sent);
    return std::get<1>(pair->value) == 1.5;
  }));
  odom.emit(2.5);
  EXPECT_FALSE(reader.read_for(20ms)) << "only the first source's values make tuples";
}

TYPED_TEST(SourceTest, SyncWithinToleranceMatchesOnlyValuesThatClose) {
  this->play(within_tolerance(3ms), kWithinToleranceScenario);
}

TYPED_TEST(SourceTest, SyncExactTimeMatchesEqualStampsAndDropsTheUnmatched) {
  this->play(exact_time, kExactTimeScenario);
}

TYPED_TEST(SourceTest, SyncedTuplesFeedACollectorAndAChain) {
  auto& core = *this->core;
  auto lidar = this->template feed<int>("lidar");
  auto odom = this->template feed<int>("odom");
  auto fused = collector(core, sync(exact_time, lidar.source, odom.source)) |
               core.chain([](std::tuple<int, int> t) { return std::get<0>(t) + std::get<1>(t); });
  const auto t0 = Clock::now();
  lidar.emit(1, t0);
  odom.emit(2, t0);
  ASSERT_TRUE(eventually([&] {
    try {
      return fused(Token{}) == 3;
    } catch (const Failure&) {
      return false;
    }
  }));
}

TYPED_TEST(SourceTest, SyncApproximateTimeMakesTheBestSetsWhateverTheWorkersOrder) {
  this->play(approximate_time(), kApproximateTimeScenario);
}

TYPED_TEST(SourceTest, ASyncThatWouldKeepNoValueIsRefusedByName) {
  auto lidar = this->template feed<int>("lidar");
  auto odom = this->template feed<int>("odom");
  auto none = approximate_time({});
  none.depth = 0;
  try {
    (void)sync(none, lidar.source, odom.source);
    ADD_FAILURE() << "a depth of 0 was taken";
  } catch (const Failure& f) {
    EXPECT_EQ(f.error().code, Errc::invalid_argument);
    EXPECT_NE(f.error().message.find("a depth of 0"), std::string::npos) << f.error().message;
  }
}

TYPED_TEST(SourceTest, SyncLatestOfEachCanBeMadeByAnyInput) {
  auto lidar = this->template feed<int>("lidar");
  auto odom = this->template feed<int>("odom");
  auto fused = sync(latest_of_each_on(kAnyInput), lidar.source, odom.source);
  auto reader = fused.subscribe();
  const auto t0 = Clock::now();
  lidar.emit(1, t0);
  odom.emit(10, t0 + 1ms);  // the first set: both have spoken
  auto set = reader.read_for(kPatience);
  ASSERT_TRUE(set) << set.error().describe();
  EXPECT_EQ((static_cast<const std::tuple<int, int>&>(set->value)), (std::tuple<int, int>{1, 10}));
  odom.emit(20, t0 + 2ms);  // an odometry value makes a set too
  set = reader.read_for(kPatience);
  ASSERT_TRUE(set) << set.error().describe();
  EXPECT_EQ((static_cast<const std::tuple<int, int>&>(set->value)), (std::tuple<int, int>{1, 20}));
  EXPECT_EQ(set->stamp, t0 + 2ms) << "the set's stamp is the value that made it";
}

TYPED_TEST(SourceTest, InterpolateAtGivesTheOtherValueAtEachTriggersStampOrAnError) {
  const InterpolationScenario scenario;
  auto lidar = this->template feed<int>("lidar");
  auto odom = this->template feed<double>("odom");
  auto fused = interpolate_at(lidar.source, odom.source, {.max_gap = scenario.max_gap});
  auto reader = fused.subscribe();
  const auto t0 = Clock::now();
  test::play(scenario, t0, [&](int input, int ms) { input == 0 ? lidar.emit(ms, at(t0, ms)) : odom.emit(ms, at(t0, ms)); }, reader);
}

TYPED_TEST(SourceTest, ACollectorCanSayNotYetWithoutAnError) {
  auto& core = *this->core;
  auto odom = this->template feed<int>("odom");
  auto maybe = collector(core, odom.source | this->core->chain(twice), or_nothing);
  EXPECT_EQ(maybe(Token{}), std::nullopt) << "nothing yet is a value, not an error";
  auto waiting = collector(core, odom.source, first_within(kPatience));
  std::jthread later{[&, reading = ::gettid()] {
    if (asleep_within(reading)) odom.emit(7);  // once the call below waits for the first value
  }};
  EXPECT_EQ(waiting(Token{}), 7) << "a call before the first value waits for it";
  EXPECT_EQ(waiting(Token{}), 7) << "and it stays the newest";
  ASSERT_TRUE(eventually([&] { return maybe(Token{}) == 14; }));
  auto silent = this->template feed<int>("silent");
  EXPECT_TRUE(fails_with([&] { (void)collector(core, silent.source, first_within(20ms))(Token{}); }, Errc::no_data,
                         "collector of 'silent': nothing published within 20 ms"));
}

TYPED_TEST(SourceTest, RepeatReadsTheSourceEachIteration) {
  auto& core = *this->core;
  auto ticks = this->template feed<int>("ticks", {.capacity = 16, .overflow = Overflow::block});
  auto accumulate = repeat(core, core.chain([](std::pair<int, int> p) { return p.first + p.second; }),
                           [](const int& sum) { return sum >= 6; }, ticks.source);
  std::jthread driver{[&] {
    for (int i = 1; i <= 3; ++i) ticks.emit(i);
  }};
  EXPECT_EQ(accumulate(0), 6);  // 0+1, +2, +3
}

TYPED_TEST(SourceTest, RepeatWaitingOnASilentSourceTimesOut) {
  auto& core = *this->core;
  auto ticks = this->template feed<int>("ticks");
  auto accumulate = repeat(core, core.chain([](std::pair<int, int> p) { return p.first + p.second; }),
                           [](const int&) { return false; }, ticks.source,
                           RepeatLimits{.read_timeout = std::chrono::milliseconds{10}});
  EXPECT_TRUE(fails_with([&] { (void)accumulate(0); }, Errc::timeout, "repeat 'repeat': source 'ticks'"));
}

TYPED_TEST(SourceTest, AnEventWithOneReaderMovesItsValueWithoutCopies) {
  if constexpr (!passes_objects_in_place<TypeParam>()) {
    GTEST_SKIP() << "this medium serialises values: there are no copies of the object to count";
  } else if constexpr (!carries_any_type<TypeParam>()) {
    GTEST_SKIP() << "this medium's sources carry trivially copyable messages; a copy-counted object is not one";
  } else {
    auto& core = *this->core;
    auto step = [](Lifetime m) {
      ++m.value;
      return m;
    };
    Event<Lifetime> event;
    auto source = core.source(event, "counted");
    auto reader = (source | core.chain(step) | core.chain(step)).subscribe();
    Lifetime::reset();
    event.emit(Lifetime{1});
    auto value = reader.read_for(kPatience);
    ASSERT_TRUE(value);
    EXPECT_EQ(value->value.value, 3);
    EXPECT_EQ(Lifetime::copies, 0) << "one reader: the value is moved all the way";
  }
}

TYPED_TEST(SourceTest, EachFurtherReaderCostsExactlyOneCopy) {
  if constexpr (!passes_objects_in_place<TypeParam>()) {
    GTEST_SKIP() << "this medium serialises values: there are no copies of the object to count";
  } else if constexpr (!carries_any_type<TypeParam>()) {
    GTEST_SKIP() << "this medium's sources carry trivially copyable messages; a copy-counted object is not one";
  } else {
    Event<Lifetime> event;
    auto source = this->core->source(event, "counted");
    auto r1 = source.subscribe();
    auto r2 = source.subscribe();
    auto r3 = source.subscribe();
    Lifetime::reset();
    event.emit(Lifetime{1});
    EXPECT_EQ(Lifetime::copies, 0) << "the readers share the value until they read it";
    EXPECT_EQ(r1.try_read()->value.value, 1);
    EXPECT_EQ(r3.try_read()->value.value, 1);
    EXPECT_EQ(r2.try_read()->value.value, 1);
    EXPECT_EQ(Lifetime::copies, 2) << "the last reader to read it gets it moved";
  }
}

TYPED_TEST(SourceTest, SourcesBufferedValuesAreFreedWithTheirReaders) {
  if constexpr (!passes_objects_in_place<TypeParam>()) {
    GTEST_SKIP() << "this medium serialises values: there are no copies of the object to count";
  } else if constexpr (!carries_any_type<TypeParam>()) {
    GTEST_SKIP() << "this medium's sources carry trivially copyable messages; a copy-counted object is not one";
  } else {
    const int before = Lifetime::alive;
    {
      Event<Lifetime> event;
      auto source = this->core->source(event, "counted", {.capacity = 8});
      auto reader = source.subscribe();
      for (int i = 0; i < 20; ++i) event.emit(Lifetime{i});
      EXPECT_EQ(Lifetime::alive, before + 8);
    }
    EXPECT_EQ(Lifetime::alive, before);
  }
}

TYPED_TEST(SourceTest, ForwardHandsEveryValueWithItsStampToASink) {
  auto odom = this->template feed<int>("odom");
  std::mutex mutex;
  std::vector<std::pair<int, Clock::time_point>> got;
  forward(odom.source, [&](const auto& value, Clock::time_point stamp) {
    std::scoped_lock lock{mutex};
    got.emplace_back(static_cast<const int&>(value), stamp);
  });
  const auto t0 = Clock::now();
  odom.emit(1, t0);
  odom.emit(2, t0 + 1ms);
  ASSERT_TRUE(eventually([&] { std::scoped_lock lock{mutex}; return got.size() == 2; }));
  EXPECT_EQ(got[0], std::make_pair(1, t0));
  EXPECT_EQ(got[1], std::make_pair(2, t0 + 1ms));
}

TYPED_TEST(SourceTest, ForwardReportsWhatItsSinkRefusesAndGoesOn) {
  auto errors = this->core->errors().subscribe();
  auto odom = this->template feed<int>("odom");
  std::atomic<int> delivered = 0;
  forward(odom.source, [&](const auto& value, Clock::time_point) -> std::expected<void, Error> {
    if (static_cast<const int&>(value) < 0) return std::unexpected(Error{Errc::unreachable, "the far side is down"});
    ++delivered;
    return {};
  }, "to-redis");
  odom.emit(-1);
  odom.emit(5);
  auto report = errors.read_for(kPatience);
  ASSERT_TRUE(report);
  EXPECT_EQ(report->value.code, Errc::unreachable);
  EXPECT_NE(report->value.message.find("forward 'to-redis' of 'odom': the far side is down"), std::string::npos)
      << report->value.message;
  EXPECT_TRUE(eventually([&] { return delivered == 1; }));
}

TYPED_TEST(SourceTest, DescribesASourceTopology) {
  auto& core = *this->core;
  auto lidar = this->template feed<int>("lidar");
  auto odom = this->template feed<int>("odom");
  auto plan = collector(core, sync(exact_time, lidar.source | core.chain(twice, "filter"), odom.source)) |
              core.chain([](std::tuple<int, int>) { return 0; }, "plan");
  const auto text = plan.graph().text();
  for (const char* edge : {"lidar [source", "-> filter [chain", "filter [chain", "-> sync(lidar | filter, odom) [sync",
                           "odom [source", "-> collector [collector", "-> plan [chain"})
    EXPECT_NE(text.find(edge), std::string::npos) << edge << " missing from:\n" << text;
}

// Destroyed in any order: never a crash, never a hang.

TYPED_TEST(SourceTest, EventDestroyedBeforeItsSourceAndReaders) {
  auto& core = *this->core;
  auto event = std::make_unique<Event<int>>();
  auto source = core.source(*event, "lidar");
  auto linked = source | core.chain(twice);
  auto reader = linked.subscribe();
  event->emit(1);
  ASSERT_TRUE(reader.read_for(kPatience));
  event.reset();
  EXPECT_FALSE(reader.read_for(10ms));
}

TYPED_TEST(SourceTest, SourceHandlesDroppedWhileTheEventGoesOn) {
  auto& core = *this->core;
  Event<int> event;
  std::optional<Reader<int>> reader;
  {
    auto source = core.source(event, "lidar");
    reader.emplace((source | core.chain(twice)).subscribe());
  }
  event.emit(4);  // the linked worker keeps the source alive for its reader
  auto value = reader->read_for(kPatience);
  ASSERT_TRUE(value);
  EXPECT_EQ(value->value, 8);
  reader.reset();
  event.emit(5);  // nobody reads: nothing to do, nothing to crash
  EXPECT_EQ(event.listener_count(), 1u) << "the linked worker still listens until its core stops";
}

TYPED_TEST(SourceTest, DestroyingTheCoreStopsAndJoinsItsWorkers) {
  Event<int> event;
  std::atomic<int> started{0}, finished{0};
  auto source = this->core->source(event, "lidar");
  auto slow = source | this->core->chain([&](int x) {
    ++started;
    std::this_thread::sleep_for(50ms);
    ++finished;
    return x;
  });
  auto reader = slow.subscribe();
  event.emit(1);
  ASSERT_TRUE(eventually([&] { return started == 1; }));
  this->core.reset();  // waits for the running block, then joins
  EXPECT_EQ(finished, 1) << "the core's destructor joined the worker";
  event.emit(2);       // the worker is gone (joined above): no thread is left to run it
  EXPECT_EQ(started, 1);
  EXPECT_EQ(reader.read_all().size(), 1u);
  EXPECT_THROW((void)(source | liberty::Core{}.chain(twice)), Failure) << "linking to a dead core's source";
}

// A fork inside a worker's chain waits for room as the worker's own output
// does: stopping the core ends that wait too.
TYPED_TEST(SourceTest, DestroyingTheCoreReleasesAWorkerWaitingInAForkOfItsChain) {
  Event<int> event;
  auto source = this->core->source(event, "lidar");
  std::atomic<int> seen{0};
  auto [teed, outputs] = fork(*this->core, this->core->chain([&seen](int x) {
    seen = x;
    return twice(x);
  }), "doubled", {.capacity = 1, .overflow = Overflow::block, .block_timeout = std::chrono::milliseconds{60'000}});
  auto full = outputs.subscribe();
  auto relay = source | teed;
  auto sink = relay.subscribe();
  event.emit(1);
  event.emit(2);
  ASSERT_TRUE(eventually([&] { return seen == 2; })) << "the worker took the second value (the first's copy is in the fork)";
  this->expect_destroying_the_core_ends_the_wait("the worker waits for room in the fork that never comes");
  if (this->HasFatalFailure()) return;
  auto first = full.try_read();
  ASSERT_TRUE(first);
  EXPECT_EQ(first->value, 2);
}

// So does a repeat inside a worker's chain, waiting for its source.
TYPED_TEST(SourceTest, DestroyingTheCoreReleasesAWorkerWaitingInARepeatOfItsChain) {
  auto lidar = this->template feed<int>("lidar");
  auto ticks = this->template feed<int>("ticks");
  std::atomic<int> seen{0};
  auto accumulate = repeat(*this->core, this->core->chain([&seen](std::pair<int, int> p) {
    seen = p.second;
    return p.first + p.second;
  }), [](const int&) { return false; }, ticks.source, RepeatLimits{.read_timeout = std::chrono::milliseconds{60'000}});
  auto relay = lidar.source | accumulate;
  auto sink = relay.subscribe();
  lidar.emit(1);
  ticks.emit(5);
  ASSERT_TRUE(eventually([&] { return seen == 5; })) << "the worker runs the repeat, which read one tick";
  this->expect_destroying_the_core_ends_the_wait("the repeat waits for a tick that never comes");
}

TYPED_TEST(SourceTest, DestroyingTheCoreReleasesAWorkerBlockedOnAFullBuffer) {
  Event<int> event;
  auto source = this->core->source(event, "lidar");
  std::atomic<int> seen{0};
  auto relay = source | this->core->chain([&seen](int x) {
    seen = x;
    return twice(x);
  });
  auto full = relay.subscribe({.capacity = 1, .overflow = Overflow::block, .block_timeout = std::chrono::milliseconds{60'000}});
  event.emit(1);
  event.emit(2);
  ASSERT_TRUE(eventually([&] { return seen == 2; })) << "the worker took the second value (the first's result is in)";
  this->expect_destroying_the_core_ends_the_wait("the worker waits for room that never comes");
  if (this->HasFatalFailure()) return;
  auto first = full.try_read();
  ASSERT_TRUE(first);
  EXPECT_EQ(first->value, 2);
}

}  // namespace
}  // namespace prime::test
