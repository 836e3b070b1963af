// Services and sources in processes of their own (optimus_service_helper),
// on a real redis-server.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "optimus/support/child_process.hpp"
#include "optimus/support/optimus_fixture.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

class OptimusProcess : public OptimusTest {
 protected:
  // `before`: what runs the helper (faketime and its offset), if anything.
  ChildProcess helper(const std::vector<std::string>& role, std::vector<std::string> before = {}) {
    auto argv = std::move(before);
    argv.insert(argv.end(), {PRIME_OPTIMUS_HELPER, shared_redis().url(), domain});
    argv.insert(argv.end(), role.begin(), role.end());
    ChildProcess child{argv};
    if (!child.wait_for_line("ready", 20s)) throw std::runtime_error{"the helper did not get ready"};
    return child;
  }
};

TEST_F(OptimusProcess, AServiceInAnotherProcessIsCalledByName) {
  auto services = helper({"serve"});
  optimus::Core core{options()};
  auto twice = core.service<int, int>("double", {.timeout = 5000ms});
  EXPECT_EQ(twice(21), 42);
  const int pid = core.service<int, int>("whoami")(0);
  EXPECT_EQ(pid, services.pid());
  EXPECT_NE(pid, ::getpid());
}

TEST_F(OptimusProcess, LinkedServicesOfAnotherProcessPassDataWithoutTheCaller) {
  auto services = helper({"serve"});
  optimus::Core core{options()};
  auto pipeline = core.service<int, int>("add_one") | core.service<int, int>("times_ten") |
                  core.chain([](int x) { return x - 1; }, "local");
  EXPECT_EQ(pipeline(4), 49);
}

TEST_F(OptimusProcess, ABlockThatThrowsInAnotherProcessIsAnErrorHere) {
  auto services = helper({"serve"});
  optimus::Core core{options()};
  auto failing = core.service<int, int>("fail");
  EXPECT_TRUE(fails_with([&] { (void)failing(3); }, Errc::block_failed, "failing on 3"));
  EXPECT_EQ((core.service<int, int>("double")(2)), 4) << "the process keeps serving";
}

// Robots off the network rarely keep their clocks in step. Services whose
// machine's clock runs 30 s ahead of their caller's (faketime, which
// preloads a library that shifts the helper's clocks) still answer calls of
// a second: a worker goes by the server's clock, not the caller's, to tell
// whether a call's deadline passed. (Before, it took every one for given up.)
TEST_F(OptimusProcess, ServicesOnAMachineWhoseClockRunsAheadOfTheCallersAnswerItsCalls) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "faketime preloads a library, which a sanitizer's runtime does not let come first";
#endif
  if (std::system("command -v faketime > /dev/null") != 0) GTEST_SKIP() << "faketime is not installed (tools/run installs it)";
  // faketime keeps its state in two files of /dev/shm named by its pid,
  // which it leaves behind when the helper is stopped: removed after it.
  struct FaketimeFiles {
    pid_t pid = 0;
    ~FaketimeFiles() {
      for (const auto* stem : {"/dev/shm/faketime_shm_", "/dev/shm/sem.faketime_sem_"})
        if (pid > 0) ::unlink((stem + std::to_string(pid)).c_str());
    }
  } leftovers;
  auto services = helper({"serve"}, {"faketime", "-f", "+30s"});
  leftovers.pid = services.pid();
  optimus::Core core{options()};
  auto twice = core.service<int, int>("double", {.timeout = 1000ms});
  EXPECT_EQ(twice(21), 42);
  auto linked = core.service<int, int>("add_one") | core.service<int, int>("times_ten");
  EXPECT_EQ(linked(4), 50);
}

