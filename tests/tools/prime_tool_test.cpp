// The prime tool against real processes: what it lists, measures, prints,
// sends and cleans, and that observing never slows a publisher.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "json.hpp"
#include "tool_runs.hpp"
#include "optimus/support/redis_server.hpp"
#include "prime/optimus.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/shm.hpp"
#include "prime/shm/detail/service_layout.hpp"
#include "shm/domain.hpp"
#include "shm/mapped_topic.hpp"
#include "shm/messages.hpp"
#include "shm/peer_process.hpp"
#include "support/within.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// `argv` run as user nobody.
std::vector<std::string> as_nobody(std::vector<std::string> argv) {
  argv.insert(argv.begin(), {"setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"});
  return argv;
}

// `prime <args...>` as user nobody, to its end.
Run prime_as_nobody(std::vector<std::string> args) {
  args.insert(args.begin(), PRIME_TOOL_PATH);
  return finished(as_nobody(std::move(args)));
}

// The last line of `text` that is a JSON object with `key` (a watch
// command's figures, not its "no new samples" lines).
tool::Json last_json_with(const std::string& text, const std::string& key) {
  std::optional<tool::Json> last;
  std::size_t at = 0;
  while (at < text.size()) {
    const auto nl = text.find('\n', at);
    const auto line = text.substr(at, nl == std::string::npos ? std::string::npos : nl - at);
    if (line.starts_with('{')) {
      auto json = tool::parse_json(line);
      if (json.is_object() && json.object().contains(key)) last = std::move(json);
    }
    at = nl == std::string::npos ? text.size() : nl + 1;
  }
  if (!last) throw std::runtime_error{"no JSON line with '" + key + "' in:\n" + text};
  return *last;
}

// A domain whose one process, which made topic "old", was killed with kill -9.
std::string killed_domain(const std::string& stem) {
  const auto dead = unique_domain(stem);
  PeerProcess crashed{{"leave_segments", dead, "old"}};
  if (!crashed.says("created")) throw std::runtime_error{"the peer made no topic"};
  crashed.kill9();
  return dead;
}


