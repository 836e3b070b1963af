// Shm services across real processes: many callers at once, a service or a
// caller killed mid-call, a service restarted under the same name, and
// services of other processes linked and used in every combinator.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <latch>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/shm.hpp"
#include "prime/shm/detail/service_layout.hpp"
#include "shm/domain.hpp"
#include "shm/mapped_topic.hpp"
#include "shm/messages.hpp"
#include "shm/peer_process.hpp"
#include "support/counted_and_timed.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr std::uint64_t kCallsPerThread = 1000;  // sanitizers check correctness, not volume
#else
constexpr std::uint64_t kCallsPerThread = 10000;
#endif

std::optional<shm::RegistrySnapshot::Service> listed(shm::Core& core, const std::string& name) {
  for (const auto& s : core.registry().services)
    if (s.name == name) return s;
  return std::nullopt;
}

TEST(ShmServiceProcesses, FourProcessesOfFourThreadsEachGetTheirOwnAnswers) {
  const auto domain = unique_domain("many-callers");
  shm::Core core{domain};
  (void)core.serve("echo", [](const Ask& a) { return Answer{a.who, a.n * 3}; }, {.workers = 2});
  std::vector<PeerProcess> callers;
  for (int p = 0; p < 4; ++p) callers.emplace_back(std::vector<std::string>{"call_many", domain, "echo", "4", std::to_string(kCallsPerThread)});
  const auto all = 4 * kCallsPerThread;
  for (auto& caller : callers)
    EXPECT_TRUE(caller.says("ok " + std::to_string(all) + " wrong 0", 300s)) << "every answer was its caller's own";
  EXPECT_EQ(listed(core, "echo")->served, 4 * all);
}

// A program that reads its signals from a signalfd, having blocked them on
// its thread once its core's workers were running, gets them: the workers
// take none. Before the workers blocked every signal, SIGTERM went to a
// worker and killed the program by its default action.
TEST(ShmServiceProcesses, AProgramsSignalsGoToItsOwnThreadsNotToTheWorkers) {
  const auto domain = unique_domain("signalfd");
  PeerProcess daemon{{"signalfd", domain, "plus"}};
  ASSERT_TRUE(daemon.says("ready"));
  ASSERT_EQ(::kill(daemon.pid(), SIGTERM), 0);
  EXPECT_TRUE(daemon.says("took SIGTERM", 10s));
  EXPECT_EQ(daemon.exit_code(10s), 0) << "128 + 15 is a death by SIGTERM, taken by a worker";
}

TEST(ShmServiceProcesses, AServiceKilledMidCallIsReportedDeadToItsCallerWithin100Ms) {
  const auto domain = unique_domain("dead-service");
  shm::Core core{domain};
  PeerProcess server{{"serve", domain, "stuck", "hang"}};
  ASSERT_TRUE(server.says("serving"));
  auto stuck = core.chain<std::int64_t, std::int64_t>("stuck", {.timeout = 30s});
  std::optional<std::expected<std::int64_t, Error>> result;
  Clock::time_point returned;
  std::jthread caller{[&] {
    result = stuck.call(1);
    returned = Clock::now();
  }};
  ASSERT_TRUE(server.says("running")) << "the service runs the call";
  server.kill9();
  const auto killed = Clock::now();
  caller.join();
  ASSERT_TRUE(result);
  ASSERT_FALSE(*result);
  EXPECT_EQ(result->error().code, Errc::peer_dead) << result->error().describe();
  EXPECT_NE(result->error().message.find("service 'stuck': its server, participant 'peer-serve'"), std::string::npos)
      << result->error().message;
  EXPECT_LT(returned - killed, 100ms) << "told within 100 ms, not at the 30 s timeout";
}

// No one waits for a post's answer or releases its cell but the worker
// running it: a server killed while it runs a post leaves the cell to the
// next server, which frees it, so the client keeps all its calls in flight.
TEST(ShmServiceProcesses, APostRunningWhenItsServerIsKilledIsFreedByTheNextServer) {
  const auto domain = unique_domain("dead-post");
  shm::Core core{domain};
  auto stuck = core.chain<std::int64_t, std::int64_t>("stuck");
  {
    PeerProcess server{{"serve", domain, "stuck", "hang"}};
    ASSERT_TRUE(server.says("serving"));
    ASSERT_TRUE(stuck.post(1));
    ASSERT_TRUE(server.says("running")) << "the service runs the post";
    server.kill9();
  }
  PeerProcess next{{"serve", domain, "stuck", "hang"}};
  ASSERT_TRUE(next.says("serving"));
  for (int i = 0; i < 4; ++i) {  // calls_per_client, all at once: the next server answers none
    auto posted = stuck.post(10 + i);
    EXPECT_TRUE(posted) << i << ": " << posted.error().describe();
  }
}

