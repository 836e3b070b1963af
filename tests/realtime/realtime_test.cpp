// Real-time options of a periodic loop: CPU affinity and SCHED_FIFO as
// granted here, and what an unprivileged process is told when refused
// (unprivileged.cpp, a process of its own).
#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <string>
#include <vector>

#include "optimus/support/child_process.hpp"
#include "prime/liberty.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// What the loop's thread saw on each of its first runs.
struct Seen {
  std::mutex mutex;
  std::condition_variable cv;
  std::vector<int> cpus;
  int policy = -1;
  int priority = -1;
  void run() {
    sched_param param{};
    int policy_now = 0;
    ::pthread_getschedparam(::pthread_self(), &policy_now, &param);
    std::scoped_lock lock{mutex};
    cpus.push_back(::sched_getcpu());
    policy = policy_now;
    priority = param.sched_priority;
    cv.notify_all();
  }
  bool wait_for(std::size_t n) {
    std::unique_lock lock{mutex};
    return cv.wait_for(lock, 20s, [&] { return cpus.size() >= n; });
  }
};

// The last CPU this process may run on (a container's cpuset may leave out CPU 0).
int last_usable_cpu() {
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (::sched_getaffinity(0, sizeof allowed, &allowed) != 0) return 0;
  int last = 0;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu)
    if (CPU_ISSET(cpu, &allowed)) last = cpu;
  return last;
}

TEST(LoopRealtime, ALoopRunsOnlyOnTheCpuItIsPinnedTo) {
  liberty::Core core;
  Seen seen;
  const int cpu = last_usable_cpu();
  auto loop = every(core, 1ms, [&](Token) { seen.run(); }, {.name = "pinned", .deadline = 1s, .realtime = {.cpus = {cpu}}});
  ASSERT_TRUE(seen.wait_for(20));
  loop.stop();
  for (const int seen_on : seen.cpus) EXPECT_EQ(seen_on, cpu);
}

TEST(LoopRealtime, SchedFifoIsAppliedToTheLoopsThreadOrRefusedNamingTheLimit) {
  liberty::Core core;
  Seen seen;
  try {
    auto loop = every(core, 2ms, [&](Token) { seen.run(); },
                      {.name = "fifo", .realtime = {.policy = Realtime::fifo, .priority = 10}});
    ASSERT_TRUE(seen.wait_for(3));
    loop.stop();
    EXPECT_EQ(seen.policy, SCHED_FIFO);
    EXPECT_EQ(seen.priority, 10);
  } catch (const Failure& f) {  // a machine that may not: the error says why and what to change
    EXPECT_EQ(f.error().code, Errc::refused);
    EXPECT_NE(f.error().message.find("RLIMIT_RTPRIO"), std::string::npos) << f.what();
  }
}

TEST(LoopRealtime, WhatCannotBeAskedForIsRefusedBeforeAnythingRuns) {
  liberty::Core core;
  const auto nothing = [](Token) {};
  EXPECT_TRUE(fails_with([&] { (void)every(core, 1ms, nothing, {.name = "p", .realtime = {.policy = Realtime::fifo}}); },
                         Errc::invalid_argument, "loop 'p': priority 0 is outside 1..99"));
  EXPECT_TRUE(fails_with([&] { (void)every(core, 1ms, nothing, {.name = "q", .realtime = {.priority = 5}}); },
                         Errc::invalid_argument, "a priority needs the fifo or rr policy"));
  EXPECT_TRUE(fails_with([&] { (void)every(core, 1ms, nothing, {.name = "c", .realtime = {.cpus = {-1}}}); },
                         Errc::invalid_argument, "CPU -1 is not a CPU number"));
  EXPECT_TRUE(fails_with([&] { (void)every(core, 1ms, nothing, {.name = "far", .realtime = {.cpus = {1000}}}); },
                         Errc::refused, "CPU affinity {1000} was refused"));
}

TEST(LoopRealtime, AnUnprivilegedProcessIsToldWhichLimitRefusedItAndHowToRaiseIt) {
  ChildProcess child{{UNPRIVILEGED_PATH}};
  const auto fifo = child.read_line(20s);
  ASSERT_TRUE(fifo);
  EXPECT_TRUE(fifo->starts_with("fifo: refused: loop 'control': SCHED_FIFO priority 50 was refused")) << *fifo;
  EXPECT_NE(fifo->find("RLIMIT_RTPRIO, here 0 (ulimit -r)"), std::string::npos) << *fifo;
  EXPECT_NE(fifo->find("limits.conf"), std::string::npos) << *fifo;
  const auto best_effort = child.read_line(20s);
  ASSERT_TRUE(best_effort);
  EXPECT_NE(best_effort->find("ticks; warning: refused: loop 'control': SCHED_FIFO"), std::string::npos) << *best_effort;
  EXPECT_NE(best_effort->find("best effort: the loop runs without it"), std::string::npos) << *best_effort;
  const auto memlock = child.read_line(20s);
  ASSERT_TRUE(memlock);
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // The sanitizers' runtimes replace mlockall with a no-op that succeeds.
  EXPECT_EQ(*memlock, "memlock: granted") << "under a sanitizer, nothing is locked and nothing refused";
#else
  EXPECT_TRUE(memlock->starts_with("memlock: refused: locking the process's memory (mlockall) was refused")) << *memlock;
  EXPECT_NE(memlock->find("RLIMIT_MEMLOCK, here 0 bytes (ulimit -l)"), std::string::npos) << *memlock;
#endif
  EXPECT_FALSE(child.read_line(20s)) << "nothing more: it has ended";
  EXPECT_EQ(child.stop(), 0) << "exited normally";
}

}  // namespace
}  // namespace prime::test
