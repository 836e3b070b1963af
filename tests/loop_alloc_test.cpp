// After setup, a periodic loop's tick allocates nothing, and neither does a
// Radiant or Liberty chain step over trivially copyable values: counted by
// replacing the global operator new for this test binary.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <new>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/radiant.hpp"

namespace {
// Allocations made by the calling thread, ever.
thread_local std::uint64_t allocations = 0;
}  // namespace

// These replace the global operator new and delete: the memory is malloc's
// on both sides, which GCC cannot see.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

void* operator new(std::size_t size) {
  ++allocations;
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc{};
}
void* operator new[](std::size_t size) { return ::operator new(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  ++allocations;
  return std::malloc(size == 0 ? 1 : size);
}
void* operator new[](std::size_t size, const std::nothrow_t& tag) noexcept { return ::operator new(size, tag); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace prime::test {
namespace {

using namespace std::chrono_literals;

struct Pose {
  double x, y, heading;
};
Pose integrate(const Pose& p) { return {p.x + 0.01, p.y, p.heading}; }
double distance(const Pose& p) { return p.x + p.y; }

// The loop thread's allocation count at each run of the chain, kept in room
// reserved before the loop starts.
class Counts {
 public:
  explicit Counts(std::size_t n) : wanted_{n} { seen_.reserve(n); }
  void at_run() {
    std::scoped_lock lock{mutex_};
    if (seen_.size() < wanted_) seen_.push_back(allocations);
    if (seen_.size() == wanted_) cv_.notify_all();
  }
  [[nodiscard]] bool wait() {
    std::unique_lock lock{mutex_};
    return cv_.wait_for(lock, 30s, [&] { return seen_.size() == wanted_; });
  }
  [[nodiscard]] std::vector<std::uint64_t> seen() {
    std::scoped_lock lock{mutex_};
    return seen_;
  }

 private:
  const std::size_t wanted_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<std::uint64_t> seen_;
};

// Runs `step` in a loop until `counts` has all its runs; the first runs are
// setup (the worker's thread, its first tick), the rest must allocate nothing.
template <class Core, class Step>
void expect_ticks_allocate_nothing(Core& core, Step step) {
  Counts counts{60};
  Pose pose{0, 0, 0};
  double total = 0;
  // A deadline no run misses on a loaded machine: an overrun's report (a
  // string) is allowed to allocate, a tick is not.
  auto loop = every(core, 2ms, [&](Token) {
    pose = step.first(pose);
    total += step.second(pose);
    counts.at_run();
  }, {.name = "no-alloc", .deadline = 10s});
  ASSERT_TRUE(counts.wait());
  loop.stop();
  const auto seen = counts.seen();
  EXPECT_EQ(seen.back(), seen[10]) << "runs 10 to 59 (and the ticks between them) allocated "
                                   << seen.back() - seen[10] << " times";
  EXPECT_GT(total, 0);
  EXPECT_EQ(loop.stats().overruns, 0u);
}

TEST(LoopAllocation, ARadiantChainInALoopAllocatesNothingPerTick) {
  radiant::Core core;
  expect_ticks_allocate_nothing(core, std::pair{core.chain(integrate), core.chain(distance)});
}

TEST(LoopAllocation, ALibertyChainInALoopAllocatesNothingPerTick) {
  liberty::Core core;
  expect_ticks_allocate_nothing(core, std::pair{core.chain(integrate), core.chain(distance)});
}

TEST(LoopAllocation, TheCounterSeesAnAllocation) {
  static int* volatile escaped = nullptr;  // so the allocation cannot be elided
  const auto before = allocations;
  escaped = new int{7};
  EXPECT_EQ(allocations, before + 1) << "the count this test relies on works";
  delete escaped;
}

}  // namespace
}  // namespace prime::test
