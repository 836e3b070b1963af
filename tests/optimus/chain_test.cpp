// Services and the chains that call them, in one process (other tests put
// them in processes of their own).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <expected>
#include <mutex>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "optimus/support/optimus_fixture.hpp"
#include "prime/liberty.hpp"
#include "prime/optimus/detail/envelope.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using OptimusChain = OptimusTest;

TEST_F(OptimusChain, AChainCallsItsBlockAsAServiceThroughTheServer) {
  optimus::Core core{options()};
  std::atomic<std::thread::id> ran_on;
  auto twice = core.chain([&](int x) {
    ran_on = std::this_thread::get_id();
    return 2 * x;
  });
  EXPECT_EQ(twice(21), 42);
  EXPECT_NE(ran_on.load(), std::this_thread::get_id()) << "the block ran in the service's worker";
  auto answer = twice.call(5, Clock::now() + 1s);
  ASSERT_TRUE(answer) << answer.error().describe();
  EXPECT_EQ(*answer, 10);
}

TEST_F(OptimusChain, AServiceHostedByOneCoreIsCalledByNameFromAnother) {
  optimus::Core host{options()};
  optimus::Core caller{options()};
  (void)host.serve("planner", [](std::string goal) { return "path to " + goal; });
  auto planner = caller.service<std::string, std::string>("planner", {.timeout = 2000ms});
  EXPECT_EQ(planner("dock"), "path to dock");
  EXPECT_EQ(planner.graph().text(), "planner [service, optimus]\n");
}

TEST_F(OptimusChain, LinkedServicesPassTheDataOnWithoutTheCaller) {
  RedisServer own;  // counted commands must be this test's alone
  optimus::Core core{optimus::Options{.url = own.url(), .domain = domain}};
  auto add_one = core.serve("add_one", [](int x) { return x + 1; });
  auto times_ten = core.serve("times_ten", [](int x) { return x * 10; });
  auto linked = add_one | times_ten;
  static_assert(std::same_as<decltype(linked), optimus::Chain<int, int>>, "linking keeps the medium's own chain");
  RawRedis raw{own.url()};
  const auto pushes = [&] {
    auto stats = raw.text({"INFO", "commandstats"});
    const auto at = stats.find("cmdstat_rpush:calls=");
    return at == std::string::npos ? 0 : std::stoi(stats.substr(at + 20));
  };
  constexpr int kCalls = 20;
  int before = pushes();
  for (int i = 0; i < kCalls; ++i) ASSERT_EQ(linked(i), (i + 1) * 10);
  const int linked_pushes = pushes() - before;
  before = pushes();
  for (int i = 0; i < kCalls; ++i) ASSERT_EQ(times_ten(add_one(i)), (i + 1) * 10);
  const int routed_pushes = pushes() - before;
  // Linked: request -> add_one -> times_ten -> reply. Caller-routed: a
  // request and a reply per service.
  EXPECT_EQ(linked_pushes, 3 * kCalls);
  EXPECT_EQ(routed_pushes, 4 * kCalls);
  EXPECT_EQ(linked.graph().text(), "add_one [service, optimus] -> times_ten [service, optimus]\n");
}

TEST_F(OptimusChain, ManyConcurrentCallersNeverGetEachOthersAnswers) {
  optimus::Core host{options()};
  optimus::Core callers{options()};
  (void)host.serve("tag", [](std::int64_t x) { return x * 1000 + 7; }, {.workers = 3});
  auto tag = callers.service<std::int64_t, std::int64_t>("tag");
  constexpr int kThreads = 8, kCalls = 150;
  std::atomic<int> wrong{0}, failed{0};
  {
    std::vector<std::jthread> threads;
    for (int t = 0; t < kThreads; ++t)
      threads.emplace_back([&, t] {
        for (int i = 0; i < kCalls; ++i) {
          const std::int64_t in = t * 100'000 + i;
          auto out = tag.call(in);
          if (!out)
            ++failed;
          else if (*out != in * 1000 + 7)
            ++wrong;
        }
      });
  }
  EXPECT_EQ(wrong, 0);
  EXPECT_EQ(failed, 0);
}