TEST(PrimeTool, LsAndInfoShowATopicAndAServiceOfRunningPeersWithTypesAndPids) {
  const auto domain = unique_domain("tool-ls");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "100", "0"}};
  PeerProcess server{{"serve", domain, "tool/echo", "echo"}};
  ASSERT_TRUE(ticks.says("publishing"));
  ASSERT_TRUE(server.says("serving"));
  const auto ls = prime(domain, {"ls"});
  EXPECT_EQ(ls.code, 0) << ls.out;
  EXPECT_NE(ls.out.find("tool/ticks"), std::string::npos) << ls.out;
  EXPECT_NE(ls.out.find("prime::test::Tick"), std::string::npos) << ls.out;
  EXPECT_NE(ls.out.find("peer-ticks (" + std::to_string(ticks.pid()) + ")"), std::string::npos) << ls.out;
  EXPECT_NE(ls.out.find("peer-serve (" + std::to_string(server.pid()) + ")"), std::string::npos) << ls.out;

  // The global options may follow the subcommand, in any order.
  const auto after = finished({PRIME_TOOL_PATH, "ls", "--json", "--domain", domain});
  EXPECT_EQ(after.code, 0) << after.out;
  EXPECT_EQ(text(last_json(after.out).object().at("topics").array().at(0), "name"), "tool/ticks") << after.out;
  const auto info_after = finished({PRIME_TOOL_PATH, "info", "tool/ticks", "--domain", domain});
  EXPECT_EQ(info_after.code, 0) << info_after.out;
  EXPECT_NE(info_after.out.find("prime::test::Tick"), std::string::npos) << info_after.out;

  const auto json = last_json(prime(domain, {"--json", "ls"}).out);
  const auto& topics = json.object().at("topics").array();
  ASSERT_EQ(topics.size(), 1u);
  EXPECT_EQ(text(topics[0], "name"), "tool/ticks");
  EXPECT_EQ(number(topics[0], "publisher_pid"), ticks.pid());
  EXPECT_EQ(text(topics[0], "publish_fence"), "full");
  EXPECT_GT(number(topics[0], "rate"), 50) << "published at 100 Hz";
  const auto& services = json.object().at("services").array();
  ASSERT_EQ(services.size(), 1u);
  EXPECT_NE(text(services[0], "request_type").find("prime::test::Ask"), std::string::npos);
  EXPECT_EQ(number(services[0], "server_pid"), server.pid());

  const auto info = prime(domain, {"info", "tool/echo"});
  EXPECT_EQ(info.code, 0);
  EXPECT_NE(info.out.find("request: prime::test::Ask (16 bytes"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("server: peer-serve (pid " + std::to_string(server.pid()) + ")"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("  who @0\n  n @8"), std::string::npos) << "its fields, by name: " << info.out;

  shm::Core core{domain};
  auto fast = core.publisher<int>("tool/fast", {.publish_fence = shm::PublishFence::light});
  const auto light = prime(domain, {"info", "tool/fast"});
  EXPECT_NE(light.out.find("\n  publish_fence: light\n"), std::string::npos) << light.out;
  const auto info_json = last_json(prime(domain, {"--json", "info", "tool/ticks"}).out);
  EXPECT_EQ(text(info_json, "name"), "tool/ticks");
  EXPECT_FALSE(info_json.object().contains("rate")) << "info measures no rate, so it shows none (not 0)";

  const auto missing = prime(domain, {"info", "tool/nothing"});
  EXPECT_EQ(missing.code, 3) << "not found";
  EXPECT_NE(missing.out.find("no topic, service or loop 'tool/nothing'"), std::string::npos) << missing.out;
  const auto no_domain = prime(unique_domain("absent"), {"ls"});
  EXPECT_EQ(no_domain.code, 3);
  EXPECT_NE(no_domain.out.find("no shm domain"), std::string::npos) << no_domain.out;
}

TEST(PrimeTool, LsAndInfoShowTheLoopsOfARunningParticipantWithTheirStatisticsUntilItDies) {
  const auto domain = unique_domain("tool-loop");
  PeerProcess looping{{"loop", domain, "control", "10"}};
  ASSERT_TRUE(looping.says("looping"));
  const auto json = last_json(prime(domain, {"--json", "ls"}).out);
  const auto& loops = json.object().at("loops").array();
  ASSERT_EQ(loops.size(), 1u) << "one loop, in the peer";
  EXPECT_EQ(text(loops[0], "name"), "control");
  EXPECT_EQ(text(loops[0], "participant"), "peer-loop");
  EXPECT_EQ(number(loops[0], "pid"), looping.pid());
  EXPECT_EQ(number(loops[0], "period_ms"), 10);
  EXPECT_EQ(number(loops[0], "deadline_ms"), 10) << "the period, when not given";
  EXPECT_GE(number(loops[0], "ticks"), 6) << "cycles 0 to 5 ran before the peer said so";
  EXPECT_GE(number(loops[0], "overruns"), 1) << "cycle 3 ran two periods";
  const auto& run_time = loops[0].object().at("run_time");
  EXPECT_GE(number(run_time, "max_ms"), 20) << "cycle 3 ran two periods";
  EXPECT_LE(number(run_time, "p50_ms"), number(run_time, "p99_ms"));
  EXPECT_LE(number(run_time, "p99_ms"), number(run_time, "max_ms"));

  const auto ls = prime(domain, {"ls"});
  EXPECT_NE(ls.out.find("LOOPS"), std::string::npos) << ls.out;
  EXPECT_NE(ls.out.find("peer-loop (" + std::to_string(looping.pid()) + ")"), std::string::npos) << ls.out;
  const auto info = prime(domain, {"info", "control"});
  EXPECT_EQ(info.code, 0) << info.out;
  EXPECT_NE(info.out.find("loop control\n  participant: peer-loop (pid " + std::to_string(looping.pid()) + ")"),
            std::string::npos) << info.out;
  EXPECT_NE(info.out.find("\n  period: 10.000 ms\n"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("\n  lateness: p50 "), std::string::npos) << info.out;

  // The ticks go on while the tool looks: the figures are live.
  const auto later = [&] {
    const auto j = last_json(prime(domain, {"--json", "info", "control"}).out);
    return number(j.array().at(0), "ticks");
  };
  const auto before = number(loops[0], "ticks");
  EXPECT_TRUE(within(10s, [&] { return later() > before; }));

  looping.kill9();
  const auto gone = last_json(prime(domain, {"--json", "ls"}).out);
  EXPECT_TRUE(gone.object().at("loops").array().empty()) << "a dead participant's loop is not listed";
}

TEST(PrimeTool, HzReportsAHundredHertzPublisherWithinTenPercent) {
  const auto domain = unique_domain("tool-hz");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "100", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  const auto hz = prime(domain, {"--json", "hz", "tool/ticks", "--duration", "3"});
  ASSERT_EQ(hz.code, 0) << hz.out;
  const auto rate = number(last_json(hz.out), "rate");
  EXPECT_GT(rate, 90) << hz.out;
  EXPECT_LT(rate, 110) << hz.out;
}

// A publisher that stops: hz says nothing new arrives, instead of
// repeating the rate of samples long gone.
TEST(PrimeTool, HzSaysSoWhenAPublisherStops) {
  const auto domain = unique_domain("tool-hz-stop");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "100", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  auto hz = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "hz", "tool/ticks", "--duration", "4"}, true);
  ASSERT_TRUE(hz.line_starting("average rate: ", 10s)) << "it measured the publisher";
  ticks.kill9();
  const auto idle = hz.line_starting("no new samples for ", 10s);
  ASSERT_TRUE(idle) << "it says the samples stopped";
}

TEST(PrimeTool, DelayReportsAKnownDelay) {
  const auto domain = unique_domain("tool-delay");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "100", "30"}};  // each stamped 30 ms before it is published
  ASSERT_TRUE(ticks.says("publishing"));
  const auto delay = prime(domain, {"--json", "delay", "tool/ticks", "--duration", "2"});
  ASSERT_EQ(delay.code, 0) << delay.out;
  const auto mean = number(last_json(delay.out), "mean");
  EXPECT_GT(mean, 0.030) << delay.out;
  EXPECT_LT(mean, 0.040) << delay.out;
}

