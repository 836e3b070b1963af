// Components alone (the harness) and system files read and checked against
// the components, with no process started.
#include <gtest/gtest.h>

#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>

#include "pipeline.hpp"
#include "support/failure.hpp"

namespace {

using namespace std::chrono_literals;
using pipeline::Count;
using prime::Errc;
using prime::test::fails_with;
namespace sys = prime::system;

TEST(ComponentHarness, FeedsAComponentAndReadsWhatItPublishesAndServes) {
  sys::Harness h{pipeline::doubler(), {{"factor", std::int64_t{5}}}};
  auto counts = h.feed<Count>("counts");
  auto doubled = h.probe<Count>("doubled");
  auto triple = h.caller<Count, Count>("triple");
  h.start();
  for (std::int64_t n = 1; n <= 20; ++n) ASSERT_TRUE(counts.publish(Count{n}, prime::Clock::time_point{std::chrono::seconds{n}}));
  for (std::int64_t n = 1; n <= 20; ++n) {
    auto got = doubled.read_for(5s);
    ASSERT_TRUE(got) << got.error().describe();
    EXPECT_EQ(got->value.n, 5 * n);
    EXPECT_EQ(got->stamp, prime::Clock::time_point{std::chrono::seconds{n}});  // the stamp goes with the value
  }
  auto answer = triple.call(Count{7});
  ASSERT_TRUE(answer) << answer.error().describe();
  EXPECT_EQ(answer->n, 21);
  auto refused = triple.call(Count{-1});  // what the block throws is the caller's error
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, Errc::block_failed);
  EXPECT_NE(refused.error().message.find("negative count"), std::string::npos) << refused.error().message;
}

TEST(ComponentHarness, RunsAComponentsTriggerWithItsParameters) {
  sys::Harness h{pipeline::counter(), {{"limit", std::int64_t{10}}, {"tick.period_ms", std::int64_t{1}}}};
  auto counts = h.probe<Count>("counts");
  h.start();
  for (std::int64_t n = 1; n <= 10; ++n) {
    auto got = counts.read_for(5s);
    ASSERT_TRUE(got) << got.error().describe();
    EXPECT_EQ(got->value.n, n);
  }
  h.stop();
  EXPECT_FALSE(counts.try_read());  // the limit held: nothing past 10
}

TEST(ComponentHarness, AnsweredCallsComeFromTheTestsServer) {
  sys::Harness h{pipeline::checker()};
  auto doubled = h.feed<Count>("doubled");
  std::atomic<int> calls = 0;
  h.serve<Count, Count>("triple", [&](const Count& c) {
    ++calls;
    return Count{c.n * 3};
  });
  auto& o = pipeline::observed();
  o.clear();
  h.start();
  for (std::int64_t n = 1; n <= 5; ++n) ASSERT_TRUE(doubled.publish(Count{2 * n}));
  EXPECT_TRUE(o.wait_for(5s, [](const auto& seen) { return seen.size() >= 5; }));
  h.stop();
  std::scoped_lock lock{o.mutex};
  ASSERT_EQ(o.seen.size(), 5u);
  for (std::int64_t n = 1; n <= 5; ++n) EXPECT_EQ(o.seen[n - 1], (pipeline::Seen{2 * n, 6 * n}));
  EXPECT_EQ(calls, 5);
}

TEST(ComponentHarness, APortUsedAsItWasNotDeclaredIsRefusedByName) {
  const auto wrong_type = sys::Component{"test.wrong_type"}.subscribes<Count>("counts").build([](sys::Context& ctx) {
    (void)ctx.input<double>("counts");
  });
  EXPECT_TRUE(fails_with([&] { sys::Harness{wrong_type}.start(); }, Errc::type_mismatch, "'counts' is declared as"));
  const auto undeclared = sys::Component{"test.undeclared"}.build([](sys::Context& ctx) { (void)ctx.output<Count>("counts"); });
  EXPECT_TRUE(fails_with([&] { sys::Harness{undeclared}.start(); }, Errc::invalid_argument, "does not declare that it publishes 'counts'"));
  EXPECT_TRUE(fails_with([&] { sys::Harness(pipeline::doubler(), {{"factor", std::string{"two"}}}).start(); }, Errc::type_mismatch,
                         "parameter 'factor' is an integer, given a string"));
  EXPECT_TRUE(fails_with([&] { sys::Harness(pipeline::doubler(), {{"gain", 1.0}}).start(); }, Errc::invalid_argument,
                         "parameter 'gain' is not declared"));
}

