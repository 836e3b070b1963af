// One small system run in every placement — all in one process, one
// process per component, and split over two "machines" linked through a
// real redis-server on loopback — with the same checks in each: the same
// delivered values, the same service answers, and the same recovery from
// kill -9 of a component's process and its restart.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "optimus/support/redis_server.hpp"
#include "pipeline.hpp"
#include "shm/domain.hpp"
#include "shm/peer_process.hpp"

namespace {

using namespace std::chrono_literals;
using prime::test::PeerProcess;
namespace sys = prime::system;

struct Placement {
  const char* name;
  bool split;  // each component has a process of its own
};

class EveryPlacement : public ::testing::TestWithParam<Placement> {
 protected:
  void SetUp() override {
    pipeline::register_all();
    pipeline::observed().clear();
    std::ofstream{path_} << "system: " << domain_ << R"(
machines:
  a: {redis: ")" << redis_.url() << R"("}
  b: {redis: ")" << redis_.url() << R"("}
components:
  counter: {type: test.counter, params: {limit: )" << limit_ << R"(}}
  doubler: {type: test.doubler, params: {factor: 2}}
  checker: {type: test.checker}
topics:
  counts: {capacity: 256, overflow: block}
  doubled: {capacity: 256, overflow: block}
placements:
  one:
    all: [checker, doubler, counter]
  split:
    checker: [checker]
    doubler: [doubler]
    counter: [counter]
  machines:                 # every link between the doubler and the others through Redis
    checker: {components: [checker], machine: a}
    doubler: {components: [doubler], machine: b}
    counter: {components: [counter], machine: a}
)";
  }
  void TearDown() override { std::filesystem::remove(path_); }

  // Starts `process` of the placement in a process of its own, once it is ready.
  void start(std::optional<PeerProcess>& peer, const std::string& process) {
    peer.reset();
    peer.emplace(std::vector<std::string>{"--prime-system", path_, "--placement", GetParam().name, "--process", process});
    EXPECT_TRUE(peer->says("[prime] process '" + process + "' ready", 20s)) << process << " did not start";
  }
  // Every doubled value of 1..n, each with its tripled answer, in order.
  static bool all_of(std::int64_t from, std::int64_t to, const std::vector<pipeline::Seen>& seen, std::size_t at = 0) {
    if (seen.size() < at + static_cast<std::size_t>(to - from + 1)) return false;
    for (auto n = from; n <= to; ++n)
      if (!(seen[at + static_cast<std::size_t>(n - from)] == pipeline::Seen{2 * n, 6 * n})) return false;
    return true;
  }

  const std::string domain_ = prime::test::unique_domain("placement");
  const std::string path_ = ::testing::TempDir() + "/" + domain_ + ".yaml";
  prime::test::RedisServer redis_;
  std::int64_t limit_ = 200;
  const sys::Registry& registry_ = sys::Registry::global();
};

// Whether `address` lies in this process's mapping of a shared-memory
// segment of `domain` (/proc/self/maps: "start-end perms offset dev inode path").
bool in_shared_memory(std::uintptr_t address, const std::string& domain) {
  std::ifstream maps{"/proc/self/maps"};
  for (std::string line; std::getline(maps, line);) {
    if (line.find("/dev/shm/prime." + domain + ".") == std::string::npos) continue;
    const auto dash = line.find('-');
    const auto start = std::stoull(line.substr(0, dash), nullptr, 16);
    const auto end = std::stoull(line.substr(dash + 1, line.find(' ') - dash - 1), nullptr, 16);
    if (address >= start && address < end) return true;
  }
  return false;
}

