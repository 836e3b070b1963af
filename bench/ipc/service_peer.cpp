// ShmService: Prime's services between processes (request/response over
// shared-memory cells), in place both ways: the client writes a sequence
// number into an N-byte request where the service reads it, the service
// writes it back into an N-byte reply where the client reads it; the other
// bytes are never touched.
//
//   RoundTrip          the child serves; the parent calls, busy-waiting for the answer
//   RoundTripSleeping  both sides sleep at once (spin 0): the peer of two futex wakes
//   Calls/<clients>    the parent serves; 1 or 4 child processes call as fast as they can
//   Linked, Routed     the child serves a and b; the parent calls a | b (a's output goes
//                      straight to b) or a, then b itself. Both services' workers sleep
//                      (they share one CPU), so each hop costs a wake-up.
//   LinkedBusy, RoutedBusy
//                      the same with the services' workers busy-polling for
//                      50 µs too, as the caller does: they share the child's
//                      CPU, so they take turns on it.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "harness.hpp"
#include "payload.hpp"
#include "shm_domain.hpp"
#include "prime/shm.hpp"

namespace {

namespace ipc = prime::bench::ipc;
namespace shm = prime::shm;
using namespace std::chrono_literals;

shm::ServiceQos echo_qos(std::size_t bytes, std::chrono::microseconds spin) {
  return {.max_request_size = bytes, .max_reply_size = bytes, .spin = spin};
}

// Echoes the request's sequence number in an N-byte reply.
std::size_t echo(std::span<const std::byte> request, std::span<std::byte> reply) {
  ipc::stamp(reply.data(), ipc::seq_of(request.data()));
  return request.size();
}

// A call of `bytes` carrying `seq`; throws on a wrong answer or an error.
void call(const shm::ServiceChain<shm::Bytes, shm::Bytes>& service, std::size_t bytes, std::uint64_t seq) {
  std::uint64_t got = 0;
  auto done = service.call_in_place(
      [&](std::span<std::byte> request) {
        ipc::stamp(request.data(), seq);
        return bytes;
      },
      [&](std::span<const std::byte> reply) { got = ipc::seq_of(reply.data()); });
  if (!done) throw ipc::PeerError{"shm service: " + done.error().describe()};
  if (got != seq) throw ipc::out_of_sequence(seq, got);
}

// Keeps the child's process alive (its workers serve) until the parent stops it.
void serve_until_stopped(ipc::Child& self) {
  self.ready();
  ipc::sleep_until(self, [] { return false; });
}

template <bool kSleeps>
void serve(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  (void)core.serve_in_place<shm::Bytes, shm::Bytes>("echo", echo, echo_qos(self.bytes(), kSleeps ? 0us : 50us));
  serve_until_stopped(self);
}
const ipc::ChildEntry kServe{"ShmService.serve", serve<false>};
const ipc::ChildEntry kServeSleeping{"ShmService.serve_sleeping", serve<true>};

template <bool kSleeps>
void round_trip(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    ipc::Link child{kSleeps ? "ShmService.serve_sleeping" : "ShmService.serve", bytes, {}, {domain}};
    child.wait_ready();
    child.go();
    auto service = core.chain<shm::Bytes, shm::Bytes>(
        "echo", {.timeout = 10s, .wait_for_service = 10s, .spin = kSleeps ? 0us : 50us});
    ipc::time_round_trips(state, [&](std::uint64_t seq) { call(service, bytes, seq); });
    child.stop();
  });
}
void BM_RoundTrip_ShmService(benchmark::State& state) { round_trip<false>(state); }
void BM_RoundTrip_ShmServiceSleeping(benchmark::State& state) { round_trip<true>(state); }
BENCHMARK(BM_RoundTrip_ShmService)->Apply(ipc::round_trip_payloads);
BENCHMARK(BM_RoundTrip_ShmServiceSleeping)->Arg(64)->UseRealTime();

// A client process calling the parent's service until stopped.
void call_loop(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  auto service = core.chain<shm::Bytes, shm::Bytes>("echo", {.timeout = 10s, .wait_for_service = 10s});
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    if (seq % 1024 == 0) self.check();
    call(service, self.bytes(), seq);
  }
}
const ipc::ChildEntry kCallLoop{"ShmService.call_loop", call_loop};