// A linked call's worker holds the next service's cell while it runs (its
// output goes straight there). Killed with its server, it leaves that cell
// to no one: the caller, told the server died, frees it; for a post, which
// no caller waits for, the next server does.
TEST(ShmServiceProcesses, AServerKilledWhileItsOutputGoesOnLeavesTheNextServiceNoCellStuck) {
  const auto domain = unique_domain("dead-forward");
  shm::Core core{domain};
  (void)core.serve("plus", [](const std::int64_t& x) { return x + 1; }, {.calls_per_client = 1});
  auto plus = core.chain<std::int64_t, std::int64_t>("plus");
  auto linked = core.chain<std::int64_t, std::int64_t>("stuck", {.timeout = 30s}) | plus;
  {
    PeerProcess server{{"serve", domain, "stuck", "hang"}};
    ASSERT_TRUE(server.says("serving"));
    std::optional<std::expected<std::int64_t, Error>> result;
    std::jthread caller{[&] { result = linked.call(1); }};
    ASSERT_TRUE(server.says("running"));
    server.kill9();
    caller.join();
    ASSERT_TRUE(result && !*result);
    EXPECT_EQ(result->error().code, Errc::peer_dead) << result->error().describe();
  }
  auto direct = plus.call(1);  // plus allows one call in flight per client
  ASSERT_TRUE(direct) << direct.error().describe();
  EXPECT_EQ(*direct, 2);

  {
    PeerProcess server{{"serve", domain, "stuck", "hang"}};
    ASSERT_TRUE(server.says("serving"));
    ASSERT_TRUE(linked.post(1));
    ASSERT_TRUE(server.says("running"));
    server.kill9();
  }
  PeerProcess next{{"serve", domain, "stuck", "hang"}};
  ASSERT_TRUE(next.says("serving")) << "it took the service over, and what the dead one held";
  direct = plus.call(2);
  ASSERT_TRUE(direct) << direct.error().describe();
  EXPECT_EQ(*direct, 3);
}

TEST(ShmServiceProcesses, ARestartedServiceIsFoundAgainByTheSameHandle) {
  const auto domain = unique_domain("restart");
  shm::Core core{domain};
  auto twice = core.chain<std::int64_t, std::int64_t>("twice", {.timeout = 10s});
  {
    PeerProcess first{{"serve", domain, "twice", "twice"}};
    ASSERT_TRUE(first.says("serving"));
    EXPECT_EQ(twice(21), 42);
    first.kill9();
  }
  auto none = twice.call(1);
  ASSERT_FALSE(none);
  EXPECT_EQ(none.error().code, Errc::not_found);
  EXPECT_NE(none.error().message.find("service 'twice' has no live server"), std::string::npos) << none.error().message;
  PeerProcess second{{"serve", domain, "twice", "twice"}};
  ASSERT_TRUE(second.says("serving"));
  EXPECT_EQ(twice(50), 100) << "the same handle calls the new server";
}

// Runs twice (CountedAndTimed): what is left of the dead caller, and,
// timed, that the service serves as fast after it.
class ShmDeadCaller : public CountedAndTimed {};
INSTANTIATE_TEST_SUITE_P(Service, ShmDeadCaller, ::testing::Bool(), counted_or_timed);

TEST_P(ShmDeadCaller, ACallerKilledMidCallLeavesNothingStuck) {
  const auto domain = unique_domain("dead-caller");
  std::latch release{1};
  std::atomic<bool> entered{false};
  shm::Core core{domain};  // after what its block uses: stopped first
  (void)core.serve("gate", [&](const std::int64_t& x) {
    if (x == -1) {
      entered = true;
      release.wait();
    }
    return x;
  }, {.max_clients = 2});
  auto gate = core.chain<std::int64_t, std::int64_t>("gate");
  auto rate = [&] {  // the best of 10 batches: another test may share the CPUs meanwhile
    double best = 0;
    for (int b = 0; b < (timed() ? 10 : 1); ++b) {
      const auto start = Clock::now();
      for (std::int64_t i = 0; i < 1000; ++i) EXPECT_EQ(gate(i), i);
      best = std::max(best, 1000 / std::chrono::duration<double>(Clock::now() - start).count());
    }
    return best;
  };
  const auto before = rate();
  std::uint32_t dead_pid = 0;
  {
    PeerProcess caller{{"call_once", domain, "gate", "18446744073709551615"}};  // -1
    ASSERT_TRUE(caller.says("calling"));
    ASSERT_TRUE(MappedTopic::within(10s, [&] { return entered.load(); })) << "the worker runs its call";
    dead_pid = static_cast<std::uint32_t>(caller.pid());
    caller.kill9();
  }
  release.count_down();  // the answer goes to no one
  const auto after = rate();
  if (timed()) EXPECT_GE(after, 0.5 * before) << before << " calls/s before, " << after << " after";
  core.reclaim();  // (an idle worker may have done it already)
  const auto clients = listed(core, "gate")->client_pids;
  EXPECT_EQ(std::count(clients.begin(), clients.end(), dead_pid), 0) << "the dead caller's client slot was reclaimed";
  auto newcomer = core.chain<std::int64_t, std::int64_t>("gate");
  EXPECT_EQ(newcomer(7), 7) << "its slot serves a new client (max_clients 2)";
}