TEST_F(OptimusChain, ABlockThatThrowsIsAnErrorForTheCallerAndTheServiceKeepsServing) {
  optimus::Core core{options()};
  auto checked = core.chain(
      [](int x) {
        if (x < 0) throw std::invalid_argument{"negative range"};
        return x;
      },
      "check");
  EXPECT_TRUE(fails_with([&] { (void)checked(-1); }, Errc::block_failed, "service 'check': negative range"));
  auto answer = checked.call(-2);
  ASSERT_FALSE(answer);
  EXPECT_EQ(answer.error().code, Errc::block_failed);
  EXPECT_EQ(checked(3), 3) << "the service kept serving";
  // A prime::Failure thrown by a block keeps its code.
  auto empty = core.chain([](int) -> int { throw Failure{{Errc::no_data, "nothing yet"}}; });
  EXPECT_TRUE(fails_with([&] { (void)empty(1); }, Errc::no_data, "nothing yet"));
}

TEST_F(OptimusChain, AFailureInTheMiddleOfALinkedRouteReachesTheCaller) {
  optimus::Core core{options()};
  auto route = core.chain([](int x) { return x + 1; }, "first") |
               core.chain([](int x) -> int { if (x == 2) throw std::runtime_error{"two"}; return x; }, "second") |
               core.chain([](int x) { return x * 2; }, "third");
  EXPECT_EQ(route(5), 12);
  EXPECT_TRUE(fails_with([&] { (void)route(1); }, Errc::block_failed, "service 'second': two"));
  EXPECT_EQ(route(6), 14);
}

TEST_F(OptimusChain, EveryCallHasADeadline) {
  // The block holds input 1 until the test lets it go, which it does only
  // after the call came back: a call that waited past its deadline could only
  // come back with the answer (once the hold gives up, far later).
  struct Hold {
    std::mutex m;
    std::condition_variable cv;
    bool let_go = false;
    bool taken = false;
    bool gave_up = false;
    void release() {
      {
        std::scoped_lock lock{m};
        let_go = true;
      }
      cv.notify_all();
    }
  } hold;  // declared before the core: outlives the worker that runs the block
  optimus::Core core{options()};
  struct ReleaseOnExit {
    Hold& hold;
    ~ReleaseOnExit() { hold.release(); }  // a failed assertion does not leave the worker held
  } release_on_exit{hold};
  auto held = core.chain([&](int x) {
    if (x != 1) return x;
    std::unique_lock lock{hold.m};
    hold.taken = true;
    hold.cv.notify_all();
    hold.gave_up = !hold.cv.wait_for(lock, 20s, [&] { return hold.let_go; });
    return x;
  });
  ASSERT_EQ(held(0), 0) << "the service is up";

  std::expected<int, Error> late;
  bool withdrawn = true;  // never taken by the worker: then there is no late answer to check
  for (int attempt = 0; attempt < 10 && withdrawn; ++attempt) {
    late = held.call(1, Clock::now() + 50ms);
    ASSERT_FALSE(late) << "the block is held: the call cannot have had its answer";
    ASSERT_EQ(late.error().code, Errc::timeout) << late.error().describe();
    withdrawn = late.error().message.find("withdrawn") != std::string::npos;
  }
  ASSERT_FALSE(withdrawn) << "the worker never took a request: " << late.error().describe();
  {
    std::unique_lock lock{hold.m};
    ASSERT_TRUE(hold.cv.wait_for(lock, 20s, [&] { return hold.taken; })) << "the worker took the request but never ran the block";
  }
  hold.release();
  // One worker: it answers the first call (late) before it takes this one.
  EXPECT_EQ(held.with_timeout(5000ms)(2), 2) << "the late answer to the first call went to that call's key, not here";
  std::scoped_lock lock{hold.m};
  EXPECT_FALSE(hold.gave_up) << "the block ran until the test let it go";
}

TEST_F(OptimusChain, CallingAServiceNobodyServesIsPeerDeadNamingIt) {
  optimus::Core core{options()};
  auto nobody = core.service<int, int>("nobody", {.timeout = 50ms});
  auto answer = nobody.call(1);
  ASSERT_FALSE(answer);
  EXPECT_EQ(answer.error().code, Errc::peer_dead) << answer.error().describe();
  EXPECT_NE(answer.error().message.find("'nobody'"), std::string::npos);
  RawRedis raw{shared_redis().url()};
  EXPECT_EQ(raw.integer({"LLEN", domain + ":svc:nobody"}), 0) << "the unanswered request was withdrawn";
}

