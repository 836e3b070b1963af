// Optimus against bare hiredis on the same redis-server, in one run:
//
//   BM_Hiredis_Ping              one PING round trip: the floor
//   BM_Hiredis_RequestReply      a hand-written hiredis service: the caller
//                                pipelines RPUSH request + BLPOP reply, an echo
//                                thread BLPOPs and RPUSHes the answer — what a
//                                user would write without Prime
//   BM_Optimus_Hop               the same, as an Optimus chain call
//   BM_Optimus_Linked2           two services linked: the data goes service to service
//   BM_Optimus_CallerRouted2     the same two services, called one after the other
//   BM_Optimus_Publish           a source's values appended one round trip each
//   BM_Optimus_PublishPipelined  the same in batches of 64, one round trip per batch
//   BM_Optimus_PublishStreamed   the same streamed: one batch in flight while the
//                                next is sent (StreamingPublisher)
//   BM_Optimus_SourceThroughput  batches published and read back by a reader
//   BM_RedisBenchmark_XaddPipelined  the server's own tool, `redis-benchmark
//                                -P 64` (50 clients), appending entries like
//                                Prime's (t, d of the same size), untrimmed:
//                                the most XADDs this server takes, the peer of
//                                PublishPipelined (which also trims its stream)
//   BM_RedisBenchmark_XaddPipelinedOneClient  the same with one client (`-c 1`):
//                                one batch in flight, its replies read before
//                                the next is sent, as publish_all does
//
// The binary starts its own redis-server (persistence off) on a free loopback port.
#include <benchmark/benchmark.h>

#include <atomic>
#include <cstdio>
#include <expected>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "optimus/support/redis_server.hpp"
#include "prime/optimus.hpp"
#include "prime/optimus/detail/connection.hpp"  // a bare client: the floor Optimus is measured against