// Two topics of counts met by stamp in a declared synchronised set; the sum
// of each pair goes out with the pair's stamp.
sys::Component pairer() {
  return sys::Component{"test.pairer"}
      .subscribes<Count>("left", {.capacity = 64})
      .syncs<Count, Count>("pair", {"left", "right"}, prime::exact_time, {.capacity = 64})
      .publishes<Count>("sums")
      .build([](sys::Context& ctx) {
        auto sums = ctx.output<Count>("sums");
        prime::forward(ctx.synced<Count, Count>("pair"),
                       [sums](const prime::Synced<Count, Count>& set, prime::Clock::time_point stamp) {
                         (void)sums.publish(Count{std::get<0>(set).n + std::get<1>(set).n}, stamp);
                       });
      });
}

TEST(ComponentHarness, ASynchronisedSetPairsItsTopicsByStamp) {
  sys::Harness h{pairer()};
  auto left = h.feed<Count>("left");
  auto right = h.feed<Count>("right");
  auto sums = h.probe<Count>("sums");
  h.start();
  const auto at = [](std::int64_t n) { return prime::Clock::time_point{std::chrono::seconds{n}}; };
  for (std::int64_t n : {1, 2, 4, 5}) ASSERT_TRUE(left.publish(Count{n}, at(n)));
  for (std::int64_t n : {1, 2, 3, 4, 5}) ASSERT_TRUE(right.publish(Count{10 * n}, at(n)));  // 3 has no partner
  for (std::int64_t n : {1, 2, 4, 5}) {
    auto got = sums.read_for(5s);
    ASSERT_TRUE(got) << got.error().describe();
    EXPECT_EQ(got->value.n, 11 * n);
    EXPECT_EQ(got->stamp, at(n));
  }
  h.stop();
  EXPECT_FALSE(sums.try_read());  // the unmatched count made no set
}

TEST(ComponentHarness, ASynchronisedSetUsedAsItWasNotDeclaredIsRefused) {
  const auto other_types = sys::Component{"test.other_types"}
                               .syncs<Count, Count>("pair", {"left", "right"}, prime::exact_time)
                               .build([](sys::Context& ctx) { (void)ctx.synced<Count, double>("pair"); });
  EXPECT_TRUE(fails_with([&] { sys::Harness{other_types}.start(); }, Errc::type_mismatch,
                         "synchronised set 'pair' is declared as ("));
  const auto undeclared = sys::Component{"test.no_set"}.build([](sys::Context& ctx) { (void)ctx.synced<Count, Count>("pair"); });
  EXPECT_TRUE(fails_with([&] { sys::Harness{undeclared}.start(); }, Errc::invalid_argument, "declares no synchronised set 'pair'"));
  // A topic synchronised as another type than it is subscribed to as: the declaration's own mistake.
  EXPECT_TRUE(fails_with([] { (void)sys::Component{"test.both"}.subscribes<Count>("left").syncs<double, Count>("pair", {"left", "right"}, prime::exact_time); },
                         Errc::type_mismatch, "'left' is subscribed to as"));
}

TEST(ComponentHarness, ATypeThatCannotLeaveItsProcessLinksComponentsInIt) {
  const auto echo = sys::Component{"test.echo_words"}
                        .subscribes<std::string>("words")
                        .publishes<std::string>("echoed")
                        .build([](sys::Context& ctx) {
                          auto out = ctx.output<std::string>("echoed");
                          prime::forward(ctx.input<std::string>("words"),
                                         [out](const std::string& w, prime::Clock::time_point) { (void)out.publish(w + "!"); });
                        });
  sys::Harness h{echo};
  auto words = h.feed<std::string>("words");
  auto echoed = h.probe<std::string>("echoed");
  h.start();
  ASSERT_TRUE(words.publish(std::string(1000, 'a')));  // on the heap: no trivially copyable bytes
  auto got = echoed.read_for(5s);
  ASSERT_TRUE(got) << got.error().describe();
  EXPECT_EQ(got->value, std::string(1000, 'a') + "!");
}