// Destroying a core whose worker is busy ends the worker's wait for
// requests without cutting it: a request the server handed out just before
// is still answered, and the rest stay queued for another worker. Not one
// is taken and lost (a cut wait lost the one on its way to the worker).
// Each round stops the worker at a moment the test does not choose; most
// moments fall while a wait is under way, the worker being busy.
TEST_F(OptimusChain, StoppingABusyWorkerLosesNoRequestItWasHandedOut) {
  RawRedis raw{shared_redis().url()};
  const auto key = domain + ":svc:echo";
  constexpr int kRequests = 300;
  for (int round = 0; round < 10; ++round) {
    const auto reply = [&](int i) {
      return optimus::detail::reply_key(domain, "1." + std::to_string(round), static_cast<std::uint64_t>(i));
    };
    for (int i = 0; i < kRequests; ++i) {
      std::string envelope;
      optimus::detail::encode_request(static_cast<std::uint64_t>(i), reply(i), {}, 0, optimus::encode_message(i), envelope);
      raw.command({"RPUSH", key, envelope});
    }
    {
      optimus::Core core{options()};
      (void)core.serve("echo", [](int x) { return x; });
      ASSERT_TRUE(eventually([&] { return raw.integer({"LLEN", key}) < kRequests; }));  // at work
    }
    const auto queued = raw.integer({"LLEN", key});
    long long answered = 0;
    for (int i = 0; i < kRequests; ++i) answered += raw.integer({"LLEN", reply(i)});
    EXPECT_EQ(answered + queued, kRequests) << "round " << round << ": " << answered << " answered, " << queued
                                            << " still queued; the rest were taken and lost";
    raw.command({"DEL", key});
  }
}

// A linked call goes on from service to service without its caller: one
// whose next service has no live worker says so to the caller at once,
// rather than leaving the request where no one takes it until the call times out.
TEST_F(OptimusChain, ALinkedCallWhoseNextServiceHasNoLiveWorkerIsPeerDeadAtOnce) {
  optimus::Core core{options()};
  auto linked = core.serve("add_one", [](int x) { return x + 1; }) | core.service<int, int>("nobody");
  const auto start = Clock::now();
  auto answer = linked.call(1, Clock::now() + 30s);
  ASSERT_FALSE(answer);
  EXPECT_EQ(answer.error().code, Errc::peer_dead) << answer.error().describe();
  EXPECT_NE(answer.error().message.find("service 'nobody': no live worker serves it (next after 'add_one'"), std::string::npos)
      << answer.error().message;
  EXPECT_LT(Clock::now() - start, 10s) << "told at once, not at the 30 s timeout";
  RawRedis raw{shared_redis().url()};
  EXPECT_EQ(raw.integer({"LLEN", domain + ":svc:nobody"}), 0) << "nothing left for a worker that never comes";
}

// A service lives as long as the process hosting it, however long its
// blocks run: one busy for longer than its alive key lasts (3 s) is slow,
// not dead, and a linked call still hands on to it and is answered.
TEST_F(OptimusChain, AServiceBusyForLongerThanItsAliveKeyLastsIsSlowNotDead) {
  optimus::Core core{options()};
  std::atomic<bool> entered{false};
  auto slow = core.serve("slow", [&](int x) {
    if (x < 0) {  // a long computation
      entered = true;
      std::this_thread::sleep_for(optimus::detail::kAliveFor + 1s);
    }
    return x;
  });
  std::jthread busy{[&] { EXPECT_EQ(slow.call(-1, Clock::now() + 30s).value_or(0), -1); }};
  ASSERT_TRUE(eventually([&] { return entered.load(); }));
  std::this_thread::sleep_for(optimus::detail::kAliveFor + 500ms);  // the time it takes a key to run out, not a wait for an event
  RawRedis raw{shared_redis().url()};
  EXPECT_EQ(raw.integer({"EXISTS", domain + ":svc:slow:alive"}), 1) << "still alive while its one worker is busy";
  auto linked = core.serve("first", [](int x) { return x; }) | slow;
  auto answer = linked.call(7, Clock::now() + 30s);
  ASSERT_TRUE(answer) << answer.error().describe();
  EXPECT_EQ(*answer, 7);
}

TEST_F(OptimusChain, AServiceNameTakenWithOtherTypesIsATypeMismatch) {
  optimus::Core core{options()};
  (void)core.serve("planner", [](int x) { return x; });
  EXPECT_TRUE(fails_with([&] { (void)core.service<std::string, int>("planner"); }, Errc::type_mismatch, "service 'planner'"));
  EXPECT_TRUE(fails_with([&] { (void)core.serve("planner", [](double x) { return x; }); }, Errc::type_mismatch, "service 'planner'"));
  EXPECT_NO_THROW(((void)core.service<int, int>("planner")));
}