// As ShmKilledHolder.WhoseSlotsClearerWasKilledTooIsClearedAgain, for a
// client slot: a caller killed, then the process clearing its slot killed
// half way (the state written below). The slot is cleared again, and serves
// a new client of a service that has room for one.
TEST(ShmServiceProcesses, AClientSlotWhoseClearerWasKilledIsClearedAgain) {
  const auto domain = unique_domain("killed-clearer");
  shm::Core core{domain};
  (void)core.serve("echo", [](const std::int64_t& x) { return x; }, {.max_clients = 1});
  PeerProcess caller{{"call_once", domain, "echo", "5"}};
  ASSERT_TRUE(caller.says("answer 5"));  // and it keeps its client slot
  auto segment = shm::detail::Segment::open_existing(shm::detail::segment_name(domain, "service", "echo"));
  ASSERT_TRUE(segment);
  auto& h = *std::launder(reinterpret_cast<shm::detail::ServiceHeader*>(segment->data()));
  const auto dead = h.clients[0].owner.load();
  ASSERT_NE(dead, 0u);
  caller.kill9();

  h.clients[0].owner.store(shm::detail::kReclaimingBit | h.server.load());  // a live clearer: this process
  EXPECT_EQ(core.reclaim(), 0u) << "a slot a live participant clears is left to it";
  h.clients[0].owner.store(shm::detail::kReclaimingBit | dead);  // a clearer killed half way
  EXPECT_EQ(core.reclaim(), 1u);
  auto newcomer = core.chain<std::int64_t, std::int64_t>("echo");
  EXPECT_EQ(newcomer(7), 7) << "the slot serves a new client (max_clients 1)";
}

TEST(ShmServiceProcesses, ServicesOfOtherProcessesLinkAndWorkInEveryCombinator) {
  const auto domain = unique_domain("remote-chains");
  shm::Core core{domain};
  liberty::Core local;
  PeerProcess a{{"serve", domain, "twice", "twice"}};
  PeerProcess b{{"serve", domain, "plus", "plus"}};
  ASSERT_TRUE(a.says("serving"));
  ASSERT_TRUE(b.says("serving"));
  auto twice = core.chain<std::int64_t, std::int64_t>("twice");
  auto plus = core.chain<std::int64_t, std::int64_t>("plus");

  auto linked = twice | plus;
  EXPECT_EQ(linked(5), 11);
  EXPECT_EQ(listed(core, "twice")->outputs_forwarded_on, 1u) << "twice's process handed its output straight to plus";
  EXPECT_EQ(listed(core, "plus")->requests_forwarded_in, 1u);
  EXPECT_EQ(listed(core, "plus")->requests_from_callers, 0u);

  auto guarded = if_then_else(local, [](const std::int64_t& x) { return x > 0; }, twice, plus);
  EXPECT_EQ(guarded(4), 8);
  EXPECT_EQ(guarded(-4), -3);
  EXPECT_EQ(foreach(local, linked)({1, 2}), (std::vector<std::int64_t>{3, 5}));
  EXPECT_EQ(repeat(local, twice, [](const std::int64_t& x) { return x > 100; })(1), 128);

  Event<std::int64_t> ticks;
  auto outputs = core.source(ticks, "ticks") | linked;
  auto newest = collector(local, outputs);
  auto reader = outputs.subscribe();
  ticks.emit(20);
  auto got = reader.read_for(10s);
  ASSERT_TRUE(got) << got.error().describe();
  EXPECT_EQ(got->value, 41);
  EXPECT_EQ(newest(Token{}), 41);
}

}  // namespace
}  // namespace prime::test
