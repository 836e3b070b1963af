// Iceoryx: iceoryx 2.0 (Debian's), zero-copy publish/subscribe through the
// shared memory of a RouDi that this benchmark starts itself (see Roudi).
//
// Zero copy: "sending N bytes" is loaning a chunk of N bytes, writing a
// sequence number into it and publishing it; the receiver takes the chunk in
// place, reads the number and releases it. The other N - 8 bytes are never
// touched by either side, which is the point of zero copy.
//
//   Latency          the parent publishes on `ping`; the child busy-polls
//                    take(), and answers with a chunk of N bytes on `pong`,
//                    which the parent busy-polls (as the Shm rows do).
//   LatencyWaitSet   the same, but both sides sleep in a WaitSet (64 B only).
//   Throughput       the child publishes back-to-back, blocking when the
//                    parent's queue (kStreamDepth deep) is full
//                    (WAIT_FOR_CONSUMER / BLOCK_PRODUCER); the parent
//                    busy-polls take(), one chunk per iteration.
//   RoundTrip        request/response: the parent is an UntypedClient that
//                    loans an N-byte request, stamps it and sends it, then
//                    busy-polls take() for the response; the child is an
//                    UntypedServer that busy-polls take() and answers each
//                    request with a loaned N-byte response carrying its
//                    number. One request is outstanding at a time.
//
// RouDi and the runtimes: iceoryx_runtime.hpp.

#include <cstdint>
#include <optional>
#include <string>

#include "harness.hpp"
#include "iceoryx_posh/popo/untyped_client.hpp"
#include "iceoryx_posh/popo/untyped_publisher.hpp"
#include "iceoryx_posh/popo/untyped_server.hpp"
#include "iceoryx_posh/popo/untyped_subscriber.hpp"
#include "iceoryx_posh/popo/wait_set.hpp"
#include "iceoryx_runtime.hpp"
#include "payload.hpp"