TEST_F(OptimusChain, GarbageInARequestKeyIsReportedAndTheServiceKeepsServing) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto echo = core.serve("echo", [](int x) { return x; });
  RawRedis raw{shared_redis().url()};
  raw.command({"RPUSH", domain + ":svc:echo", "definitely not a request"});
  auto report = errors.read_for(5s);
  ASSERT_TRUE(report);
  EXPECT_EQ(report->value.code, Errc::type_mismatch);
  EXPECT_NE(report->value.message.find("service 'echo'"), std::string::npos) << report->value.message;
  EXPECT_EQ(echo(9), 9);
}

// A server that refuses a worker's wait (here its request key holds another
// type) is told by its own error, not as a lost server, and asked again
// after a backoff; once the key is sound the service serves again.
TEST_F(OptimusChain, AWorkerWhoseWaitTheServerRefusesSaysWhyAndServesOnceItMay) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto echo = core.serve("echo", [](int x) { return x; }, {.workers = 1});
  RawRedis raw{shared_redis().url()};
  raw.command({"SET", domain + ":svc:echo", "a string, not a list"});
  for (int i = 0; i < 3; ++i) {
    auto report = errors.read_for(5s);
    ASSERT_TRUE(report) << i;
    EXPECT_NE(report->value.message.find("WRONGTYPE"), std::string::npos) << report->value.describe();
    EXPECT_EQ(report->value.message.find("lost"), std::string::npos) << "not a lost server: " << report->value.describe();
  }
  raw.command({"DEL", domain + ":svc:echo"});
  EXPECT_EQ(echo(9), 9);
}

// A request the server refuses to queue is an error at once, naming the
// server's reason, not a wait for an answer that cannot come.
TEST_F(OptimusChain, ARequestTheServerRefusesIsAnErrorAtOnce) {
  optimus::Core core{options()};
  auto echo = core.service<int, int>("refused", {.timeout = 600'000ms});
  RawRedis raw{shared_redis().url()};
  raw.command({"SET", domain + ":svc:refused", "a string, not a list"});
  const auto start = Clock::now();
  auto refused = echo.call(1);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("WRONGTYPE"), std::string::npos) << refused.error().describe();
  EXPECT_LT(Clock::now() - start, 60s) << "not the call's 10-minute deadline";
  raw.command({"DEL", domain + ":svc:refused"});
}

TEST_F(OptimusChain, AMessageOfTheWrongTypeIsATypeMismatchFromTheService) {
  optimus::Core core{options()};
  (void)core.serve("ints", [](int x) { return x; });
  // A caller that bypasses the registry check: its chain claims doubles.
  optimus::Chain<double, int> forged{{optimus::detail::Segment{optimus::detail::Pool::make(options()),
                                                               {domain + ":svc:ints"}, {"ints"}}},
                                     Graph{}, 2000ms};
  EXPECT_TRUE(fails_with([&] { (void)forged(1.5); }, Errc::type_mismatch, "service 'ints'"));
}

// Issue 4, point 7: an Optimus service called from inside a Liberty chain.
TEST_F(OptimusChain, AnOptimusServiceRunsInsideALibertyChain) {
  optimus::Core redis{options()};
  liberty::Core local;
  (void)redis.serve("localize", [](int scan) { return scan * 10; });
  auto localize = redis.service<int, int>("localize", {.timeout = 2000ms});
  auto loop = local.chain([](int x) { return x + 1; }, "filter") | localize | local.chain([](int pose) { return pose - 3; }, "control");
  EXPECT_EQ(loop(4), 47);
  const auto text = loop.graph().text();
  EXPECT_NE(text.find("filter [chain, liberty] -> localize [service, optimus]"), std::string::npos) << text;
  // Or inside a Liberty block, for a step that decides at run time whether to ask.
  auto ask = local.chain([localize](int x) { return x > 0 ? localize(x) : 0; });
  EXPECT_EQ(ask(2), 20);
  EXPECT_EQ(ask(-2), 0);
}

TEST_F(OptimusChain, DestroyingTheCoreStopsItsServices) {
  auto core = std::make_unique<optimus::Core>(options());
  auto twice = core->chain([](int x) { return 2 * x; });
  EXPECT_EQ(twice(1), 2);
  const auto t0 = Clock::now();
  core.reset();
  EXPECT_LT(Clock::now() - t0, 2s) << "a stop ends the workers' waits at once";
  auto after = twice.with_timeout(100ms).call(1);
  ASSERT_FALSE(after);
  EXPECT_TRUE(after.error().code == Errc::peer_dead || after.error().code == Errc::timeout) << after.error().describe();
}

}  // namespace
}  // namespace prime::test
