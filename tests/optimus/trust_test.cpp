// What Optimus trusts and what it checks anyway: a request names the keys
// its answer goes to, and whoever can write a domain's request keys writes
// requests; names go into keys; credentials come from the options or the URL.
#include <gtest/gtest.h>

#include <chrono>
#include <set>
#include <string>
#include <vector>

#include "optimus/support/optimus_fixture.hpp"
#include "prime/optimus.hpp"
#include "prime/optimus/detail/envelope.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using OptimusTrust = OptimusTest;

// A request put in a service's list by hand, answered to `reply_key`.
std::string request(std::uint64_t id, const std::string& reply_key, const std::vector<std::string>& route = {}) {
  std::string envelope;
  optimus::detail::encode_request(id, reply_key, route, 0, optimus::encode_message(1), envelope);
  return envelope;
}

// The next report on `errors`: it must be Errc::damaged, from `service`, and name `key`.
::testing::AssertionResult reported(Reader<Error>& errors, const std::string& service, const std::string& key) {
  auto report = errors.read_for(5s);
  if (!report) return ::testing::AssertionFailure() << "nothing reported about '" << key << "'";
  const auto& e = report->value;
  if (e.code != Errc::damaged || e.message.find("service '" + service + "'") == std::string::npos ||
      e.message.find("'" + key + "'") == std::string::npos)
    return ::testing::AssertionFailure() << "not the report about '" << key << "': " << e.describe();
  return ::testing::AssertionSuccess();
}

// A worker answers only to its domain's reply keys. A request naming another
// application's key, or a key of its domain that is not a caller's reply key
// (here the registry, a hash, which an RPUSH refuses: the PEXPIRE after it
// ran all the same, and the registry was gone 10 s later), is dropped and
// reported by that key; nothing is written, nothing is set to expire.
TEST_F(OptimusTrust, ARequestNamingAKeyThatIsNotACallersReplyKeyIsDroppedAndReported) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto echo = core.serve("echo", [](int x) { return x; });
  RawRedis raw{shared_redis().url()};
  const auto victim = "another-app:" + domain + ":queue";
  const auto registry = domain + ":registry:services";
  raw.command({"RPUSH", victim, "precious"});
  const std::vector<std::string> foreign{victim, registry, domain + ":svc:echo", domain + ":reply:", domain + ":reply:1.ab:2:x"};
  for (std::size_t i = 0; i < foreign.size(); ++i) raw.command({"RPUSH", domain + ":svc:echo", request(i, foreign[i])});
  EXPECT_EQ(echo(9), 9) << "the worker took the others before this one, and serves on";
  for (const auto& key : foreign) EXPECT_TRUE(reported(errors, "echo", key));
  EXPECT_EQ(raw.integer({"LLEN", victim}), 1);
  EXPECT_EQ(raw.integer({"PTTL", victim}), -1) << "no expiry was set on another application's key";
  EXPECT_EQ(raw.integer({"PTTL", registry}), -1) << "nor on the registry";
  EXPECT_EQ(raw.integer({"HEXISTS", registry, "echo"}), 1);
  raw.command({"DEL", victim});
}

// A linked call hands on only to a service of the domain: a route naming
// another key (even one with an "alive" key beside it) is dropped and reported.
TEST_F(OptimusTrust, ALinkedRequestHandsOnOnlyToTheDomainsServices) {
  optimus::Core core{options()};
  auto errors = core.errors().subscribe();
  auto first = core.serve("first", [](int x) { return x + 1; });
  RawRedis raw{shared_redis().url()};
  const auto victim = "another-app:" + domain + ":queue";
  raw.command({"RPUSH", victim, "precious"});
  raw.command({"SET", victim + ":alive", "1"});
  const auto reply = domain + ":reply:1.ab:1";
  const std::vector<std::string> foreign{victim, domain + ":svc:first:alive", domain + ":svc:fir%st"};
  for (std::size_t i = 0; i < foreign.size(); ++i)
    raw.command({"RPUSH", domain + ":svc:first", request(i, reply, {foreign[i]})});
  EXPECT_EQ(first(1), 2) << "the worker took the others before this one, and serves on";
  for (const auto& key : foreign) EXPECT_TRUE(reported(errors, "first", key));
  EXPECT_EQ(raw.integer({"LLEN", victim}), 1) << "nothing was handed on to another application's key";
  EXPECT_EQ(raw.integer({"EXISTS", reply}), 0) << "no answer either: the request was dropped";
  raw.command({"DEL", victim, victim + ":alive"});
}

// Names are escaped in keys: a service named "a:alive" is not service a's
// alive key, and "a%3Aalive" is neither.
TEST_F(OptimusTrust, NamesAreEscapedSoNoTwoNamesShareAKey) {
  optimus::Core core{options()};
  auto a = core.serve("a", [](int x) { return x + 1; });
  auto a_alive = core.serve("a:alive", [](int x) { return x + 2; });
  auto a_escaped = core.serve("a%3Aalive", [](int x) { return x + 3; });
  for (const auto& [chain, expected] : {std::pair{a, 1}, std::pair{a_alive, 2}, std::pair{a_escaped, 3}}) {
    auto answer = chain.call(0, Clock::now() + 5s);
    ASSERT_TRUE(answer) << answer.error().describe();
    EXPECT_EQ(*answer, expected);
  }
  auto linked = a | a_alive | a_escaped;
  EXPECT_EQ(linked(0), 6) << "and they hand on to each other by name";
}