TEST(PrimeTool, EchoPrintsADescribedTypeFieldByFieldAndAnUndescribedOneAsBytes) {
  const auto domain = unique_domain("tool-echo");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "100", "0"}};
  PeerProcess raw{{"raw", domain, "tool/raw"}};
  ASSERT_TRUE(ticks.says("publishing"));
  ASSERT_TRUE(raw.says("ready"));
  const auto described = prime(domain, {"echo", "tool/ticks", "-n", "1"});
  EXPECT_EQ(described.code, 0);
  EXPECT_NE(described.out.find("n: "), std::string::npos) << described.out;
  EXPECT_NE(described.out.find("\nx: "), std::string::npos) << described.out;
  EXPECT_NE(described.out.find("\ntag: \"t"), std::string::npos) << described.out;
  const auto bytes = prime(domain, {"echo", "tool/raw", "-n", "1"});
  EXPECT_EQ(bytes.code, 0);
  EXPECT_NE(bytes.out.find("size: 16\nbytes: 88 77 66 55 44 33 22 11 2a 00 00 00 00 00 00 00"), std::string::npos) << bytes.out;
  const auto json = last_json(prime(domain, {"--json", "echo", "tool/ticks", "-n", "1"}).out);
  EXPECT_EQ(text(json.object().at("value"), "tag").substr(0, 1), "t");
}

// What `pub` and `call` reach: a subscriber of tool/cmd that prints each
// sample, and an echo service tool/echo, in processes of their own.
struct Targets {
  explicit Targets(const std::string& domain)
      : listener{{"listen", domain, "tool/cmd"}}, server{{"serve", domain, "tool/echo", "echo"}} {}
  bool ready() { return listener.says("listening") && server.says("serving"); }
  PeerProcess listener;
  PeerProcess server;
};

TEST(PrimeTool, PubAndCallFromTheTerminalReachASubscriberAndAService) {
  const auto domain = unique_domain("tool-pub");
  Targets peers{domain};
  ASSERT_TRUE(peers.ready());
  const auto pub = prime(domain, {"pub", "tool/cmd", "n=7", "x=1.5", "tag=hi"});
  EXPECT_EQ(pub.code, 0) << pub.out;
  EXPECT_TRUE(peers.listener.says("tick 7 1.500000 hi")) << "the subscriber got what the terminal sent";
  const auto json_pub = prime(domain, {"pub", "tool/cmd", R"({"n": 8, "tag": "json"})"});
  EXPECT_EQ(json_pub.code, 0) << json_pub.out;
  EXPECT_TRUE(peers.listener.says("tick 8 0.000000 json"));
  const auto call = prime(domain, {"call", "tool/echo", "who=5", "n=14"});
  EXPECT_EQ(call.code, 0) << call.out;
  EXPECT_EQ(call.out, "who: 5\nn: 42\n");
  const auto no_rate = prime(domain, {"pub", "tool/cmd", "--rate=-1", "n=1"});
  EXPECT_EQ(no_rate.code, 2) << "a rate below 0 is a usage error, not a flood: " << no_rate.out;
  const auto wrong = prime(domain, {"pub", "tool/cmd", "speed=1"});
  EXPECT_NE(wrong.code, 0);
  EXPECT_NE(wrong.out.find("no field 'speed' (it has n, x, tag)"), std::string::npos) << wrong.out;
}

TEST(PrimeTool, GraphNamesEveryEdgeOfAThreeProcessSystem) {
  const auto domain = unique_domain("tool-graph");
  PeerProcess publisher{{"ticks", domain, "tool/ticks", "100", "0"}};
  ASSERT_TRUE(publisher.says("publishing"));
  PeerProcess subscriber{{"listen", domain, "tool/ticks"}};
  PeerProcess server{{"serve", domain, "tool/echo", "echo"}};
  ASSERT_TRUE(subscriber.says("listening"));
  ASSERT_TRUE(server.says("serving"));
  shm::Core client{domain, {.participant = "test"}};
  auto echo = client.chain<Ask, Answer>("tool/echo");  // a client while it lives
  ASSERT_TRUE(echo.call({1, 1}));
  const auto graph = prime(domain, {"graph"});
  ASSERT_EQ(graph.code, 0);
  const auto p = [](auto pid) { return "\"pid" + std::to_string(pid) + "\""; };
  for (const auto& edge : {p(publisher.pid()) + " -> \"topic:tool/ticks\" [label=\"publishes\"]",
                           "\"topic:tool/ticks\" -> " + p(subscriber.pid()) + " [label=\"subscribes\"]",
                           "\"service:tool/echo\" -> " + p(server.pid()) + " [label=\"served by\"]",
                           p(::getpid()) + " -> \"service:tool/echo\" [label=\"calls\"]"})
    EXPECT_NE(graph.out.find(edge), std::string::npos) << edge << " missing from\n" << graph.out;
  EXPECT_EQ(graph.out.rfind("digraph prime {", 0), 0u);
  EXPECT_NE(graph.out.find("label=\"tool/echo\\nprime::test::Ask -> prime::test::Answer\""), std::string::npos)
      << "a line break in DOT, not the text \\n:\n" << graph.out;
}

