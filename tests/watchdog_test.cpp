// A watchdog (deadline monitor) acts once when its deadline passes with no
// feed, is armed again by the next feed, never acts while fed, and stops.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <future>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/topology/watchdog.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// When the watchdog acted, each time.
class Actions {
 public:
  void record() {
    std::scoped_lock lock{mutex_};
    times_.push_back(Clock::now());
    cv_.notify_all();
  }
  // Waits (up to 10 s) for the n-th action; its time.
  std::optional<Clock::time_point> wait_for(std::size_t n) {
    std::unique_lock lock{mutex_};
    if (!cv_.wait_for(lock, 10s, [&] { return times_.size() >= n; })) return std::nullopt;
    return times_[n - 1];
  }
  std::size_t count() {
    std::scoped_lock lock{mutex_};
    return times_.size();
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<Clock::time_point> times_;
};

TEST(Watchdog, ActsOnceWhenItsDeadlinePassesWithNoFeedAndAgainOnlyAfterAFeed) {
  liberty::Core core;
  Actions actions;
  const auto created = Clock::now();
  auto w = watchdog(core, 50ms, [&] { actions.record(); }, {.name = "commands"});
  const auto first = actions.wait_for(1);
  ASSERT_TRUE(first);
  EXPECT_GE(*first - created, 50ms) << "not before its deadline";
  EXPECT_TRUE(w.expired());
  std::this_thread::sleep_for(200ms);  // four more deadlines with no feed
  EXPECT_EQ(actions.count(), 1u) << "once per silence, not once per deadline";
  EXPECT_EQ(w.expiries(), 1u);

  const auto fed = Clock::now();
  w.feed();
  const auto second = actions.wait_for(2);
  ASSERT_TRUE(second) << "a feed arms it again";
  EXPECT_GE(*second - fed, 50ms) << "a deadline after the feed";
  EXPECT_EQ(w.expiries(), 2u);
}

TEST(Watchdog, NeverActsWhileFedWithinItsDeadline) {
  liberty::Core core;
  Actions actions;
  auto w = watchdog(core, 1s, [&] { actions.record(); });
  for (int i = 0; i < 30; ++i) {  // 300 ms of feeds, each 10 ms apart: far within the deadline
    w.feed();
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_EQ(actions.count(), 0u);
  EXPECT_FALSE(w.expired());
  const auto last = Clock::now();
  w.feed();
  const auto acted = actions.wait_for(1);
  ASSERT_TRUE(acted);
  EXPECT_GE(*acted - last, 1s) << "the deadline counts from the last feed";
}

TEST(Watchdog, AStoppedWatchdogNeverActsAndOneStopsItselfFromItsAction) {
  liberty::Core core;
  Actions actions;
  auto stopped = watchdog(core, 20ms, [&] { actions.record(); });
  stopped.stop();
  stopped.stop();  // idempotent
  std::this_thread::sleep_for(100ms);  // five of its deadlines
  EXPECT_EQ(actions.count(), 0u);

  std::optional<Watchdog> self;
  std::promise<void> made;
  auto ready = made.get_future().share();
  self.emplace(watchdog(core, 20ms, [&, ready] {
    ready.wait();
    self->stop();  // from its own action: does not wait for itself
    actions.record();
  }));
  made.set_value();
  ASSERT_TRUE(actions.wait_for(1));
  self.reset();  // returns: the action has ended
}

TEST(Watchdog, WhatItsActionThrowsIsReportedAndItGoesOn) {
  liberty::Core core;
  auto errors = core.errors().subscribe();
  Actions actions;
  auto w = watchdog(core, 20ms, [&] {
    actions.record();
    if (actions.count() == 1) throw std::runtime_error{"motors unreachable"};
  }, {.name = "commands"});
  const auto error = errors.read_for(10s);
  ASSERT_TRUE(error);
  EXPECT_EQ(error->value.code, Errc::block_failed);
  EXPECT_NE(error->value.message.find("watchdog 'commands': motors unreachable"), std::string::npos) << error->value.message;
  ASSERT_TRUE(actions.wait_for(1));
  w.feed();
  EXPECT_TRUE(actions.wait_for(2)) << "it goes on after a throw";
}

TEST(Watchdog, ADeadlineThatIsNotPositiveIsRefused) {
  liberty::Core core;
  try {
    (void)watchdog(core, 0ms, [] {}, {.name = "commands"});
    FAIL() << "refused";
  } catch (const Failure& f) {
    EXPECT_EQ(f.error().code, Errc::invalid_argument);
    EXPECT_NE(f.error().message.find("watchdog 'commands'"), std::string::npos);
  }
}

}  // namespace
}  // namespace prime::test