TEST_P(EveryPlacement, DeliversEveryValueAndEveryAnswerInOrder) {
  const auto system = sys::load_system(path_);
  ASSERT_TRUE(sys::problems(system, registry_, GetParam().name).empty());
  auto& o = pipeline::observed();
  std::optional<sys::Host> here;
  std::optional<PeerProcess> doubler, counter;
  if (!GetParam().split) {
    here.emplace(sys::plan_of(system, registry_, GetParam().name, "all"));
  } else {
    // Readers first, so that no value is published before they are there.
    here.emplace(sys::plan_of(system, registry_, GetParam().name, "checker"));
    start(doubler, "doubler");
    start(counter, "counter");
  }
  EXPECT_TRUE(o.wait_for(20s, [&](const auto& seen) { return seen.size() >= static_cast<std::size_t>(limit_); }));
  std::scoped_lock lock{o.mutex};
  EXPECT_TRUE(o.errors.empty()) << o.errors.front();
  EXPECT_TRUE(all_of(1, limit_, o.seen)) << o.seen.size() << " seen";
  EXPECT_EQ(o.seen.size(), static_cast<std::size_t>(limit_));
  // The checker reads the doubled values shared: in place in shared memory
  // from the doubler's process on its machine (split); the doubler's own
  // value in this process (one); the one received from Redis (machines).
  const bool in_place = std::string{GetParam().name} == "split";
  for (const auto address : o.where) ASSERT_EQ(in_shared_memory(address, domain_), in_place) << std::hex << address;
}

// The same fault in every placement: the process hosting the doubler is
// killed with SIGKILL and started again (in `one`, the process hosting all
// three). The test reads what the checker checked as a program outside the
// system would (the topic "checked", which nobody in it reads, is in the
// Shm domain in every placement). Before and after: every value answered,
// in order. After: a counter that lived on goes on from where it was
// (split, machines), one restarted with the rest begins again at 1 (one).
TEST_P(EveryPlacement, AKilledComponentProcessIsRestartedAndTheSystemGoesOn) {
  limit_ = 1'000'000;  // counts for as long as the test runs
  SetUp();
  prime::shm::Core shm{domain_, {.participant = "test"}};
  auto checked = shm.subscribe<pipeline::Seen>("checked", {}, {.capacity = 1024}).subscribe();
  const auto names = GetParam().split ? std::vector<std::string>{"checker", "doubler", "counter"} : std::vector<std::string>{"all"};
  const std::string victim = GetParam().split ? "doubler" : "all";
  std::map<std::string, std::optional<PeerProcess>> processes;
  for (const auto& name : names) start(processes[name], name);

  std::int64_t last = 0;
  int restarts_seen = 0;
  // Reads checked values until `enough` of them were published after `since`.
  const auto read = [&](int enough, prime::Clock::time_point since) {
    for (int fresh = 0; fresh < enough;) {
      auto got = checked.read_for(10s);
      ASSERT_TRUE(got) << got.error().describe() << " after " << fresh << " values";
      const auto seen = *got->value;
      ASSERT_EQ(seen.tripled, 3 * seen.doubled) << "at " << seen.doubled;
      if (seen.doubled <= last) {  // a counter that started again: only where it was restarted
        ASSERT_FALSE(GetParam().split) << seen.doubled << " after " << last << ": the counter's process was not restarted";
        ASSERT_EQ(seen.doubled, 2) << "after " << last;
        ++restarts_seen;
      } else if (!GetParam().split) {
        ASSERT_TRUE(last == 0 || seen.doubled == last + 2) << seen.doubled << " after " << last << ": a count was lost in one process";
      }
      last = seen.doubled;
      fresh += got->stamp > since ? 1 : 0;
    }
  };
  read(20, {});
  processes[victim]->kill9();
  start(processes[victim], victim);
  const auto restarted = prime::Clock::now();
  read(20, restarted);
  EXPECT_EQ(restarts_seen, GetParam().split ? 0 : 1);
}

INSTANTIATE_TEST_SUITE_P(Placements, EveryPlacement,
                         ::testing::Values(Placement{"one", false}, Placement{"split", true}, Placement{"machines", true}),
                         [](const auto& info) { return std::string{info.param.name}; });

}  // namespace