TEST(PrimeTool, CleanRemovesAKilledDomainsSegmentsAndLeavesALiveOneAlone) {
  const auto dead = killed_domain("tool-dead");
  ASSERT_EQ(segments_of(dead), 2);
  const auto cleaned = prime(dead, {"clean"});
  EXPECT_EQ(cleaned.code, 0);
  EXPECT_NE(cleaned.out.find("removed /dev/shm/prime." + dead + ".topic.old"), std::string::npos) << cleaned.out;
  EXPECT_EQ(segments_of(dead), 0) << "the dead domain is gone";

  const auto live = unique_domain("tool-live");
  PeerProcess alive{{"leave_segments", live, "current"}};
  ASSERT_TRUE(alive.says("created"));
  const auto kept = prime(live, {"clean"});
  EXPECT_EQ(kept.code, 0);
  EXPECT_NE(kept.out.find("nothing to clean"), std::string::npos) << kept.out;
  EXPECT_EQ(segments_of(live), 2) << "a live participant's segments are never touched";
}

// In a live domain, clean frees the slot of a subscriber killed with a
// sample held, and the sample: as a participant of the domain for that
// moment, so no one takes it for a clearer that died and clears the slot
// again under it.
TEST(PrimeTool, CleanFreesTheSlotOfASubscriberKilledInALiveDomain) {
  const auto domain = unique_domain("tool-killed-reader");
  shm::Core core{domain};
  auto publisher = core.publisher<std::uint64_t>("scan", {.capacity = 4});
  PeerProcess holder{{"hold", domain, "scan", "4", "drop", "view"}};
  ASSERT_TRUE(holder.says("subscribed"));
  ASSERT_TRUE(publisher.publish(0));
  ASSERT_TRUE(holder.says("holding"));
  holder.kill9();
  const auto cleaned = prime(domain, {"clean"});
  EXPECT_EQ(cleaned.code, 0) << cleaned.out;
  EXPECT_NE(cleaned.out.find("freed 1 subscriber and client slots"), std::string::npos) << cleaned.out;
  EXPECT_TRUE(core.registry().topics.at(0).subscriber_pids.empty());
  EXPECT_EQ(core.reclaim(), 0u) << "nothing left to free";
}

// Another user's domain (its segments are 0600) is one this user may not
// read: listed with the reason, and the others still are; clean --all
// leaves it alone and goes on. Run as user nobody against this root-made domain.
TEST(PrimeTool, DomainsAndCleanAllGoOnPastADomainThisUserMayNotRead) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root, to run the tool as another user";
  const auto domain = unique_domain("tool-other-user");
  shm::Core core{domain};
  auto publisher = core.publisher<Tick>("mine");
  const auto listed = prime_as_nobody({"domains"});
  EXPECT_EQ(listed.code, 0) << listed.out;
  EXPECT_NE(listed.out.find("could not read " + domain + ": "), std::string::npos) << listed.out;
  EXPECT_NE(listed.out.find("Permission denied"), std::string::npos) << listed.out;

  const auto json = last_json(prime_as_nobody({"--json", "domains"}).out);
  bool found = false;
  for (const auto& d : json.array())
    if (text(d, "name") == domain) found = text(d, "unreadable").find("Permission denied") != std::string::npos;
  EXPECT_TRUE(found) << "listed in JSON with the reason";

  const auto cleaned = prime_as_nobody({"clean", "--all"});
  EXPECT_EQ(cleaned.code, 0) << cleaned.out;
  EXPECT_NE(cleaned.out.find("left domain '" + domain + "' alone: "), std::string::npos) << cleaned.out;
  EXPECT_TRUE(publisher.publish(Tick{1, 0, {}})) << "the domain is as it was";
}

// A domain set up to be shared (permissions 0666 here, 0660 for a group)
// is joined by the tool as its participants join it: pub works for the
// user who set it up (it was refused: the tool asked for 0600). Another
// user's tool reads or joins it only when told to trust that user
// (--owner): whoever made a domain's files chose what the tool would read.
TEST(PrimeTool, ASharedDomainIsJoinedAsSetUpAndAnotherUsersOnlyWithOwner) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root, to run the tool as another user";
  const auto domain = unique_domain("tool-shared");
  shm::Core core{domain, {.permissions = 0666}};
  auto reader = core.subscribe<Tick>("shared").subscribe();
  const auto pub = prime(domain, {"pub", "shared", "n=5"});
  ASSERT_EQ(pub.code, 0) << pub.out;
  auto got = reader.read_for(10s);
  ASSERT_TRUE(got) << got.error().describe();
  EXPECT_EQ(got->value->n, 5u);

  const auto refused = prime_as_nobody({"--domain", domain, "ls"});
  EXPECT_EQ(refused.code, 5) << refused.out;
  EXPECT_NE(refused.out.find("shm domain '" + domain + "' was set up by root (uid 0), not by nobody (uid"),
            std::string::npos)
      << refused.out;
  EXPECT_NE(refused.out.find("(--owner)"), std::string::npos) << refused.out;
  const auto trusted = prime_as_nobody({"--domain", domain, "--owner", "root", "pub", "shared", "n=6"});
  ASSERT_EQ(trusted.code, 0) << trusted.out;
  got = reader.read_for(10s);
  ASSERT_TRUE(got) << got.error().describe();
  EXPECT_EQ(got->value->n, 6u);
  const auto unknown = prime(domain, {"--owner", "no-such-user-here", "ls"});
  EXPECT_EQ(unknown.code, 3) << unknown.out;
  EXPECT_NE(unknown.out.find("--owner \"no-such-user-here\": no such user"), std::string::npos) << unknown.out;
}