// Readers that share each count: what each instance was given, kept alive.
struct Shared {
  std::mutex mutex;
  std::condition_variable came;
  std::map<std::string, std::vector<std::shared_ptr<const Count>>> kept;
};
Shared& shared() {
  static Shared s;
  return s;
}
// With `share`, it reads the counts shared; without, as values of its own.
sys::Component sharer() {
  return sys::Component{"test.sharer"}
      .subscribes<Count>("counts", {.capacity = 64})
      .param("share", true)
      .build([](sys::Context& ctx) {
        const auto keep = [name = ctx.name()](std::shared_ptr<const Count> count) {
          auto& s = shared();
          {
            std::scoped_lock lock{s.mutex};
            s.kept[name].push_back(std::move(count));
          }
          s.came.notify_all();
        };
        if (ctx.param<bool>("share"))
          prime::forward(ctx.shared_input<Count>("counts"),
                         [keep](const std::shared_ptr<const Count>& count, prime::Clock::time_point) { keep(count); });
        else
          prime::forward(ctx.input<Count>("counts"),
                         [keep](const Count& count, prime::Clock::time_point) { keep(std::make_shared<const Count>(count)); });
      });
}

TEST(InProcessLinks, ReadersThatShareAValueAreGivenTheSameOneAndReadersOfValuesTheirOwn) {
  sys::Registry registry;
  registry.add(pipeline::counter());
  registry.add(sharer());
  sys::Host host{{.process = "all",
                  .instances = {{"a", "test.sharer"},
                                {"b", "test.sharer"},
                                {"own", "test.sharer", {{"share", false}}},
                                {"c", "test.counter", {{"limit", std::int64_t{20}}, {"tick.period_ms", std::int64_t{1}}}}}},
                 registry};
  auto& s = shared();
  std::unique_lock lock{s.mutex};
  ASSERT_TRUE(s.came.wait_for(lock, 10s, [&] { return s.kept["a"].size() == 20 && s.kept["b"].size() == 20 && s.kept["own"].size() == 20; }));
  for (std::size_t i = 0; i < 20; ++i) {
    EXPECT_EQ(s.kept["a"][i]->n, static_cast<std::int64_t>(i + 1));
    EXPECT_EQ(s.kept["own"][i]->n, static_cast<std::int64_t>(i + 1));
    EXPECT_EQ(s.kept["a"][i].get(), s.kept["b"][i].get()) << "count " << i + 1 << " was copied for a sharing reader";
    EXPECT_NE(s.kept["a"][i].get(), s.kept["own"][i].get());
  }
}

// A system file written for one test, removed after it.
// Words: a type that cannot leave its process (not trivially copyable).
sys::Component talker() {
  return sys::Component{"test.talker"}.publishes<std::string>("words").build([](sys::Context& ctx) { (void)ctx.output<std::string>("words"); });
}

class SystemFile : public ::testing::Test {
 protected:
  void SetUp() override {
    pipeline::register_all();
    static const bool talker_registered = (sys::Registry::global().add(talker()), true);
    (void)talker_registered;
  }
  void TearDown() override { std::filesystem::remove(path_); }
  std::string write(const std::string& text) {
    std::ofstream{path_} << text;
    return path_;
  }
  const std::string path_ = ::testing::TempDir() + "/system_" + std::to_string(::getpid()) + ".yaml";
  const sys::Registry& registry = sys::Registry::global();
};

constexpr const char* kPipeline = R"(system: pipeline_test
machines:
  a: {redis: "tcp://127.0.0.1:1"}
  b: {redis: "tcp://127.0.0.1:1"}
components:
  counter: {type: test.counter, params: {limit: 12}}
  doubler: {type: test.doubler, params: {factor: 3}}
  checker: {type: test.checker}
topics:
  counts: {capacity: 128, overflow: block}
placements:
  one:
    all: [counter, doubler, checker]
  split:
    counter: [counter]
    doubler: {components: [doubler], restart: on_failure}
    checker: [checker]
  machines:
    counter: {components: [counter], machine: a}
    rest: {components: [doubler, checker], machine: b}
)";