namespace {

using namespace std::chrono_literals;
using prime::optimus::detail::Connection;
using prime::optimus::detail::Reply;

// Made by the first benchmark to ask, on the benchmark's own thread: a server
// made by a thread a benchmark starts would die with that thread.
prime::test::RedisServer& server() {
  static prime::test::RedisServer redis;
  return redis;
}

prime::optimus::Options options(const std::string& domain) {
  return {.url = server().url(), .domain = "bench-" + domain};
}

Connection connect() {
  prime::optimus::Options o{.url = server().url()};
  auto c = Connection::open(o, *prime::optimus::detail::parse_url(o.url));
  if (!c) throw prime::Failure{c.error()};
  return std::move(*c);
}

void BM_Hiredis_Ping(benchmark::State& state) {
  auto c = connect();
  for (auto _ : state) {
    auto r = c.command({"PING"});
    if (!r) state.SkipWithError(r.error().describe().c_str());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Hiredis_Ping)->UseRealTime();

// A service written by hand with hiredis: what Optimus is measured against.
void BM_Hiredis_RequestReply(benchmark::State& state) {
  const std::string requests = "bench-raw:requests", replies = "bench-raw:replies";
  std::atomic<bool> done{false};
  (void)server();  // here, not first in the echo thread, which ends after each run
  std::jthread echo{[&] {
    auto c = connect();
    c.set_timeout(2s);
    bool answer_pending = false;
    std::string answer;
    while (!done) {
      if (answer_pending) c.append({"RPUSH", replies, answer});
      c.append({"BLPOP", requests, "0.2"});
      if (answer_pending && !c.reply()) return;
      auto got = c.reply();
      if (!got) return;
      answer_pending = (*got)->is_array();
      if (answer_pending) answer.assign((**got)[1].text());
    }
    if (answer_pending) (void)c.command({"RPUSH", replies, answer});
  }};
  auto c = connect();
  c.set_timeout(2s);
  std::int64_t x = 0;
  for (auto _ : state) {
    const std::string payload(reinterpret_cast<const char*>(&x), sizeof x);
    c.append({"RPUSH", requests, payload});
    c.append({"BLPOP", replies, "1"});
    auto pushed = c.reply();
    auto answer = c.reply();
    if (!pushed || !answer || !(*answer)->is_array()) {
      state.SkipWithError("the hand-written echo did not answer");
      break;
    }
    ++x;
  }
  done = true;
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Hiredis_RequestReply)->UseRealTime();

void BM_Optimus_Hop(benchmark::State& state) {
  prime::optimus::Core core{options("hop")};
  auto step = core.serve("step", [](std::int64_t x) { return x + 1; });
  std::int64_t x = 0;
  for (auto _ : state) {
    auto out = step.call(x);
    if (!out) {
      state.SkipWithError(out.error().describe().c_str());
      break;
    }
    x = *out;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Optimus_Hop)->UseRealTime();

void BM_Optimus_Linked2(benchmark::State& state) {
  prime::optimus::Core core{options("linked")};
  auto pipeline = core.serve("a", [](std::int64_t x) { return x + 1; }) | core.serve("b", [](std::int64_t x) { return x * 2; });
  std::int64_t x = 0;
  for (auto _ : state) {
    auto out = pipeline.call(x & 0xffff);
    if (!out) {
      state.SkipWithError(out.error().describe().c_str());
      break;
    }
    x = *out;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Optimus_Linked2)->UseRealTime();

void BM_Optimus_CallerRouted2(benchmark::State& state) {
  prime::optimus::Core core{options("routed")};
  auto a = core.serve("a", [](std::int64_t x) { return x + 1; });
  auto b = core.serve("b", [](std::int64_t x) { return x * 2; });
  std::int64_t x = 0;
  for (auto _ : state) {
    auto mid = a.call(x & 0xffff);
    auto out = mid ? b.call(*mid) : mid;
    if (!out) {
      state.SkipWithError(out.error().describe().c_str());
      break;
    }
    x = *out;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Optimus_CallerRouted2)->UseRealTime();

struct Imu {
  double ax, ay, az, gx, gy, gz;
  std::int64_t sequence;
};

void BM_Optimus_Publish(benchmark::State& state) {
  prime::optimus::Core core{options("publish")};
  auto pub = core.publisher<Imu>("imu", {.capacity = 4096});
  Imu imu{};
  for (auto _ : state) {
    ++imu.sequence;
    if (!pub.publish(imu)) {
      state.SkipWithError("publish failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Optimus_Publish)->UseRealTime();

// Batches of state.range(0) values, each handed to `publish_all`.
template <class PublishAll>
void publish_batches(benchmark::State& state, PublishAll&& publish_all) {
  const auto batch_size = static_cast<std::size_t>(state.range(0));
  std::vector<prime::Sample<Imu>> batch(batch_size, prime::Sample<Imu>{Imu{}, prime::Clock::now()});
  for (auto _ : state) {
    for (auto& s : batch) ++s.value.sequence;
    if (!publish_all(std::span<const prime::Sample<Imu>>{batch})) {
      state.SkipWithError("publish_all failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(batch_size));
}

void BM_Optimus_PublishPipelined(benchmark::State& state) {
  prime::optimus::Core core{options("pipelined")};
  auto pub = core.publisher<Imu>("imu", {.capacity = 4096});
  publish_batches(state, [&](auto batch) { return pub.publish_all(batch).has_value(); });
}
BENCHMARK(BM_Optimus_PublishPipelined)->Arg(64)->UseRealTime();

void BM_Optimus_PublishStreamed(benchmark::State& state) {
  prime::optimus::Core core{options("streamed")};
  auto pub = core.publisher<Imu>("imu", {.capacity = 4096});
  auto stream = pub.streaming();
  publish_batches(state, [&](auto batch) { return stream.publish_all(batch).has_value(); });
  if (!stream.flush()) state.SkipWithError("the last batch failed");
}
BENCHMARK(BM_Optimus_PublishStreamed)->Arg(64)->UseRealTime();

void BM_Optimus_SourceThroughput(benchmark::State& state) {
  prime::optimus::Core core{options("throughput")};
  auto pub = core.publisher<Imu>("imu", {.capacity = 4096});
  auto reader = pub.source().subscribe({.capacity = 4096});
  const auto batch_size = static_cast<std::size_t>(state.range(0));
  std::vector<prime::Sample<Imu>> batch(batch_size, prime::Sample<Imu>{Imu{}, prime::Clock::now()});
  std::int64_t received = 0;
  for (auto _ : state) {
    if (!pub.publish_all(batch)) {
      state.SkipWithError("publish_all failed");
      break;
    }
    received += static_cast<std::int64_t>(reader.read_all().size());
  }
  if (received != state.iterations() * static_cast<std::int64_t>(batch_size)) state.SkipWithError("values were lost");
  state.SetItemsProcessed(received);
}
BENCHMARK(BM_Optimus_SourceThroughput)->Arg(64)->UseRealTime();

// What redis-benchmark reports for `args` (requests per second), or an
// error that says why there is none.
std::expected<double, std::string> redis_benchmark(const std::string& args) {
  const std::string command = std::string{PRIME_REDIS_BENCHMARK} + " -h 127.0.0.1 -p " + std::to_string(server().port()) +
                              " -q " + args + " 2>&1";
  std::unique_ptr<FILE, int (*)(FILE*)> out{::popen(command.c_str(), "r"), ::pclose};
  if (!out) return std::unexpected("cannot start " + command);
  std::string text;
  char buffer[512];
  while (std::fgets(buffer, sizeof buffer, out.get())) text += buffer;
  // "XADD ...: 123456.78 requests per second, p50=..." after progress lines ending in \r
  const auto at = text.rfind(" requests per second");
  const auto colon = at == std::string::npos ? at : text.rfind(": ", at);
  if (colon == std::string::npos) return std::unexpected("redis-benchmark said: " + text);
  return std::stod(text.substr(colon + 2, at - colon - 2));
}

// redis-benchmark appending `requests` entries like Prime's for an Imu (a
// stamp, the encoded value) from `clients` clients, each pipelining
// `pipeline` XADDs: each iteration one run of it.
void redis_benchmark_xadd(benchmark::State& state, int clients) {
  const auto pipeline = state.range(0);
  constexpr int kRequests = 100000;
  const std::string entry = "t 1000000000000 d " + std::string(57, 'x');
  const std::string args = "-c " + std::to_string(clients) + " -P " + std::to_string(pipeline) + " -n " +
                           std::to_string(kRequests) + " XADD bench-xadd '*' " + entry;
  for (auto _ : state) {
    const auto rate = redis_benchmark(args);
    if (!rate) {
      state.SkipWithError(rate.error().c_str());
      break;
    }
    state.SetIterationTime(kRequests / *rate);
  }
  state.SetItemsProcessed(state.iterations() * kRequests);
  (void)connect().command({"DEL", "bench-xadd"});
}

void BM_RedisBenchmark_XaddPipelined(benchmark::State& state) { redis_benchmark_xadd(state, 50); }
BENCHMARK(BM_RedisBenchmark_XaddPipelined)->Arg(64)->UseManualTime()->Iterations(3);

void BM_RedisBenchmark_XaddPipelinedOneClient(benchmark::State& state) { redis_benchmark_xadd(state, 1); }
BENCHMARK(BM_RedisBenchmark_XaddPipelinedOneClient)->Arg(64)->UseManualTime()->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