// A domain whose processes were all killed keeps what they left for a look
// (prime ls) until someone cleans it: a tool that reads or writes a topic
// joins only a running system, so it never clears a dead one, as a program
// of the system joining it does.
TEST(PrimeTool, ToolsThatJoinADomainLeaveADeadOnesSegmentsAlone) {
  const auto dead = killed_domain("tool-dead-look");
  ASSERT_EQ(segments_of(dead), 2);
  for (const auto& args : std::vector<std::vector<std::string>>{{"echo", "old", "-n", "1"}, {"hz", "old", "-n", "1"}}) {
    const auto run = prime(dead, args);
    EXPECT_EQ(run.code, 3) << args[0] << ": " << run.out;
    EXPECT_NE(run.out.find("has no live participant"), std::string::npos) << args[0] << ": " << run.out;
    EXPECT_EQ(segments_of(dead), 2) << args[0] << " left the dead domain as it was";
  }
  const auto listed = prime(dead, {"ls"});
  EXPECT_NE(listed.out.find("old"), std::string::npos) << "still there to look at:\n" << listed.out;
  EXPECT_EQ(prime(dead, {"clean"}).code, 0);
  EXPECT_EQ(segments_of(dead), 0);
}

// Input the tool cannot take is a usage error (exit 2) that names what was
// wrong, and sends nothing: text after a number, broken JSON or escapes,
// and numbers of seconds or a rate no clock can hold.
TEST(PrimeTool, MalformedInputAndOutOfRangeOptionsAreUsageErrorsNamingWhatWasWrong) {
  const auto domain = unique_domain("tool-usage");
  Targets peers{domain};
  ASSERT_TRUE(peers.ready());
  struct Case {
    std::vector<std::string> args;
    std::string says;
  };
  for (const auto& c : std::vector<Case>{
           {{"pub", "tool/cmd", "n=5m"}, "n: expected a number, not \"5m\""},
           {{"pub", "tool/cmd", R"({"n": )"}, "JSON: unexpected end"},
           {{"pub", "tool/cmd", R"({"tag": "\ud800"})"}, "a high surrogate without its low one"},
           {{"pub", "tool/cmd", "n=300000000000000000000"}, "is not a whole number from 0 to"},
           {{"pub", "tool/cmd", "--rate", "1e-300", "n=1"}, "--rate"},
           {{"pub", "tool/cmd", "--rate", "nan", "n=1"}, "--rate"},
           {{"pub", "tool/cmd", "--rate", "inf", "n=1"}, "--rate"},
           {{"call", "tool/echo", "--timeout", "1e30", "who=1"}, "--timeout"},
           {{"call", "tool/echo", "--timeout", "-1", "who=1"}, "--timeout"},
           {{"call", "tool/echo", "--timeout", "nan", "who=1"}, "--timeout"},
           {{"echo", "tool/cmd", "--timeout", "inf"}, "--timeout"},
           {{"hz", "tool/cmd", "--duration", "1e30"}, "--duration"},
           {{"pub", "tool/\x01" "cmd", "n=1"}, "a control character"},
       }) {
    const auto run = prime(domain, c.args);
    EXPECT_EQ(run.code, 2) << c.args[0] << " " << c.args[1] << " " << c.args[2] << ": " << run.out;
    EXPECT_NE(run.out.find(c.says), std::string::npos) << c.args[2] << ": " << run.out;
  }
  ASSERT_EQ(prime(domain, {"pub", "tool/cmd", "n=9"}).code, 0);
  EXPECT_EQ(peers.listener.line_starting("tick "), "tick 9 0.000000 ") << "the first sample it got is the good one";
}

// Ctrl-C ends a command that had more to do with 130, so a script never
// takes an interrupted call for an answer; one that runs until Ctrl-C (hz
// with no -n or --duration) ends as it always does, with a report and 0.
TEST(PrimeTool, CtrlCEndsAnUnfinishedCommandWith130AndAnOpenEndedOneWith0) {
  const auto domain = unique_domain("tool-ctrl-c");
  shm::Core core{domain};
  std::atomic<bool> called{false}, released{false};
  struct Release {  // a failed assertion still lets the service answer (the core joins it)
    std::atomic<bool>& released;
    ~Release() {
      released = true;
      released.notify_all();
    }
  } release{released};
  auto slow = core.serve("tool/slow", [&](const Ask& a) {
    called = true;
    released.wait(false);
    return Answer{a.who, a.n};
  });
  auto call = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "call", "tool/slow", "who=1", "n=2", "--timeout", "60"}, true);
  ASSERT_TRUE(within(10s, [&] { return called.load(); })) << "the call reached the server";
  ::kill(call.pid(), SIGINT);
  EXPECT_EQ(call.exit_code(10s), 130) << call.all_output();
  released = true;
  released.notify_all();

  auto quiet = core.publisher<Tick>("tool/quiet");
  auto echo = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "echo", "tool/quiet", "-n", "3", "--timeout", "0"}, true);
  ASSERT_TRUE(within(10s, [&] {
    for (const auto& p : core.registry().participants)
      if (p.name == "prime echo" && p.alive) return true;
    return false;
  })) << "the echo joined";
  ::kill(echo.pid(), SIGINT);
  EXPECT_EQ(echo.exit_code(10s), 130) << "it had 3 samples to print: " << echo.all_output();

  PeerProcess ticks{{"ticks", domain, "tool/ticks", "100", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  auto hz = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "hz", "tool/ticks"}, true);
  ASSERT_TRUE(hz.line_starting("average rate: ", 10s));
  ::kill(hz.pid(), SIGINT);
  EXPECT_EQ(hz.exit_code(10s), 0) << "hz runs until Ctrl-C: " << hz.all_output();
}

