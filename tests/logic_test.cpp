// The logic layer on its own: blocks, events, connections.
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "prime/logic.hpp"

namespace prime::test {
namespace {

std::string name_of(const int& x) { return std::to_string(x); }
struct Scale {
  double factor;
  double operator()(double x) const noexcept { return x * factor; }
};

static_assert(std::same_as<block_input_t<decltype(&name_of)>, int>);
static_assert(std::same_as<block_input_t<Scale>, double>);
static_assert(std::same_as<block_output_t<Scale, double>, double>);
static_assert(Block<decltype(&name_of), int>);
static_assert(!Block<void (*)(int), int>, "a block returns a value");
static_assert(!DeducibleBlock<decltype([](auto x) { return x; })>, "a generic lambda names no input");

TEST(EventTest, EmitReachesEveryListenerWithTheStamp) {
  Event<int> event;
  std::vector<Sample<int>> a, b;
  auto ca = event.connect([&](Sample<int>&& s) { a.push_back(s); });
  auto cb = event.connect([&](Sample<int>&& s) { b.push_back(s); });
  const auto stamp = Clock::now() - std::chrono::seconds{1};
  event.emit(7, stamp);
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(a[0].value, 7);
  EXPECT_EQ(b[0].stamp, stamp);
}

TEST(EventTest, EmitWithoutAStampStampsNow) {
  Event<int> event;
  Clock::time_point seen;
  auto c = event.connect([&](Sample<int>&& s) { seen = s.stamp; });
  const auto before = Clock::now();
  event.emit(1);
  EXPECT_GE(seen, before);
  EXPECT_LE(seen, Clock::now());
}

TEST(EventTest, DestroyedConnectionStopsDelivery) {
  Event<int> event;
  int calls = 0;
  {
    auto c = event.connect([&](Sample<int>&&) { ++calls; });
    event.emit(1);
  }
  event.emit(2);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(event.listener_count(), 0u);
}

TEST(EventTest, ConnectionMayOutliveTheEvent) {
  Connection c;
  {
    Event<int> event;
    c = event.connect([](Sample<int>&&) {});
  }
  c.disconnect();  // nothing left to disconnect from: does nothing
  SUCCEED();
}

TEST(EventTest, MoveOnlyValuesReachTheirOneListener) {
  Event<std::unique_ptr<int>> event;
  int got = 0;
  auto c = event.connect([&](Sample<std::unique_ptr<int>>&& s) { got = *s.value; });
  event.emit(std::make_unique<int>(5));
  EXPECT_EQ(got, 5);
  EXPECT_THROW((void)event.connect([](auto&&) {}), std::logic_error);
}

TEST(EventTest, ConcurrentEmitConnectAndDisconnectAreSafe) {
  Event<int> event;
  std::atomic<int> delivered{0};
  std::vector<std::jthread> emitters;
  for (int t = 0; t < 3; ++t)
    emitters.emplace_back([&] {
      for (int i = 0; i < 2000; ++i) event.emit(i);
    });
  for (int i = 0; i < 200; ++i) {
    auto c = event.connect([&](Sample<int>&&) { ++delivered; });
  }
  emitters.clear();
  EXPECT_EQ(event.listener_count(), 0u);
}

TEST(ErrorTest, DescribeNamesTheCodeAndTheMessage) {
  Failure f{{Errc::timeout, "source 'lidar': no value before the deadline"}};
  EXPECT_STREQ(f.what(), "timeout: source 'lidar': no value before the deadline");
  EXPECT_EQ(f.error().code, Errc::timeout);
}


}  // namespace
}  // namespace prime::test
