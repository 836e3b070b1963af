// One small system run in every placement — all in one process, one
// process per component, and split over two "machines" linked through a
// real redis-server on loopback — with the same checks in each: the same
// delivered values, the same service answers, and (where a component has a
// process of its own) the same recovery from kill -9 and a restart.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <optional>

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
  bool split;  // the doubler has a process of its own (it can be killed)
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
  machines:
    checker: {components: [checker], machine: b}
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
}

TEST_P(EveryPlacement, AKilledComponentProcessIsRestartedAndTheSystemGoesOn) {
  if (!GetParam().split) GTEST_SKIP() << "all in one process: no component has a process of its own to kill";
  limit_ = 1'000'000;  // counts for as long as the test runs
  SetUp();
  const auto system = sys::load_system(path_);
  auto& o = pipeline::observed();
  sys::Host here{sys::plan_of(system, registry_, GetParam().name, "checker")};
  std::optional<PeerProcess> doubler, counter;
  start(doubler, "doubler");
  start(counter, "counter");
  ASSERT_TRUE(o.wait_for(20s, [](const auto& seen) { return seen.size() >= 20; }));
  doubler->kill9();
  std::size_t before = 0;
  std::int64_t last = 0;
  {
    std::scoped_lock lock{o.mutex};
    before = o.seen.size();
    last = o.seen.back().doubled;
  }
  start(doubler, "doubler");
  // Values flow again, each answered, through the restarted process.
  ASSERT_TRUE(o.wait_for(20s, [&](const auto& seen) { return seen.size() >= before + 20; }));
  std::scoped_lock lock{o.mutex};
  for (std::size_t i = before; i < o.seen.size(); ++i) {
    EXPECT_GT(o.seen[i].doubled, last) << "at " << i;
    EXPECT_EQ(o.seen[i].tripled, 3 * o.seen[i].doubled);
    last = o.seen[i].doubled;
  }
}

INSTANTIATE_TEST_SUITE_P(Placements, EveryPlacement,
                         ::testing::Values(Placement{"one", false}, Placement{"split", true}, Placement{"machines", true}),
                         [](const auto& info) { return std::string{info.param.name}; });

}  // namespace