// A type description lies in shared memory, where any program of the user
// may write. One whose counts do not fit its message (here an array of
// 2^64-1 empty arrays in 0 bytes, which kept echo and call reading for ever)
// is refused naming the field: echo and call show such values as bytes,
// pub and call build nothing by it.
TEST(PrimeTool, AHostileTypeDescriptionIsRefusedByFieldInsteadOfHangingEchoAndCall) {
  const auto domain = unique_domain("tool-hostile");
  const std::string hostile = "{n@0:arr18446744073709551615,0(arr0,1(u8))}";
  shm::Core core{domain};
  auto publisher = core.publisher<Tick>("tool/ticks");
  std::strcpy(MappedTopic{domain, "tool/ticks"}.header().schema, hostile.c_str());
  auto echo = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "echo", "tool/ticks", "-n", "1"}, true);
  std::optional<int> code;
  for (std::uint64_t n = 0; !code && n < 2000; ++n) {  // publish until the echo has one and ends
    ASSERT_TRUE(publisher.publish(Tick{n, 0, {}}));
    code = echo.exit_code(10ms);
  }
  const auto echoed = echo.all_output(1s);
  ASSERT_EQ(code, 0) << "the echo ended: " << echoed;
  EXPECT_NE(echoed.find("field 'n': a stride of 0"), std::string::npos) << echoed;
  EXPECT_NE(echoed.find("\nbytes: "), std::string::npos) << "the sample, as bytes: " << echoed;
  const auto pub = prime(domain, {"pub", "tool/ticks", "n=1"});
  EXPECT_EQ(pub.code, 1) << pub.out;
  EXPECT_NE(pub.out.find("field 'n': a stride of 0"), std::string::npos) << pub.out;

  auto service = core.serve("tool/echo", [](const Ask& a) { return Answer{a.who, a.n}; });
  auto segment = shm::detail::Segment::open_existing(shm::detail::segment_name(domain, "service", "tool/echo"));
  ASSERT_TRUE(segment);
  auto& header = *std::launder(reinterpret_cast<shm::detail::ServiceHeader*>(segment->data()));
  std::strcpy(header.reply_schema, hostile.c_str());
  auto call = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "call", "tool/echo", "who=1", "n=2"}, true);
  ASSERT_EQ(call.exit_code(20s), 0) << "the call ended";
  const auto answered = call.all_output(1s);
  EXPECT_NE(answered.find("field 'n': a stride of 0"), std::string::npos) << answered;
  EXPECT_NE(answered.find("bytes: 01 00 00 00 00 00 00 00 02"), std::string::npos) << "the answer, as bytes: " << answered;
  std::strcpy(header.request_schema, hostile.c_str());
  const auto refused = prime(domain, {"call", "tool/echo", "n=2"});
  EXPECT_EQ(refused.code, 1) << refused.out;
  EXPECT_NE(refused.out.find("field 'n': a stride of 0"), std::string::npos) << refused.out;
}

// What clean could not remove it says it could not, with the reason, and
// exits 1; it never says it removed what is still there, and keeps the
// registry that lists it for a later clean. A dead domain of user nobody,
// one of whose files is root's: /dev/shm (sticky) lets only a file's owner
// remove it.
TEST(PrimeTool, CleanReportsARemovalThatFailedWithTheReasonAndExitsNonZero) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root, to run the tool as another user";
  const auto dead = unique_domain("tool-clean-fails");
  auto crashed = PeerProcess::command(as_nobody({SHM_PEER_PATH, "leave_segments", dead, "old"}));
  ASSERT_TRUE(crashed.says("created"));
  crashed.kill9();
  const std::string topic = "/dev/shm/prime." + dead + ".topic.old";
  ASSERT_EQ(::chown(topic.c_str(), 0, 0), 0);
  const auto cleaned = prime_as_nobody({"--domain", dead, "clean"});
  EXPECT_EQ(cleaned.code, 1) << cleaned.out;
  EXPECT_NE(cleaned.out.find("could not remove " + topic + ": Permission denied (it belongs to root (uid 0))"), std::string::npos)
      << cleaned.out;
  EXPECT_EQ(cleaned.out.find("removed " + topic), std::string::npos) << cleaned.out;
  const std::string registry = "/dev/shm/prime." + dead + ".registry.";
  EXPECT_NE(cleaned.out.find("could not remove " + registry + ": kept: it lists the segments that stay"),
            std::string::npos)
      << "the registry stays, so the topic is no orphan a later clean cannot find: " << cleaned.out;
  EXPECT_TRUE(std::filesystem::remove(topic));  // as its owner would
  const auto again = prime_as_nobody({"--domain", dead, "clean"});
  EXPECT_EQ(again.code, 0) << again.out;
  EXPECT_NE(again.out.find("removed " + registry), std::string::npos) << again.out;
  EXPECT_EQ(segments_of(dead), 0) << again.out;
}

