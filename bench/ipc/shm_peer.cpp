// Shm: Prime's own medium, topics of raw bytes in a domain of this benchmark.
//
// Zero copy, as for Iceoryx: "sending N bytes" is loaning an N-byte sample,
// writing a sequence number into it and publishing it; the receiver reads
// the number where the sender wrote it. The other N - 8 bytes are never
// touched by either side.
//
//   Latency          the parent publishes on `ping`; the child busy-polls its
//                    reader and answers with an N-byte sample on `pong`.
//   LatencySleeping  the same, but both readers sleep on the topic's futex
//                    at once (spin 0): the peer of FutexWake.
//   Throughput       the child publishes back-to-back on a `block` topic
//                    kStreamDepth deep (lossless: it waits for the parent);
//                    the parent busy-polls, one sample per iteration. Each
//                    sample carries its sensor's stamp, as a driver passes it
//                    on (no clock read per message: the other peers stamp
//                    nothing).
//   ShmClock         Throughput with publish()'s default stamp, the clock
//                    read at each publish: what that read costs here.
//   ShmLight         Throughput with the publisher's PublishFence::light:
//                    no full fence per publish (the parent busy-polls, so it
//                    never needs the membarrier that makes up for it).
//   ShmBatch         the same in batches: the child loans and publishes up to
//                    kBatch at once (loan_some), each with its sensor's
//                    stamp; the parent takes every sample available, up to
//                    kBatch, in one read_some.
//   ShmViews         ShmBatch read in shm::Views batches (BatchReader):
//                    each batch let go of at once, not view by view.
//   PublisherAlone   Throughput's publishing side (ShmBatch's, for
//                    PublisherAlone_ShmBatch) in this one process, on the same
//                    topic with no subscriber, its loop as the child's: one
//                    message (one batch) per iteration, no more around it. No
//                    cache line crosses cores, no one is waited for: what is
//                    left is the publisher's own bookkeeping per message, the
//                    most it could ever send to another process. The only
//                    benchmarks here with no second process (with PathAlone):
//                    the figure the two-process ones are read against.
//   PathAlone        loan, publish, take, read and release of one sample, all
//                    in this one thread: the instructions Prime runs per
//                    sample on both sides, with nothing crossing cores.
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "harness.hpp"
#include "payload.hpp"
#include "shm_domain.hpp"
#include "prime/shm.hpp"

namespace {

namespace ipc = prime::bench::ipc;
namespace shm = prime::shm;
using namespace std::chrono_literals;

shm::TopicQos latency_qos(std::size_t bytes) { return {.capacity = 4, .max_message_size = bytes}; }
shm::TopicQos stream_qos(std::size_t bytes, shm::PublishFence fence = shm::PublishFence::full) {
  return {.capacity = ipc::kStreamDepth, .max_message_size = bytes, .overflow = prime::Overflow::block,
          .block_timeout = 10s, .publish_fence = fence, .max_subscribers = 1, .max_held = 4};
}
constexpr std::size_t kBatch = 32;
shm::TopicQos batch_qos(std::size_t bytes) {
  auto qos = stream_qos(bytes);
  qos.max_held = kBatch;  // the reader holds a whole batch of views at once
  return qos;
}

// Publishes `seq` stamped `stamp`, or (none) with publish()'s default stamp.
void send(shm::Publisher<shm::Bytes>& publisher, std::size_t bytes, std::uint64_t seq,
          std::optional<prime::Clock::time_point> stamp = std::nullopt) {
  auto sample = publisher.loan(bytes);
  if (!sample) throw ipc::PeerError{"shm: " + sample.error().describe()};
  ipc::stamp(sample->bytes().data(), seq);
  if (stamp) std::move(*sample).publish(*stamp);
  else std::move(*sample).publish();
}

bool try_take(prime::Reader<shm::View<shm::Bytes>>& reader, std::uint64_t seq) {
  auto sample = reader.try_read();
  if (!sample) return false;
  const auto got = ipc::seq_of(sample->value.bytes().data());
  if (got != seq) throw ipc::out_of_sequence(seq, got);
  return true;
}

// Waits for `seq` asleep on the futex, looking at the other process between
// sleeps of at most 50 ms.
template <ipc::Side S>
void sleep_and_take(S& side, prime::Reader<shm::View<shm::Bytes>>& reader, std::uint64_t seq) {
  ipc::Patience<S> patience{side};
  while (true) {
    auto sample = reader.read_for(50ms);
    if (sample) {
      const auto got = ipc::seq_of(sample->value.bytes().data());
      if (got != seq) throw ipc::out_of_sequence(seq, got);
      return;
    }
    patience.idle();
  }
}

template <bool kSleeps>
void echo(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  const auto qos = latency_qos(self.bytes());
  auto ping = core.subscribe<shm::Bytes>("ping", {.spin = kSleeps ? 0us : 50us}, qos).subscribe();
  auto pong = core.publisher<shm::Bytes>("pong", qos);
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    if constexpr (kSleeps) sleep_and_take(self, ping, seq);
    else ipc::spin_until(self, [&] { return try_take(ping, seq); });
    send(pong, self.bytes(), seq);
  }
}
const ipc::ChildEntry kEcho{"Shm.echo", echo<false>};
const ipc::ChildEntry kEchoSleeping{"Shm.echo_sleeping", echo<true>};