// Calls per second that one service (one worker) answers for `clients`
// client processes calling at once; an iteration is a millisecond of them.
void BM_Calls_ShmService(benchmark::State& state) {
  ipc::run(state, [&](std::size_t) {
    const auto clients = static_cast<std::size_t>(state.range(0));
    constexpr std::size_t kBytes = 64;
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    std::atomic<std::uint64_t> answered{0};
    (void)core.serve_in_place<shm::Bytes, shm::Bytes>(
        "echo",
        [&](std::span<const std::byte> request, std::span<std::byte> reply) {
          answered.fetch_add(1, std::memory_order_relaxed);
          return echo(request, reply);
        },
        echo_qos(kBytes, 50us));
    ipc::Links links;
    for (std::size_t c = 0; c < clients; ++c) links.start("ShmService.call_loop", kBytes, {}, {domain});
    links.wait_ready();
    links.go();
    // This thread (and the service's worker, which it started) share one
    // CPU: it looks at the count every millisecond, asleep in between.
    ipc::sleep_until(links, [&] { return answered.load() >= 1000; });  // warmed up
    const auto start = std::chrono::steady_clock::now();
    const auto first = answered.load();
    for (auto _ : state) {
      std::this_thread::sleep_for(1ms);
      links.check();
    }
    const std::chrono::duration<double> elapsed = std::chrono::steady_clock::now() - start;
    state.counters["calls/s"] = static_cast<double>(answered.load() - first) / elapsed.count();
    links.stop();
  });
}
BENCHMARK(BM_Calls_ShmService)->Arg(1)->Arg(4)->UseRealTime();

template <bool kBusy>
void serve_two(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  const shm::ServiceQos qos{.spin = kBusy ? 50us : 0us};
  (void)core.serve("a", [](const std::uint64_t& x) { return x + 1; }, qos);
  (void)core.serve("b", [](const std::uint64_t& x) { return x * 2; }, qos);
  serve_until_stopped(self);
}
const ipc::ChildEntry kServeTwo{"ShmService.serve_two", serve_two<false>};
const ipc::ChildEntry kServeTwoBusy{"ShmService.serve_two_busy", serve_two<true>};

template <bool kLinked, bool kBusy = false>
void two_services(benchmark::State& state) {
  ipc::run(state, [&](std::size_t) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    ipc::Link child{kBusy ? "ShmService.serve_two_busy" : "ShmService.serve_two", 64, {}, {domain}};
    child.wait_ready();
    child.go();
    const shm::ClientQos qos{.timeout = 10s, .wait_for_service = 10s};  // the caller busy-polls (50 µs, the default)
    auto a = core.chain<std::uint64_t, std::uint64_t>("a", qos);
    auto b = core.chain<std::uint64_t, std::uint64_t>("b", qos);
    auto linked = a | b;
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      auto got = kLinked ? linked.call(seq) : b.call(a(seq));
      if (!got) throw ipc::PeerError{"shm service: " + got.error().describe()};
      if (*got != (seq + 1) * 2) throw ipc::out_of_sequence((seq + 1) * 2, *got);
    });
    child.stop();
  });
}
void BM_RoundTrip_ShmServicesLinked(benchmark::State& state) { two_services<true>(state); }
void BM_RoundTrip_ShmServicesRouted(benchmark::State& state) { two_services<false>(state); }
void BM_RoundTrip_ShmServicesLinkedBusy(benchmark::State& state) { two_services<true, true>(state); }
void BM_RoundTrip_ShmServicesRoutedBusy(benchmark::State& state) { two_services<false, true>(state); }
BENCHMARK(BM_RoundTrip_ShmServicesLinked)->Arg(64)->UseRealTime();
BENCHMARK(BM_RoundTrip_ShmServicesRouted)->Arg(64)->UseRealTime();
BENCHMARK(BM_RoundTrip_ShmServicesLinkedBusy)->Arg(64)->UseRealTime();
BENCHMARK(BM_RoundTrip_ShmServicesRoutedBusy)->Arg(64)->UseRealTime();

}  // namespace