// Compared with a twin topic no one observes, in batches taken in turn, so a
// change in the machine's load meanwhile falls on both. A speed ratio: label
// `timing`, which the sanitizer runs skip (their slowdown is their own).
TEST(PrimeToolTiming, ObservingABlockTopicNeverSlowsItsPublisher) {
  const auto domain = unique_domain("tool-observe");
  shm::Core core{domain};
  const shm::TopicQos qos{.capacity = 64, .overflow = Overflow::block, .block_timeout = 10s};
  auto publisher = core.publisher<Tick>("tool/fast", qos);
  auto reader = core.subscribe<Tick>("tool/fast", {}, qos).subscribe();
  auto twin_publisher = core.publisher<Tick>("tool/twin", qos);
  auto twin_reader = core.subscribe<Tick>("tool/twin", {}, qos).subscribe();
  std::uint64_t n = 0;
  auto batch = [&n](auto& to, auto& from) {  // messages per second, read as fast as they come
    const auto start = Clock::now();
    for (int i = 0; i < 20000; ++i) {
      EXPECT_TRUE(to.publish(Tick{n++, 0, {}}));
      while (from.try_read()) {
      }
    }
    return 20000 / std::chrono::duration<double>(Clock::now() - start).count();
  };
  // An echo whose output no one reads: it stops reading once its pipe is full.
  auto echo = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "echo", "tool/fast"});
  bool seen = false;
  for (int i = 0; i < 1000 && !seen; ++i) {  // publish until the echo prints one
    ASSERT_TRUE(publisher.publish(Tick{n++, 0, {}}));
    while (reader.try_read()) {
    }
    seen = echo.line_starting("n: ", 10ms).has_value();
  }
  ASSERT_TRUE(seen) << "the echo reads the topic";
  double observed = 0;
  double alone = 0;
  // The best of 10 batches each: the echo reads on until its pipe is full,
  // and another test may share the CPUs meanwhile.
  for (int b = 0; b < 10; ++b) {
    observed = std::max(observed, batch(publisher, reader));
    alone = std::max(alone, batch(twin_publisher, twin_reader));
  }
  EXPECT_GT(observed, 0.5 * alone) << alone << " messages/s alone, " << observed << " observed by a stalled echo";
  EXPECT_EQ(reader.lost(), 0u);
}

// Credentials reach a server that asks for them from the URL, or from the
// environment (off the command line, where `ps` shows it); no output ever
// shows the password.
TEST(PrimeTool, OptimusCredentialsComeFromTheUrlOrTheEnvironmentAndAreNeverShown) {
  RedisServer locked{{.extra = {"--requirepass", "s3cret"}}};
  const auto domain = unique_domain("tool-auth");
  const auto with_password = "tcp://:s3cret@127.0.0.1:" + std::to_string(locked.port());
  optimus::Core core{optimus::Options{.url = with_password, .domain = domain}};
  auto ticks = core.publisher<int>("ticks");
  const auto by_url = prime(domain, {"--redis", with_password, "ls"});
  EXPECT_EQ(by_url.code, 0) << by_url.out;
  EXPECT_NE(by_url.out.find("ticks"), std::string::npos) << by_url.out;
  const auto by_environment =
      finished({"env", "PRIME_REDIS_PASSWORD=s3cret", PRIME_TOOL_PATH, "--domain", domain, "--redis", locked.url(), "ls"});
  EXPECT_EQ(by_environment.code, 0) << by_environment.out;
  EXPECT_NE(by_environment.out.find("ticks"), std::string::npos) << by_environment.out;
  const auto without = prime(domain, {"--redis", locked.url(), "ls"});
  EXPECT_NE(without.code, 0) << without.out;
  const auto elsewhere = prime(domain + "-none", {"--redis", with_password, "ls"});
  EXPECT_NE(elsewhere.code, 0) << elsewhere.out;
  for (const auto* run : {&by_url, &by_environment, &without, &elsewhere})
    EXPECT_EQ(run->out.find("s3cret"), std::string::npos) << "the password is shown: " << run->out;
}