// kClock: publish()'s default stamp (the clock read per sample), else the
// sensor's: its clock's reading at the start, one tick per sample on.
template <shm::PublishFence kFence, bool kClock>
void stream(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  auto out = core.publisher<shm::Bytes>("stream", stream_qos(self.bytes(), kFence));
  self.ready();
  const auto start = prime::Clock::now();
  for (std::uint64_t seq = 1;; ++seq) {
    if (seq % 1024 == 0) self.check();
    if (kClock) send(out, self.bytes(), seq);
    else send(out, self.bytes(), seq, start + prime::Clock::duration{seq});
  }
}
const ipc::ChildEntry kStream{"Shm.stream", stream<shm::PublishFence::full, false>};
const ipc::ChildEntry kStreamLight{"Shm.stream_light", stream<shm::PublishFence::light, false>};
const ipc::ChildEntry kStreamClock{"Shm.stream_clock", stream<shm::PublishFence::full, true>};

// Loans up to kBatch samples, writes seq, seq + 1... into them, each stamped
// by its sensor (`start` plus one tick per sample, as stream's), and
// publishes them at once. Returns how many. `stamps`: room for kBatch.
std::size_t send_batch(shm::Publisher<shm::Bytes>& publisher, std::size_t bytes, std::uint64_t seq,
                       prime::Clock::time_point start, std::vector<prime::Clock::time_point>& stamps) {
  auto batch = publisher.loan_some(kBatch, bytes);
  if (!batch) throw ipc::PeerError{"shm: " + batch.error().describe()};
  stamps.clear();
  for (std::size_t i = 0; i < batch->size(); ++i) {
    ipc::stamp(batch->bytes(i).data(), seq + i);
    stamps.push_back(start + prime::Clock::duration{seq + i});
  }
  std::move(*batch).publish(stamps);
  return stamps.size();
}

void stream_batches(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  auto out = core.publisher<shm::Bytes>("stream", batch_qos(self.bytes()));
  self.ready();
  const auto start = prime::Clock::now();
  std::vector<prime::Clock::time_point> stamps;
  stamps.reserve(kBatch);
  for (std::uint64_t seq = 1, checked = 0;;) {
    if (seq - checked >= 1024) {
      self.check();
      checked = seq;
    }
    seq += send_batch(out, self.bytes(), seq, start, stamps);
  }
}
const ipc::ChildEntry kStreamBatches{"Shm.stream_batches", stream_batches};

template <bool kSleeps>
void latency(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    const auto qos = latency_qos(bytes);
    auto ping = core.publisher<shm::Bytes>("ping", qos);
    auto pong = core.subscribe<shm::Bytes>("pong", {.spin = kSleeps ? 0us : 50us}, qos).subscribe();
    ipc::Link child{kSleeps ? "Shm.echo_sleeping" : "Shm.echo", bytes, {}, {domain}};
    child.wait_ready();
    child.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      send(ping, bytes, seq);
      if constexpr (kSleeps) sleep_and_take(child, pong, seq);
      else ipc::spin_until(child, [&] { return try_take(pong, seq); });
    });
    child.stop();
  });
}

void BM_Latency_Shm(benchmark::State& state) { latency<false>(state); }
void BM_Latency_ShmSleeping(benchmark::State& state) { latency<true>(state); }
BENCHMARK(BM_Latency_Shm)->Apply(ipc::latency_payloads);
BENCHMARK(BM_Latency_ShmSleeping)->Arg(64)->UseRealTime();

template <shm::PublishFence kFence, bool kClock = false>
void throughput(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto in = core.subscribe<shm::Bytes>("stream", {}, stream_qos(bytes)).subscribe();
    ipc::Link child{kClock ? "Shm.stream_clock" : kFence == shm::PublishFence::light ? "Shm.stream_light" : "Shm.stream",
                    bytes, {}, {domain}};
    child.set_drain([&] {
      while (in.try_read()) {  // one view at a time: the topic lets a subscriber hold 4
      }
    });
    child.wait_ready();
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) { ipc::spin_until(child, [&] { return try_take(in, seq); }); });
    child.stop();
  });
}