TEST_F(SystemFile, PlansEachLinkByWhereItsEndsArePlaced) {
  const auto system = sys::load_system(write(kPipeline));
  EXPECT_TRUE(sys::problems(system, registry, "split").empty());
  auto one = sys::plan_of(system, registry, "one", "all");
  EXPECT_EQ(one.instances.size(), 3u);
  EXPECT_EQ(one.reach["counts"], sys::Reach::here);
  EXPECT_EQ(one.reach["triple"], sys::Reach::here);
  EXPECT_EQ(one.topic_qos["counts"].capacity, 128u);
  EXPECT_EQ(one.shm_domain, "pipeline_test");

  auto doubler = sys::plan_of(system, registry, "split", "doubler");
  EXPECT_EQ(doubler.reach["counts"], sys::Reach::same_machine);
  EXPECT_EQ(doubler.reach["doubled"], sys::Reach::same_machine);
  EXPECT_EQ(doubler.reach["triple"], sys::Reach::here | sys::Reach::same_machine);  // served here, called from checker
  EXPECT_EQ(std::get<std::int64_t>(doubler.instances.at(0).params.at("factor")), 3);

  auto counter = sys::plan_of(system, registry, "machines", "counter");
  EXPECT_EQ(counter.reach["counts"], sys::Reach::other_machine);
  EXPECT_EQ(counter.redis, "tcp://127.0.0.1:1");
  auto rest = sys::plan_of(system, registry, "machines", "rest");
  EXPECT_EQ(rest.reach["counts"], sys::Reach::other_machine);
  EXPECT_EQ(rest.reach["doubled"], sys::Reach::here);

  EXPECT_EQ(sys::start_order(system, registry, "split"), (std::vector<std::string>{"counter", "doubler", "checker"}));
}