// ls, and hz, bw, delay and echo on a source, as on a shared-memory topic
// (the figures and --json are the same code for both).
TEST(PrimeTool, LsShowsAnOptimusDomainsSourcesAndServicesAndTheWatchCommandsReadASource) {
  RedisServer server;
  const auto domain = unique_domain("tool-optimus");
  optimus::Core core{optimus::Options{.url = server.url(), .domain = domain}};
  auto doubled = core.serve("double", [](int x) { return 2 * x; });
  auto ticks = core.publisher<int>("ticks");
  const auto ls = prime(domain, {"--redis", server.url(), "ls"});
  EXPECT_EQ(ls.code, 0) << ls.out;
  EXPECT_NE(ls.out.find("ticks"), std::string::npos) << ls.out;
  EXPECT_NE(ls.out.find("double"), std::string::npos) << ls.out;
  EXPECT_NE(ls.out.find("int (4 bytes"), std::string::npos) << ls.out;
  // The same server through its Unix socket, as Optimus itself reaches one.
  const auto over_socket = prime(domain, {"--redis", server.unix_url(), "ls"});
  EXPECT_EQ(over_socket.code, 0) << over_socket.out;
  EXPECT_NE(over_socket.out.find("ticks"), std::string::npos) << over_socket.out;
  const auto json = last_json(prime(domain, {"--redis", server.url(), "--json", "ls"}).out);
  EXPECT_EQ(text(json.object().at("sources").array().at(0), "name"), "ticks");
  EXPECT_EQ(json.object().at("services").array().at(0).object().at("alive").value, tool::Json{true}.value);

  const auto watching = [&](const std::string& command, std::vector<std::string> more) {
    std::vector<std::string> argv{PRIME_TOOL_PATH, "--domain", domain, "--redis", server.url(), "--json", command, "ticks"};
    argv.insert(argv.end(), more.begin(), more.end());
    return PeerProcess::command(argv, true);
  };
  auto hz = watching("hz", {"--duration", "2"});
  auto bw = watching("bw", {"--duration", "2"});
  auto delay = watching("delay", {"--duration", "2"});
  auto echo = watching("echo", {"-n", "3"});
  for (auto next = Clock::now(), end = next + 2500ms; next < end; next += 10ms) {  // 100 Hz
    std::this_thread::sleep_until(next);
    ASSERT_TRUE(ticks.publish(1, Clock::now() - 5ms));  // taken 5 ms ago
  }
  const auto rate = last_json_with(hz.all_output(), "rate");
  EXPECT_GT(number(rate, "rate"), 70) << "a 100 Hz source (over Redis, on a busy machine)";
  EXPECT_LT(number(rate, "rate"), 130);
  EXPECT_GT(number(rate, "stddev"), 0);
  const auto bandwidth = last_json_with(bw.all_output(), "bytes_per_second");
  EXPECT_EQ(number(bandwidth, "mean_size"), 20) << "an int and Optimus's 16-byte header";
  EXPECT_GT(number(bandwidth, "bytes_per_second"), 70 * 20) << "bytes per second, not per sample";
  EXPECT_LT(number(bandwidth, "bytes_per_second"), 130 * 20);
  const auto ages = last_json_with(delay.all_output(), "p50");
  EXPECT_GE(number(ages, "p50"), 0.005) << "each sample was taken 5 ms before it was published";
  EXPECT_LT(number(ages, "p50"), 1);
  const auto echoed = echo.all_output();
  const auto sample = last_json_with(echoed, "size");
  EXPECT_EQ(number(sample, "size"), 20) << echoed;
  EXPECT_GT(number(sample, "stamp_ns"), 0) << echoed;

  // A reader that values were dropped for (block policy, it read nothing in
  // time) has a second field in the readers hash, and is still one reader.
  auto stalled = core.publisher<int>("stalled", {.capacity = 8, .overflow = Overflow::block, .block_timeout = 20ms});
  auto stuck = stalled.source().subscribe({.capacity = 1, .overflow = Overflow::block});
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(stalled.publish(i));
  {
    const optimus::Options options{.url = server.url()};
    auto raw = optimus::detail::Connection::open(options, *optimus::detail::parse_url(server.url()));
    ASSERT_TRUE(raw);
    auto fields = raw->command({"HLEN", domain + ":readers:stalled"});
    ASSERT_TRUE(fields);
    ASSERT_EQ((*fields)->integer(), 2) << "a progress and a lost field";
  }
  const auto listed = last_json(prime(domain, {"--redis", server.url(), "--json", "ls"}).out);
  int listed_stalled = 0;
  for (const auto& source : listed.object().at("sources").array())
    if (text(source, "name") == "stalled") {
      ++listed_stalled;
      EXPECT_EQ(number(source, "readers"), 1.0);
    }
  EXPECT_EQ(listed_stalled, 1);

  const auto unreachable = prime(domain, {"--redis", "tcp://127.0.0.1:1", "ls"});
  EXPECT_EQ(unreachable.code, 5);
  EXPECT_NE(unreachable.out.find("unreachable"), std::string::npos) << unreachable.out;
  const auto no_scheme = prime(domain, {"--redis", "127.0.0.1:1", "ls"});
  EXPECT_EQ(no_scheme.code, 5);
  EXPECT_NE(no_scheme.out.find("bad server URL '127.0.0.1:1'"), std::string::npos) << no_scheme.out;

  // echo on a source nothing is published on gives up at its --timeout.
  const auto quiet = prime(domain, {"--redis", server.url(), "echo", "ticks", "--timeout", "0.3"});
  EXPECT_EQ(quiet.code, 4) << quiet.out;
  EXPECT_NE(quiet.out.find("nothing published on 'ticks' within 0.3 s"), std::string::npos) << quiet.out;
}

// prime record: a publisher's samples into an MCAP file, every one, with
// its stamp as log_time; prime record info says what the file holds.
}  // namespace
}  // namespace prime::test
