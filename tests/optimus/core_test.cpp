// Reaching the server: URLs, AUTH, Unix sockets, domains, and what an
// unreachable server looks like.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <expected>
#include <string>
#include <string_view>
#include <vector>

#include "optimus/support/optimus_fixture.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using OptimusCore = OptimusTest;

TEST_F(OptimusCore, ABadUrlIsRefusedByName) {
  EXPECT_TRUE(fails_with([] { optimus::Core core{"http://127.0.0.1:6379"}; }, Errc::unreachable, "'http://127.0.0.1:6379'"));
  EXPECT_TRUE(fails_with([] { optimus::Core core{"tcp://127.0.0.1:http"}; }, Errc::unreachable, "port"));
  EXPECT_TRUE(fails_with([] { optimus::Core core{"unix://relative/path"}; }, Errc::unreachable, "absolute"));
}

TEST_F(OptimusCore, AnUnreachableServerIsAnErrorNamingTheUrlNotAHang) {
  // A port nobody listens on: a server stopped for good.
  int port;
  {
    RedisServer gone;
    port = gone.port();
  }
  const auto url = "tcp://127.0.0.1:" + std::to_string(port);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(fails_with([&] { optimus::Core core{url}; }, Errc::unreachable, url));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);
}

// A peer that closes the connection: the first write after that brings back
// a reset, the next fails with EPIPE, and would raise SIGPIPE, which ends a
// process that does not handle it. It must be an error, and nothing else.
TEST(OptimusConnection, WritingToAPeerThatHasGoneIsAnErrorNotASignal) {
  const int listener = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(listener, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof address;
  ASSERT_EQ(::bind(listener, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  ASSERT_EQ(::listen(listener, 1), 0);
  ASSERT_EQ(::getsockname(listener, reinterpret_cast<sockaddr*>(&address), &length), 0);
  const auto url = "tcp://127.0.0.1:" + std::to_string(ntohs(address.sin_port));
  auto connection = optimus::detail::Connection::open(optimus::Options{.url = url},
                                                      *optimus::detail::parse_url(url));
  ASSERT_TRUE(connection) << connection.error().describe();
  ::close(::accept(listener, nullptr, nullptr));  // the peer goes
  ::close(listener);
  bool failed = false;
  for (int i = 0; i < 3 && !failed; ++i) {
    connection->append({"PING"});
    failed = !connection->flush();
  }
  EXPECT_TRUE(failed) << "a write to a closed peer fails";
  const auto reply = connection->reply();
  ASSERT_FALSE(reply);
  EXPECT_EQ(reply.error().code, Errc::unreachable);
  EXPECT_NE(reply.error().message.find(url), std::string::npos) << reply.error().message;
}

TEST_F(OptimusCore, ConnectsOverAUnixSocket) {
  optimus::Core core{optimus::Options{.url = shared_redis().unix_url(), .domain = domain}};
  EXPECT_EQ(core.chain([](int x) { return x + 1; })(41), 42);
}

TEST_F(OptimusCore, AuthenticatesWithAPassword) {
  RedisServer locked{{.extra = {"--requirepass", "s3cret"}}};
  EXPECT_TRUE(fails_with([&] { optimus::Core core{locked.url()}; }, Errc::unreachable, "NOAUTH"));
  EXPECT_TRUE(fails_with([&] { optimus::Core core{optimus::Options{.url = locked.url(), .password = "wrong"}}; },
                         Errc::unreachable, "refused AUTH"));
  optimus::Core core{optimus::Options{.url = locked.url(), .password = "s3cret", .domain = domain}};
  EXPECT_EQ(core.chain([](int x) { return x * 3; })(5), 15);
}

// An ACL user that may touch only keys under "robot:" (and may not flush, nor
// read the server's config, where a core looks up the longest string it takes):
// everything the medium does works there, so it touches nothing outside its
// domain; a core whose domain lies outside is refused by the server.
TEST_F(OptimusCore, WorksForAnAclUserConfinedToItsDomain) {
  RedisServer acl{{.extra = {"--user", "robot", "on", ">pw", "~robot:*", "&*", "+@all", "-flushall", "-flushdb", "-config",
                             "--user", "default", "off"}}};
  optimus::Options options{.url = acl.url(), .username = "robot", .password = "pw", .domain = "robot"};
  optimus::Core core{options};
  auto pipeline = core.chain([](int x) { return x + 1; }) | core.serve("twice", [](int x) { return 2 * x; });
  EXPECT_EQ(pipeline(20), 42);
  auto caller = core.service<int, int>("twice");
  EXPECT_EQ(caller(4), 8);
  Event<int> lidar;
  auto scans = core.source(lidar, "lidar", {.capacity = 4});
  auto reader = scans.subscribe();
  auto cmds = core.publisher<int>("cmds", {.capacity = 2, .overflow = Overflow::block});
  auto cmd_reader = cmds.source().subscribe({.capacity = 2, .overflow = Overflow::block});
  for (int i = 0; i < 6; ++i) lidar.emit(i);
  ASSERT_TRUE(cmds.publish(7));
  EXPECT_EQ(reader.read_all().size(), 4u);
  EXPECT_EQ(reader.lost(), 2u);
  EXPECT_EQ(cmd_reader.try_read()->value, 7);

  options.domain = "elsewhere";
  optimus::Core outsider{options};  // connecting is allowed; touching keys is not
  EXPECT_TRUE(fails_with([&] { (void)outsider.service<int, int>("twice"); }, Errc::unreachable, "NOPERM"));
}

// A server takes strings up to its proto-max-bulk-len (1 MiB here, the
// least it allows); a longer one makes it drop the connection. A message
// that long is refused before anything is sent, by name and with both sizes,
// and nothing sent around it is lost: by a source (one value, a batch, a
// stream), by a caller, by a service answering or handing on.
TEST_F(OptimusCore, AMessageLongerThanTheServerTakesIsRefusedByNameAndLosesNothingElse) {
  RedisServer small{{.extra = {"--proto-max-bulk-len", "1mb"}}};
  optimus::Core core{optimus::Options{.url = small.url(), .domain = domain}};
  const std::string big(std::size_t{2} << 20, 'x');
  const std::string fine = "ok";
  const auto refused = [](const std::expected<void, Error>& done, std::string_view what) {
    if (done) return ::testing::AssertionFailure() << "not refused";
    if (done.error().code != Errc::too_large || done.error().message.find(what) == std::string::npos ||
        done.error().message.find("proto-max-bulk-len, 1048576 bytes") == std::string::npos)
      return ::testing::AssertionFailure() << done.error().describe();
    return ::testing::AssertionSuccess();
  };

  auto scans = core.publisher<std::string>("scans", {.capacity = 8});
  auto reader = scans.source().subscribe({.capacity = 8});
  EXPECT_TRUE(refused(scans.publish(big), "source 'scans': a message of 20971"));
  ASSERT_TRUE(scans.publish(fine));
  const std::vector<Sample<std::string>> batch{{fine, Clock::now()}, {big, Clock::now()}, {fine, Clock::now()}};
  EXPECT_TRUE(refused(scans.publish_all(batch), "source 'scans': value 2 of a batch of 3 of 20971"));
  {
    auto stream = scans.streaming();
    const std::vector<Sample<std::string>> first{{fine, Clock::now()}}, second{{big, Clock::now()}};
    ASSERT_TRUE(stream.publish_all(first));
    EXPECT_TRUE(refused(stream.publish_all(second), "value 1 of a batch of 1"));
    ASSERT_TRUE(stream.flush()) << "the batch in flight before the refused one is answered";
  }
  const auto got = reader.read_all();
  ASSERT_EQ(got.size(), 2u) << "the value published alone and the one streamed; nothing of the refused batch";
  for (const auto& s : got) EXPECT_EQ(s.value, fine);

  auto echo = core.serve("echo", [](std::string s) { return s; });
  auto grow = core.serve("grow", [&](std::string s) { return s == "grow" ? big : s; });
  auto caller = core.service<std::string, std::string>("echo");
  const auto call_refused = [&](auto& chain, const std::string& in, std::string_view what) {
    const auto start = Clock::now();
    auto out = chain.call(in, Clock::now() + 30s);
    if (Clock::now() - start > 10s) return ::testing::AssertionFailure() << "told only at the timeout";
    return refused(out ? std::expected<void, Error>{} : std::unexpected(out.error()), what);
  };
  EXPECT_TRUE(call_refused(caller, big, "service 'echo': a request of 2097"));
  EXPECT_EQ(caller(fine), fine);
  EXPECT_TRUE(call_refused(grow, "grow", "service 'grow': its output of 2097"));
  EXPECT_EQ(grow(fine), fine) << "the worker serves on";
  auto linked = grow | echo;
  EXPECT_TRUE(call_refused(linked, "grow", "service 'grow': its output of 2097"));
  EXPECT_EQ(linked(fine), fine);
}

TEST_F(OptimusCore, DomainsSharingAServerDoNotSeeEachOther) {
  optimus::Core a{optimus::Options{.url = shared_redis().url(), .domain = domain + "-a"}};
  optimus::Core b{optimus::Options{.url = shared_redis().url(), .domain = domain + "-b"}};
  (void)a.serve("step", [](int x) { return x + 1; });
  (void)b.serve("step", [](int x) { return x - 1; });
  EXPECT_EQ((a.service<int, int>("step")(10)), 11);
  EXPECT_EQ((b.service<int, int>("step")(10)), 9);
  RawRedis raw{shared_redis().url()};
  auto keys = raw.command({"KEYS", domain + "-*"});
  ASSERT_GT(keys->size(), 0u);
  for (std::size_t i = 0; i < keys->size(); ++i) {
    const auto key = optimus::detail::text((*keys)[i]);
    EXPECT_TRUE(key.starts_with(domain + "-a:") || key.starts_with(domain + "-b:")) << key;
  }
}

TEST_F(OptimusCore, IsAMediumNamedOptimus) {
  optimus::Core core{options()};
  EXPECT_EQ(core.medium(), "optimus");
  static_assert(Medium<optimus::Core>);
}

}  // namespace
}  // namespace prime::test
