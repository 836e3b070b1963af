// The server stopped and started again mid-run: callers get errors meanwhile,
// connections come back, work resumes, and no request is answered twice or
// to the wrong caller.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

#include "optimus/support/optimus_fixture.hpp"

namespace prime::test {
namespace {

using OptimusFault = OptimusTest;

// What `reader` reads until it has `n` values, or 10 s have passed.
template <class Reader>
std::vector<int> read_at_least(Reader& reader, std::size_t n) {
  std::vector<int> got;
  (void)eventually(
      [&] {
        for (auto& s : reader.read_all()) got.push_back(s.value);
        return got.size() >= n;
      },
      10s);
  return got;
}

TEST_F(OptimusFault, CallersGetErrorsWhileRedisIsDownAndWorkResumesAfter) {
  RedisServer redis;  // this test's own: it is killed and restarted
  const optimus::Options opts{.url = redis.url(), .domain = domain, .call_timeout = 300ms};
  optimus::Core host{opts};
  optimus::Core callers{opts};

  std::mutex mutex;
  std::map<std::int64_t, int> runs;  // input -> how many times the service ran it
  (void)host.serve("tag", [&](std::int64_t x) {
    std::scoped_lock lock{mutex};
    ++runs[x];
    return x * 1000 + 7;
  }, {.workers = 2});
  auto tag = callers.service<std::int64_t, std::int64_t>("tag", {.timeout = 300ms});

  std::atomic<bool> done{false};
  std::atomic<int> ok{0}, failed{0}, wrong{0};
  std::vector<std::jthread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (std::int64_t i = 0; !done; ++i) {
        const std::int64_t in = t * 10'000'000 + i;
        auto out = tag.call(in);
        if (!out) {
          ++failed;
          std::this_thread::sleep_for(5ms);  // a caller's own pacing while the server is away
        } else if (*out != in * 1000 + 7) {
          ++wrong;
        } else {
          ++ok;
        }
      }
    });

  ASSERT_TRUE(eventually([&] { return ok >= 200; }, 10s));
  redis.kill();
  const int failed_before = failed;
  ASSERT_TRUE(eventually([&] { return failed >= failed_before + 8; }, 10s)) << "callers see errors while it is down";
  redis.start();
  const int ok_at_restart = ok;
  EXPECT_TRUE(eventually([&] { return ok >= ok_at_restart + 200; }, 15s)) << "work resumes after the restart";
  done = true;
  threads.clear();

  EXPECT_EQ(wrong, 0) << "no caller got another caller's answer";
  std::scoped_lock lock{mutex};
  for (const auto& [input, count] : runs) ASSERT_EQ(count, 1) << "request " << input << " ran " << count << " times";
  EXPECT_GE(static_cast<int>(runs.size()), ok.load()) << "every answer came from a run of its own";
}

TEST_F(OptimusFault, ASourceAndItsReaderCarryOnAfterARestart) {
  RedisServer redis;
  optimus::Core core{optimus::Options{.url = redis.url(), .domain = domain}};
  auto errors = core.errors().subscribe();
  auto pub = core.publisher<int>("odom");
  auto reader = pub.source().subscribe();
  ASSERT_TRUE(pub.publish(1));
  ASSERT_EQ(reader.read_for(2s)->value, 1);

  redis.kill();
  auto down = pub.publish(2);
  ASSERT_FALSE(down);
  EXPECT_EQ(down.error().code, Errc::unreachable);
  EXPECT_NE(down.error().message.find(redis.url()), std::string::npos) << down.error().message;
  auto nothing = reader.read_for(100ms);
  ASSERT_FALSE(nothing);

  redis.start();
  ASSERT_TRUE(eventually([&] { return pub.publish(3).has_value(); }, 10s));
  auto value = reader.read_for(5s);
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(value->value, 3) << "the reader follows the stream begun anew";
}

// The writer's batches append in the stream's epoch, numbered by the
// server. A restart without persistence loses the stream: the next batch
// begins it again in a later epoch, so the reader, whose cursor is in the
// old one, reads every new value, and counts none lost.
TEST_F(OptimusFault, BatchesBeginTheStreamAgainAfterARestartAndTheReaderFollows) {
  RedisServer redis;
  optimus::Core core{optimus::Options{.url = redis.url(), .domain = domain}};
  auto pub = core.publisher<int>("imu", {.capacity = 1000});
  auto reader = pub.source().subscribe({.capacity = 1000});
  std::vector<Sample<int>> batch;
  for (int i = 0; i < 200; ++i) batch.push_back({i, Clock::now()});
  ASSERT_TRUE(pub.publish_all(std::span{batch}.first(100)));
  ASSERT_EQ(reader.read_all().size(), 100u);

  redis.kill();
  redis.start();
  ASSERT_TRUE(eventually([&] { return pub.publish_all(std::span{batch}.last(100)).has_value(); }, 10s));
  const auto got = read_at_least(reader, 100);
  ASSERT_EQ(got.size(), 100u);
  for (int i = 0; i < 100; ++i) EXPECT_EQ(got[static_cast<std::size_t>(i)], 100 + i);
  EXPECT_EQ(reader.lost(), 0u);
}

// A batch in flight when the server died: flush says so (no hang), and the
// publisher streams again once the server is back, beginning the stream
// anew.
TEST_F(OptimusFault, AStreamingPublisherWhoseServerDiedSaysSoAndStreamsAgainAfterARestart) {
  RedisServer redis;
  optimus::Core core{optimus::Options{.url = redis.url(), .domain = domain}};
  auto pub = core.publisher<int>("imu", {.capacity = 1000});
  auto reader = pub.source().subscribe({.capacity = 1000});
  auto stream = pub.streaming();
  std::vector<Sample<int>> batch;
  for (int i = 0; i < 300; ++i) batch.push_back({i, Clock::now()});
  const std::span values{batch};
  ASSERT_TRUE(stream.publish_all(values.first(100)));
  ASSERT_TRUE(stream.flush());
  ASSERT_EQ(reader.read_all().size(), 100u);

  redis.kill();
  (void)stream.publish_all(values.subspan(100, 100));  // sent, or not, into a dead connection
  auto flushed = stream.flush();
  ASSERT_FALSE(flushed);
  EXPECT_EQ(flushed.error().code, Errc::unreachable);
  EXPECT_NE(flushed.error().message.find("source 'imu'"), std::string::npos) << flushed.error().message;
  EXPECT_NE(flushed.error().message.find("100 values of the last batch may not all have been appended"), std::string::npos)
      << flushed.error().message;

  redis.start();
  ASSERT_TRUE(eventually([&] { return stream.publish_all(values.last(100)).has_value() && stream.flush().has_value(); }, 10s));
  const auto got = read_at_least(reader, 100);
  ASSERT_GE(got.size(), 100u);
  for (std::size_t i = 0; i < 100; ++i) EXPECT_EQ(got[got.size() - 100 + i], 200 + static_cast<int>(i)) << "in order";
}

}  // namespace
}  // namespace prime::test