TEST_F(SystemFile, StartsAProcessAfterThoseServingWhatItCalls) {
  const auto system = sys::load_system(write(R"(components:
  counter: {type: test.counter}
  doubler: {type: test.doubler}
  checker: {type: test.checker}
placements:
  p: {checker: [checker], counter: [counter], doubler: [doubler]}
)"));
  EXPECT_EQ(sys::start_order(system, registry, "p"), (std::vector<std::string>{"counter", "doubler", "checker"}));
}

TEST_F(SystemFile, TakesParameterOverridesAsTheCommandLineGivesThem) {
  const auto system = sys::load_system(write(kPipeline), {"doubler.factor=7", "counter.tick.period_ms=5"});
  auto plan = sys::plan_of(system, registry, "one", "all");
  EXPECT_EQ(std::get<std::int64_t>(plan.instances.at(1).params.at("factor")), 7);
  EXPECT_EQ(std::get<std::int64_t>(plan.instances.at(0).params.at("tick.period_ms")), 5);
  EXPECT_TRUE(fails_with([&] { (void)sys::load_system(path_, {"nobody.factor=1"}); }, Errc::invalid_argument, "has no component 'nobody'"));
}

TEST_F(SystemFile, ATopicThatCannotLeaveItsProcessStaysInItWhenNobodyReadsIt) {
  const auto system = sys::load_system(write("components:\n  t: {type: test.talker}\nplacements:\n  p: {x: [t]}\n"));
  ASSERT_TRUE(sys::problems(system, registry, "p").empty());
  const auto plan = sys::plan_of(system, registry, "p", "x");
  const auto reach = plan.reach.find("words");
  EXPECT_TRUE(reach == plan.reach.end() || reach->second == sys::Reach::here);  // not offered to the Shm domain
}

// Each wrong system names the file, the line and what is wrong.
struct WrongSystem {
  const char* name;
  std::string text;
  std::string expected;  // in the first problem
};

void PrintTo(const WrongSystem& wrong, std::ostream* out) { *out << wrong.name; }

class WrongSystems : public SystemFile, public ::testing::WithParamInterface<WrongSystem> {};

TEST_P(WrongSystems, AreRefusedNamingTheLineAndWhatIsWrong) {
  const auto& wrong = GetParam();
  const auto path = write(wrong.text);
  std::vector<std::string> found;
  try {
    found = sys::problems(sys::load_system(path), registry, "p");
  } catch (const prime::Failure& f) {
    found.push_back(f.what());
  }
  ASSERT_FALSE(found.empty()) << "nothing was found wrong";
  EXPECT_NE(found.front().find(path + ":"), std::string::npos) << found.front();
  EXPECT_NE(found.front().find(wrong.expected), std::string::npos) << found.front();
}

INSTANTIATE_TEST_SUITE_P(
    SystemFile, WrongSystems,
    ::testing::Values(
        WrongSystem{"unknown_component", "components:\n  c: {type: test.nothing}\nplacements:\n  p: {a: [c]}\n",
                    ":2: component 'c': no component type 'test.nothing' is registered"},
        WrongSystem{"unknown_parameter", "components:\n  c:\n    type: test.counter\n    params: {speed: 3}\nplacements:\n  p: {a: [c]}\n",
                    ":4: component 'c' (test.counter): parameter 'speed' is not declared"},
        WrongSystem{"wrong_parameter_type", "components:\n  c:\n    type: test.counter\n    params:\n      limit: \"many\"\nplacements:\n  p: {a: [c]}\n",
                    ":5: component 'c' (test.counter): parameter 'limit' is an integer, given a string"},
        WrongSystem{"two_publishers",
                    "components:\n  a: {type: test.counter}\n  b: {type: test.counter}\nplacements:\n  p: {x: [a, b]}\n",
                    ":3: topic 'counts' has two publishers: 'a' and 'b'"},
        WrongSystem{"nobody_serves", "components:\n  c: {type: test.checker}\nplacements:\n  p: {x: [c]}\n",
                    ":2: 'c' calls the service 'triple', which nobody serves"},
        WrongSystem{"no_redis",
                    "components:\n  a: {type: test.counter}\n  b: {type: test.doubler}\nplacements:\n  p:\n    x: {components: [a], machine: m1}\n    y: {components: [b], machine: m2}\n",
                    ":6: process 'x' on machine 'm1' is linked to another machine ('counts') and its machine has no Redis"},
        WrongSystem{"placed_twice", "components:\n  a: {type: test.counter}\nplacements:\n  p: {x: [a], y: [a]}\n",
                    "component 'a' is placed in 'x' and in 'y'"},
        WrongSystem{"placed_nowhere", "components:\n  a: {type: test.counter}\n  b: {type: test.doubler}\nplacements:\n  p: {x: [a]}\n",
                    ":5: placement 'p' places component 'b' in no process"},
        WrongSystem{"no_placement", "components:\n  a: {type: test.counter}\nplacements:\n  q: {x: [a]}\n", "no placement 'p' (it has q)"},
        WrongSystem{"unknown_key", "components:\n  a: {type: test.counter, param: {}}\nplacements:\n  p: {x: [a]}\n",
                    ":2: unknown key 'param' in component 'a' (it takes type, params)"},
        WrongSystem{"bad_overflow", "components:\n  a: {type: test.counter}\ntopics:\n  counts: {overflow: wait}\nplacements:\n  p: {x: [a]}\n",
                    ":4: topic 'counts': overflow is drop_oldest or block, not 'wait'"},
        WrongSystem{"not_yaml", "components: [a\n", ":2: not YAML"},
        WrongSystem{"process_named_twice", "components:\n  a: {type: test.counter}\nplacements:\n  p:\n    x: [a]\n    x: [a]\n",
                    ":6: 'x' appears twice in placement 'p' (first at line 5)"},
        WrongSystem{"capacity_too_large", "components:\n  a: {type: test.counter}\ntopics:\n  counts: {capacity: 100000000}\nplacements:\n  p: {x: [a]}\n",
                    ":4: topic 'counts': capacity must be from 1 to 1048576"},
        WrongSystem{"exposed_cannot_leave", "components:\n  t: {type: test.talker}\ntopics:\n  words: {expose: true}\nplacements:\n  p: {x: [t]}\n",
                    ":4: topic 'words' is exposed, and its type"}),
    [](const auto& info) { return std::string{info.param.name}; });

}  // namespace