// Each name has one spelling in a key, and a key has at most one name: a
// key spelt otherwise (a raw ':', a bad or needless escape) names no service.
TEST_F(OptimusTrust, ANameHasOneSpellingInAKey) {
  using optimus::detail::service_key;
  using optimus::detail::service_name;
  const std::vector<std::string> names{"a", "a:alive", "a%3Aalive", "a%3aalive", "", std::string{"n\0ul", 4}, "x/y.z~_-", "*?[]"};
  std::set<std::string> keys;
  for (const auto& name : names) {
    const auto key = service_key("d:x", name);
    EXPECT_TRUE(keys.insert(key).second) << key;
    EXPECT_EQ(key.find(':', std::string{"d:x:svc:"}.size()), std::string::npos) << key;
    EXPECT_EQ(service_name("d:x", key), name) << key;
  }
  for (const std::string key : {"d:x:svc:a:alive", "d:x:svc:a%3aalive", "d:x:svc:%61", "d:x:svc:a%3", "d:y:svc:a"})
    EXPECT_FALSE(service_name("d:x", key)) << key;
  EXPECT_TRUE(optimus::detail::is_reply_key("d:x", optimus::detail::reply_key("d:x", "12.00ff", 7)));
  for (const std::string key : {"d:x:reply:", "d:x:reply:12.00ff:7:x", "d:x:reply:12:7", "d:x:reply:12.00FF:7", "d:y:reply:12.00ff:7"})
    EXPECT_FALSE(optimus::detail::is_reply_key("d:x", key)) << key;
}

// A request left in a service's list that no worker takes (its service's
// process died after saying it was alive) goes away soon after its
// deadline: here one a linked call handed on.
TEST_F(OptimusTrust, ARequestNoWorkerTakesExpiresSoonAfterItsDeadline) {
  optimus::Core core{options()};
  RawRedis raw{shared_redis().url()};
  const auto second = domain + ":svc:second";
  raw.command({"SET", second + ":alive", "1", "PX", "60000"});  // a host that died just now
  auto linked = core.serve("first", [](int x) { return x + 1; }) | core.service<int, int>("second");
  auto answer = linked.call(1, Clock::now() + 3s);  // room for the first hop under ThreadSanitizer
  ASSERT_FALSE(answer);
  EXPECT_EQ(answer.error().code, Errc::timeout) << answer.error().describe();
  ASSERT_EQ(raw.integer({"LLEN", second}), 1) << "handed on, and never taken";
  const auto ttl = raw.integer({"PTTL", second});
  EXPECT_GT(ttl, 0) << "the request has an expiry";
  EXPECT_LE(ttl, 3'000 + 10'000) << "the call's deadline and a margin";
}

// Redis's AUTH takes a password, with or without a user: a user alone is a
// mistake in the options, said as such, not a connection made without AUTH.
TEST_F(OptimusTrust, AUsernameWithoutAPasswordIsAnErrorSayingSo) {
  EXPECT_TRUE(fails_with([&] { optimus::Core core{optimus::Options{.url = shared_redis().url(), .username = "robot", .domain = domain}}; },
                         Errc::unreachable, "user 'robot' without a password"));
}

// Credentials may come in the URL (for `prime --redis`): tcp://user:password@host:port,
// percent-escaped; the password is never shown in an error.
TEST_F(OptimusTrust, CredentialsMayComeInTheUrlAndAreNeverShown) {
  RedisServer acl{{.extra = {"--user", "robot", "on", ">p@ss:w%rd", "~robot:*", "&*", "+@all", "--user", "default", "off"}}};
  const auto at = "@127.0.0.1:" + std::to_string(acl.port());
  optimus::Core core{optimus::Options{.url = "tcp://robot:p%40ss%3Aw%25rd" + at, .domain = "robot"}};
  EXPECT_EQ(core.chain([](int x) { return x + 1; })(41), 42);

  try {
    optimus::Core wrong{optimus::Options{.url = "tcp://robot:wrong-secret" + at, .domain = "robot"}};
    ADD_FAILURE() << "a wrong password was taken";
  } catch (const Failure& f) {
    EXPECT_EQ(f.error().code, Errc::unreachable);
    EXPECT_NE(std::string{f.what()}.find("refused AUTH as 'robot'"), std::string::npos) << f.what();
    EXPECT_EQ(std::string{f.what()}.find("wrong-secret"), std::string::npos) << "the password is shown: " << f.what();
  }
  EXPECT_TRUE(fails_with([&] { optimus::Core twice{optimus::Options{.url = "tcp://robot:x" + at, .password = "y"}}; },
                         Errc::unreachable, "both in the URL and in the options"));
  EXPECT_TRUE(fails_with([&] { optimus::Core broken{optimus::Options{.url = "tcp://robot:p%4" + at}}; },
                         Errc::unreachable, "a bad %-escape"));

  RedisServer locked{{.extra = {"--requirepass", "s3cret"}}};
  optimus::Core by_password{optimus::Options{.url = "tcp://:s3cret@127.0.0.1:" + std::to_string(locked.port()), .domain = domain}};
  EXPECT_EQ(by_password.chain([](int x) { return x * 3; })(5), 15);
}

}  // namespace
}  // namespace prime::test