void BM_Throughput_Shm(benchmark::State& state) { throughput<shm::PublishFence::full>(state); }
void BM_Throughput_ShmLight(benchmark::State& state) { throughput<shm::PublishFence::light>(state); }
BENCHMARK(BM_Throughput_Shm)->Apply(ipc::throughput_payloads);
BENCHMARK(BM_Throughput_ShmLight)->Apply(ipc::throughput_payloads);
void BM_Throughput_ShmClock(benchmark::State& state) { throughput<shm::PublishFence::full, true>(state); }
BENCHMARK(BM_Throughput_ShmClock)->Arg(64)->UseRealTime();

void BM_Throughput_ShmBatch(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto in = core.subscribe<shm::Bytes>("stream", {}, batch_qos(bytes)).subscribe();
    ipc::Link child{"Shm.stream_batches", bytes, {}, {domain}};
    std::vector<prime::Sample<shm::View<shm::Bytes>>> taken;
    taken.reserve(kBatch);
    std::size_t next = 0;
    child.set_drain([&] {
      taken.clear();
      while (in.try_read()) {
      }
    });
    child.wait_ready();
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) {
      if (next == taken.size()) {  // all of the last batch read: let its views go, take the next
        taken.clear();
        next = 0;
        ipc::spin_until(child, [&] { return in.read_some(taken, kBatch, prime::Clock::now()).value_or(0) > 0; });
      }
      const auto got = ipc::seq_of(taken[next++].value.bytes().data());
      if (got != seq) throw ipc::out_of_sequence(seq, got);
    });
    child.stop();
  });
}
BENCHMARK(BM_Throughput_ShmBatch)->Apply(ipc::throughput_payloads);

// ShmBatch read with a BatchReader: each batch one shm::Views, let go of at once.
void BM_Throughput_ShmViews(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto in = core.subscribe<shm::Bytes>("stream", {}, batch_qos(bytes)).batches();
    ipc::Link child{"Shm.stream_batches", bytes, {}, {domain}};
    shm::Views<shm::Bytes> batch;
    std::size_t next = 0;
    child.set_drain([&] {
      batch = {};
      while (!in.try_read(kBatch).empty()) {
      }
    });
    child.wait_ready();
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) {
      if (next == batch.size()) {  // all of the last batch read: let it go, take the next
        batch = {};
        next = 0;
        ipc::spin_until(child, [&] { return !(batch = in.try_read(kBatch)).empty(); });
      }
      const auto got = ipc::seq_of(batch.bytes(next++).data());
      if (got != seq) throw ipc::out_of_sequence(seq, got);
    });
    child.stop();
  });
}
BENCHMARK(BM_Throughput_ShmViews)->Apply(ipc::throughput_payloads);

template <bool kBatches>
void publisher_alone(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto out = core.publisher<shm::Bytes>("stream", kBatches ? batch_qos(bytes) : stream_qos(bytes));
    const auto start = prime::Clock::now();
    std::vector<prime::Clock::time_point> stamps;
    stamps.reserve(kBatch);
    // As the stream children send: one message, or one batch, per iteration.
    ipc::time_sending(state, [&](std::uint64_t seq) -> std::size_t {
      if constexpr (kBatches) return send_batch(out, bytes, seq, start, stamps);
      send(out, bytes, seq, start + prime::Clock::duration{seq});
      return 1;
    });
  });
}
void BM_PublisherAlone_Shm(benchmark::State& state) { publisher_alone<false>(state); }
void BM_PublisherAlone_ShmBatch(benchmark::State& state) { publisher_alone<true>(state); }
BENCHMARK(BM_PublisherAlone_Shm)->Arg(64)->UseRealTime();
BENCHMARK(BM_PublisherAlone_ShmBatch)->Arg(64)->UseRealTime();

// The whole path of one sample in this one process and thread: loan,
// publish, take, read, release. Nothing crosses cores and nothing waits:
// what is left is the instructions Prime runs per sample on both sides.
void BM_PathAlone_Shm(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto in = core.subscribe<shm::Bytes>("stream", {}, stream_qos(bytes)).subscribe();
    auto out = core.publisher<shm::Bytes>("stream", stream_qos(bytes));
    const auto start = prime::Clock::now();
    ipc::time_sending(state, [&](std::uint64_t seq) -> std::size_t {
      send(out, bytes, seq, start + prime::Clock::duration{seq});
      if (!try_take(in, seq)) throw ipc::PeerError{"shm: sample " + std::to_string(seq) + " was not taken"};
      return 1;
    });
  });
}
BENCHMARK(BM_PathAlone_Shm)->Arg(64)->UseRealTime();

}  // namespace