namespace {

namespace ipc = prime::bench::ipc;
using namespace std::chrono_literals;

// The RouDi, the runtimes and the topic names (iceoryx_runtime.hpp).
using ipc::iceoryx::ChildRuntimeFiles;
using ipc::iceoryx::new_topic;
using ipc::iceoryx::run_on_roudi;
using ipc::iceoryx::service;
using ipc::iceoryx::start_child_runtime;

// ---- topics -----------------------------------------------------------------

iox::popo::PublisherOptions blocking_publisher() {
  iox::popo::PublisherOptions options;
  options.subscriberTooSlowPolicy = iox::popo::ConsumerTooSlowPolicy::WAIT_FOR_CONSUMER;
  return options;
}

iox::popo::SubscriberOptions blocking_subscriber() {
  iox::popo::SubscriberOptions options;
  options.queueCapacity = ipc::kStreamDepth;
  options.queueFullPolicy = iox::popo::QueueFullPolicy::BLOCK_PRODUCER;
  return options;
}

bool subscribed(const iox::popo::UntypedSubscriber& subscriber) {
  return subscriber.getSubscriptionState() == iox::SubscribeState::SUBSCRIBED;
}

// Loans a chunk of `bytes`, writes `seq` into it and publishes it: no copy.
void send(iox::popo::UntypedPublisher& publisher, std::size_t bytes, std::uint64_t seq) {
  auto chunk = publisher.loan(static_cast<std::uint32_t>(bytes));
  if (chunk.has_error())
    throw ipc::PeerError{"iceoryx could not loan a chunk of " + std::to_string(bytes) + " bytes (AllocationError " +
                         std::to_string(static_cast<int>(chunk.get_error())) + ")"};
  ipc::stamp(chunk.value(), seq);
  publisher.publish(chunk.value());
}

// Takes the next chunk, if there is one, checks it carries `seq`, and releases it.
bool try_take(iox::popo::UntypedSubscriber& subscriber, std::uint64_t seq) {
  auto chunk = subscriber.take();
  if (chunk.has_error()) {
    if (chunk.get_error() == iox::popo::ChunkReceiveResult::NO_CHUNK_AVAILABLE) return false;
    throw ipc::PeerError{"iceoryx take failed: too many chunks held"};
  }
  const std::uint64_t got = ipc::seq_of(chunk.value());
  subscriber.release(chunk.value());
  if (got != seq) throw ipc::out_of_sequence(seq, got);
  return true;
}

void drain(iox::popo::UntypedSubscriber& subscriber) {
  for (auto chunk = subscriber.take(); !chunk.has_error(); chunk = subscriber.take()) subscriber.release(chunk.value());
}

// ---- request/response -------------------------------------------------------

// One request outstanding at a time: the client takes each response before it
// sends the next request, and the server answers a request before it takes
// the next, so neither queue ever holds more than one chunk. Should one be
// full anyway, its producer waits instead of dropping (WAIT_FOR_CONSUMER /
// BLOCK_PRODUCER, the pair iceoryx connects), so nothing is ever lost.
constexpr std::uint64_t kRpcQueueCapacity = 1;

iox::popo::ClientOptions lossless_client() {
  iox::popo::ClientOptions options;
  options.responseQueueCapacity = kRpcQueueCapacity;
  options.responseQueueFullPolicy = iox::popo::QueueFullPolicy::BLOCK_PRODUCER;
  options.serverTooSlowPolicy = iox::popo::ConsumerTooSlowPolicy::WAIT_FOR_CONSUMER;
  return options;
}

iox::popo::ServerOptions lossless_server() {
  iox::popo::ServerOptions options;
  options.requestQueueCapacity = kRpcQueueCapacity;
  options.requestQueueFullPolicy = iox::popo::QueueFullPolicy::BLOCK_PRODUCER;
  options.clientTooSlowPolicy = iox::popo::ConsumerTooSlowPolicy::WAIT_FOR_CONSUMER;
  return options;
}

[[noreturn]] void loan_failed(std::size_t bytes, iox::popo::AllocationError error) {
  throw ipc::PeerError{"iceoryx could not loan a chunk of " + std::to_string(bytes) + " bytes (AllocationError " +
                       std::to_string(static_cast<int>(error)) + ")"};
}

// Loans a request of `bytes`, writes `seq` into it and sends it: no copy.
void request(iox::popo::UntypedClient& client, std::size_t bytes, std::uint64_t seq) {
  auto chunk = client.loan(static_cast<std::uint32_t>(bytes), iox::CHUNK_DEFAULT_USER_PAYLOAD_ALIGNMENT);
  if (chunk.has_error()) loan_failed(bytes, chunk.get_error());
  ipc::stamp(chunk.value(), seq);
  if (auto sent = client.send(chunk.value()); sent.has_error())
    throw ipc::PeerError{std::string{"iceoryx could not send a request: "} +
                         iox::popo::asStringLiteral(sent.get_error())};
}

// Takes the response, if it is in, checks it carries `seq`, and releases it.
bool try_take(iox::popo::UntypedClient& client, std::uint64_t seq) {
  auto chunk = client.take();
  if (chunk.has_error()) {
    if (chunk.get_error() == iox::popo::ChunkReceiveResult::NO_CHUNK_AVAILABLE) return false;
    throw ipc::PeerError{"iceoryx take failed: too many responses held"};
  }
  const std::uint64_t got = ipc::seq_of(chunk.value());
  client.releaseResponse(chunk.value());
  if (got != seq) throw ipc::out_of_sequence(seq, got);
  return true;
}

// Takes the next request, if there is one: nullptr if there is none.
const void* try_take(iox::popo::UntypedServer& server) {
  auto chunk = server.take();
  if (chunk.has_error()) {
    if (chunk.get_error() == iox::popo::ServerRequestResult::NO_PENDING_REQUESTS) return nullptr;
    throw ipc::PeerError{std::string{"iceoryx server take failed: "} + iox::popo::asStringLiteral(chunk.get_error())};
  }
  return chunk.value();
}

// Answers `request` with a loaned response of `bytes` carrying its number,
// then releases the request: no copy, and the release is off the client's
// path.
void answer(iox::popo::UntypedServer& server, const void* request, std::size_t bytes) {
  const std::uint64_t seq = ipc::seq_of(request);
  auto chunk = server.loan(iox::popo::RequestHeader::fromPayload(request), static_cast<std::uint32_t>(bytes),
                           iox::CHUNK_DEFAULT_USER_PAYLOAD_ALIGNMENT);
  if (chunk.has_error()) {
    server.releaseRequest(request);
    loan_failed(bytes, chunk.get_error());
  }
  ipc::stamp(chunk.value(), seq);
  const auto sent = server.send(chunk.value());
  server.releaseRequest(request);
  if (sent.has_error())
    throw ipc::PeerError{std::string{"iceoryx could not send a response: "} +
                         iox::popo::asStringLiteral(sent.get_error())};
}

// Sleeps in `waitset` until `subscriber` has data, then takes it.
template <ipc::Side S>
void wait_and_take(S& side, iox::popo::WaitSet<>& waitset, iox::popo::UntypedSubscriber& subscriber, std::uint64_t seq) {
  ipc::Patience<S> patience{side};
  while (!try_take(subscriber, seq))
    if (waitset.timedWait(iox::units::Duration::fromMilliseconds(50)).empty()) patience.idle();
}

void attach(iox::popo::WaitSet<>& waitset, iox::popo::UntypedSubscriber& subscriber) {
  if (waitset.attachState(subscriber, iox::popo::SubscriberState::HAS_DATA).has_error())
    throw ipc::PeerError{"iceoryx: cannot attach the subscriber to a WaitSet"};
}

// ---- the peer ---------------------------------------------------------------

// Child: "Iceoryx.echo" busy-polls, "Iceoryx.echo_waitset" sleeps.
template <bool kSleeps>
void echo(ipc::Child& self) {
  start_child_runtime(self.arg(0));
  iox::popo::UntypedSubscriber ping{service(self.arg(0), "ping")};
  iox::popo::UntypedPublisher pong{service(self.arg(0), "pong")};
  std::optional<iox::popo::WaitSet<>> waitset;
  if constexpr (kSleeps) attach(waitset.emplace(), ping);
  ipc::sleep_until(self, [&] { return subscribed(ping) && pong.hasSubscribers(); });
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    if constexpr (kSleeps) wait_and_take(self, *waitset, ping, seq);
    else ipc::spin_until(self, [&] { return try_take(ping, seq); });
    send(pong, self.bytes(), seq);
  }
}
const ipc::ChildEntry kEcho{"Iceoryx.echo", echo<false>};
const ipc::ChildEntry kEchoWaitSet{"Iceoryx.echo_waitset", echo<true>};