// A block reader's process killed with its room full: writers wait for it
// (block_timeout, then the value is dropped for it and reported) only until
// its lease runs out, not on every publish for as long as the source lives.
TEST_F(OptimusProcess, AKilledBlockReaderIsWaitedForOnlyUntilItsLeaseRunsOut) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto publisher = core.publisher<int>("held", {.capacity = 8, .overflow = Overflow::block, .block_timeout = 50ms});
  auto reader = helper({"block_reader", "held"});
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(publisher.publish(i));  // room for 2
  auto full = errors.read_for(5s);
  ASSERT_TRUE(full) << "the third was dropped for the reader that made no room";
  EXPECT_EQ(full->value.code, Errc::overflow) << full->value.describe();
  reader.kill();  // kill -9: no goodbye
  RawRedis raw{shared_redis().url()};
  const auto leases = domain + ":readers:held:lease:*";
  const auto give_up = Clock::now() + 10s;
  while (raw.command({"KEYS", leases})->size() != 0) {  // the server's clock runs the lease out
    ASSERT_LT(Clock::now(), give_up) << "the dead reader's lease never ran out";
    std::this_thread::sleep_for(50ms);  // a poll of the server, not a wait for anything of ours
  }
  for (int i = 3; i < 10; ++i) ASSERT_TRUE(publisher.publish(i));
  auto more = errors.try_read();
  EXPECT_FALSE(more) << "no longer waited for: " << more->value.describe();
}

// A caller killed while its request waits for a worker that never comes
// (the service's process died too, or it was an anonymous one) leaves the
// request behind: it goes away by itself soon after the call's deadline,
// rather than staying in the service's list for good.
TEST_F(OptimusProcess, ARequestOfAKilledCallerExpiresSoonAfterItsDeadline) {
  RawRedis raw{shared_redis().url()};
  const auto requests = domain + ":svc:nobody";
  auto caller = helper({"call", "nobody", "60000"});
  ASSERT_TRUE(eventually([&] { return raw.integer({"LLEN", requests}) == 1; })) << "the request was sent";
  caller.kill();  // kill -9: it never withdraws its request
  const auto ttl = raw.integer({"PTTL", requests});
  EXPECT_GT(ttl, 0) << "the request has an expiry";
  EXPECT_LE(ttl, 60'000 + 10'000) << "the call's deadline and a margin";
  raw.command({"DEL", requests});
}

// `block` readers killed (kill -9: no goodbye) leave no field in their
// source's readers hash once their leases have run out and the stream has
// passed them: a writer that looks strikes them (one values were dropped
// for, and so has a count there, at once; one that had room once its room
// is used up), and so does a reader that subscribes.
TEST_F(OptimusProcess, KilledBlockReadersLeaveNothingInTheReadersHash) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto publisher = core.publisher<int>("held", {.capacity = 8, .overflow = Overflow::block, .block_timeout = 50ms});
  RawRedis raw{shared_redis().url()};
  const auto readers = domain + ":readers:held";
  const auto leases_gone = [&] {
    const auto give_up = Clock::now() + 10s;
    while (raw.command({"KEYS", readers + ":lease:*"})->size() != 0) {  // the server's clock runs them out
      if (Clock::now() > give_up) return false;
      std::this_thread::sleep_for(50ms);  // a poll of the server, not a wait for anything of ours
    }
    return true;
  };

  auto full = helper({"block_reader", "held"});
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(publisher.publish(i));  // room for 2: the third is dropped for it
  ASSERT_TRUE(errors.read_for(5s)) << "the third was dropped for the reader that made no room";
  auto idle = helper({"block_reader", "held"});  // room to spare
  ASSERT_EQ(raw.integer({"HLEN", readers}), 3) << "two progress fields and one count of what was dropped";
  full.kill();
  idle.kill();
  ASSERT_TRUE(leases_gone()) << "the dead readers' leases never ran out";
  ASSERT_TRUE(publisher.publish(3));
  EXPECT_EQ(raw.integer({"HLEN", readers}), 1) << "the writer struck the full one; the one with room is left";
  ASSERT_TRUE(publisher.publish(4));
  ASSERT_TRUE(publisher.publish(5));  // its room of 2 past what it read: it would be waited for
  EXPECT_EQ(raw.integer({"HLEN", readers}), 0) << "the writer struck both dead readers";
  EXPECT_FALSE(errors.try_read()) << "and waited for neither";

  auto another = helper({"block_reader", "held"});
  another.kill();
  ASSERT_TRUE(leases_gone());
  // Two more: its room is used up, which the writers (looking before each
  // append) have not yet seen; a reader subscribing looks past the last.
  for (int i = 6; i < 8; ++i) ASSERT_TRUE(publisher.publish(i));
  EXPECT_EQ(raw.integer({"HLEN", readers}), 1) << "left by the writers";
  auto reader = core.subscribe<int>("held", {.capacity = 2, .overflow = Overflow::block}).subscribe();
  EXPECT_EQ(raw.integer({"HLEN", readers}), 1) << "the new reader struck the dead one; its own field is left";
}