void stream(ipc::Child& self) {
  start_child_runtime(self.arg(0));
  iox::popo::UntypedPublisher out{service(self.arg(0), "stream"), blocking_publisher()};
  ipc::sleep_until(self, [&] { return out.hasSubscribers(); });
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    self.check();
    send(out, self.bytes(), seq);
  }
}
const ipc::ChildEntry kStream{"Iceoryx.stream", stream};

void serve(ipc::Child& self) {
  start_child_runtime(self.arg(0));
  iox::popo::UntypedServer server{service(self.arg(0), "rpc"), lossless_server()};
  ipc::sleep_until(self, [&] { return server.hasClients(); });
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    const void* request = nullptr;
    ipc::spin_until(self, [&] { return (request = try_take(server)) != nullptr; });
    if (const std::uint64_t got = ipc::seq_of(request); got != seq) {
      server.releaseRequest(request);
      throw ipc::out_of_sequence(seq, got);
    }
    answer(server, request, self.bytes());
  }
}
const ipc::ChildEntry kServe{"Iceoryx.serve", serve};

template <bool kSleeps>
void latency(benchmark::State& state) {
  run_on_roudi(state, [&](std::size_t bytes) {
    const std::string topic = new_topic();
    iox::popo::UntypedPublisher ping{service(topic, "ping")};
    iox::popo::UntypedSubscriber pong{service(topic, "pong")};
    std::optional<iox::popo::WaitSet<>> waitset;
    if constexpr (kSleeps) attach(waitset.emplace(), pong);
    const ChildRuntimeFiles files{topic};
    ipc::Link child{kSleeps ? "Iceoryx.echo_waitset" : "Iceoryx.echo", bytes, {}, {topic}};
    child.wait_ready();
    ipc::sleep_until(child, [&] { return subscribed(pong) && ping.hasSubscribers(); });
    child.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      send(ping, bytes, seq);
      if constexpr (kSleeps) wait_and_take(child, *waitset, pong, seq);
      else ipc::spin_until(child, [&] { return try_take(pong, seq); });
    });
    child.stop();
  });
}

void BM_Latency_Iceoryx(benchmark::State& state) { latency<false>(state); }
void BM_Latency_IceoryxWaitSet(benchmark::State& state) { latency<true>(state); }
BENCHMARK(BM_Latency_Iceoryx)->Apply(ipc::latency_payloads);
BENCHMARK(BM_Latency_IceoryxWaitSet)->Arg(64)->UseRealTime();

void BM_Throughput_Iceoryx(benchmark::State& state) {
  run_on_roudi(state, [&](std::size_t bytes) {
    const std::string topic = new_topic();
    iox::popo::UntypedSubscriber in{service(topic, "stream"), blocking_subscriber()};
    const ChildRuntimeFiles files{topic};
    ipc::Link child{"Iceoryx.stream", bytes, {}, {topic}};
    // The child may be blocked on a full queue: keep taking until it is gone
    // (a child killed inside publish() would leave RouDi hanging, see
    // run_on_roudi), and leave nothing queued for RouDi to clean up.
    child.set_drain([&] { drain(in); });
    child.wait_ready();
    ipc::sleep_until(child, [&] { return subscribed(in); });
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) { ipc::spin_until(child, [&] { return try_take(in, seq); }); });
    child.stop();
    drain(in);
  });
}
BENCHMARK(BM_Throughput_Iceoryx)->Apply(ipc::throughput_payloads);

void BM_RoundTrip_Iceoryx(benchmark::State& state) {
  run_on_roudi(state, [&](std::size_t bytes) {
    const std::string topic = new_topic();
    iox::popo::UntypedClient client{service(topic, "rpc"), lossless_client()};
    const ChildRuntimeFiles files{topic};
    ipc::Link child{"Iceoryx.serve", bytes, {}, {topic}};
    child.wait_ready();
    ipc::sleep_until(child, [&] { return client.getConnectionState() == iox::ConnectionState::CONNECTED; });
    child.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      request(client, bytes, seq);
      ipc::spin_until(child, [&] { return try_take(client, seq); });
    });
    child.stop();
  });
}
BENCHMARK(BM_RoundTrip_Iceoryx)->Apply(ipc::round_trip_payloads);

}  // namespace