// A `block` reader that only paused (read nothing for longer than its
// lease, with room to spare) is not taken for gone: it reads on with
// nothing lost and no warning that it may have lost values (it was struck
// from the readers hash, and told so, as if it had died).
TEST_F(OptimusProcess, ABlockReaderThatPausedWithRoomReadsOnWithoutAWarning) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto publisher = core.publisher<int>("paused", {.capacity = 8, .overflow = Overflow::block, .block_timeout = 50ms});
  auto reader = core.subscribe<int>("paused", {.capacity = 4, .overflow = Overflow::block}).subscribe();
  ASSERT_TRUE(publisher.publish(1));
  ASSERT_TRUE(reader.read_for(5s));
  RawRedis raw{shared_redis().url()};
  const auto give_up = Clock::now() + 10s;
  while (raw.command({"KEYS", domain + ":readers:paused:lease:*"})->size() != 0) {  // the server's clock runs it out
    ASSERT_LT(Clock::now(), give_up) << "the lease never ran out";
    std::this_thread::sleep_for(50ms);  // a poll of the server, not a wait for anything of ours
  }
  ASSERT_TRUE(publisher.publish(2));
  ASSERT_TRUE(publisher.publish(3));
  for (int expected : {2, 3}) {
    const auto got = reader.read_for(5s);
    ASSERT_TRUE(got) << got.error().describe();
    EXPECT_EQ(got->value, expected);
  }
  EXPECT_EQ(reader.lost(), 0u);
  const auto said = errors.try_read();
  EXPECT_FALSE(said) << said->value.describe();
}

TEST_F(OptimusProcess, AServiceProcessKilledAndRestartedIsFoundAgain) {
  optimus::Core core{options()};
  auto whoami = core.service<int, int>("whoami", {.timeout = 300ms});
  auto first = helper({"serve"});
  const pid_t first_pid = first.pid();
  EXPECT_EQ(whoami(0), first_pid);

  first.kill();  // kill -9: no goodbye
  auto meanwhile = whoami.call(0);
  ASSERT_FALSE(meanwhile);
  EXPECT_TRUE(meanwhile.error().code == Errc::timeout || meanwhile.error().code == Errc::peer_dead)
      << meanwhile.error().describe();

  auto second = helper({"serve"});
  auto again = whoami.with_timeout(5000ms).call(0);
  ASSERT_TRUE(again) << again.error().describe();
  EXPECT_EQ(*again, second.pid());
  EXPECT_NE(*again, first_pid);
  RawRedis raw{shared_redis().url()};
  EXPECT_EQ(raw.integer({"LLEN", domain + ":svc:whoami"}), 0) << "no stale request was left for the new process";
}

TEST_F(OptimusProcess, ASourcePublishedByAnotherProcessIsReadHere) {
  auto publisher = helper({"publish", "imu"});
  optimus::Core core{options()};
  auto imu = core.subscribe<int>("imu", {.capacity = 1000});
  auto reader = imu.subscribe();
  publisher.send_line("go 100");
  ASSERT_TRUE(publisher.wait_for_line("published 100", 20s));
  auto values = reader.read_all();
  ASSERT_EQ(values.size(), 100u);
  for (int i = 0; i < 100; ++i) EXPECT_EQ(values[static_cast<std::size_t>(i)].value, i);
  EXPECT_EQ(reader.lost(), 0u);
  // A type it does not carry is refused by name.
  EXPECT_TRUE(fails_with([&] { (void)core.subscribe<double>("imu"); }, Errc::type_mismatch, "source 'imu'"));
}

}  // namespace
}  // namespace prime::test
