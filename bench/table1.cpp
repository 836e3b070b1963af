// The paper's Table 1: chains of 100 services, each adding one to a counter,
// for every way Prime carries a chain and for the paper's peers, in one run.
//
//   FOR       m = add(m) a hundred times, by hand
//   Radiant   add | add | ... | add, fused at compile time
//   Liberty   add | add | ... | add, linked at run time
//   Sources   producer -> event -> source -> [100-hop Liberty chain] -> output -> this thread
//             (SourcesRadiant: the same with a 100-hop Radiant chain)
//   CCR-like  producer -> port 0 -> dispatcher -> port 1 -> ... -> port 100 -> this thread
//
// Arguments: payload bytes, width (1, or 2 chains side by side). Each reports
// `ns_per_hop`: time per message and hop, CPU time for the one-thread peers and
// wall time for the threaded ones. `prime bench` makes the table.

#include <benchmark/benchmark.h>

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <ctime>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <stop_token>
#include <thread>
#include <utility>
#include <vector>

#include "ccr_like.hpp"
#include "prime/liberty.hpp"
#include "prime/radiant.hpp"
#include "services.hpp"

namespace {

using prime::Clock;
using prime::bench::add;
using prime::bench::Message;
using namespace std::chrono_literals;

constexpr std::int64_t kHops = 100;
// Messages per iteration of a threaded peer. Two batches circulate, more than
// a source queue holds, so the producer runs ahead of the chain and the block
// policy's back-pressure is part of what is measured, as with a fast driver.
constexpr std::int64_t kBatch = 1000;
constexpr auto kReadTimeout = 5s;
constexpr int kDispatcherThreads = 2;
const prime::Qos kQos{.capacity = 1024, .overflow = prime::Overflow::block};

// The same service as `add`, but visible to the optimiser here, which may fold
// a hundred calls into one. Used only by the *_Inlined benchmarks.
Message add_inlined(Message m) {
  ++m.counter;
  return m;
}

void table1_args(benchmark::internal::Benchmark* b) { b->ArgsProduct({{100, 1024, 10240}, {1, 2}}); }

std::vector<Message> make_messages(const benchmark::State& state, std::int64_t count) {
  std::vector<Message> messages;
  for (std::int64_t i = 0; i < count; ++i) messages.push_back(prime::bench::make_message(static_cast<std::size_t>(state.range(0))));
  return messages;
}

// This thread's CPU time, as Google Benchmark's own CPU column measures it: a
// one-thread peer is timed by it, so a busy machine that preempts the thread
// does not count against the peer.
std::chrono::nanoseconds thread_cpu_time() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return std::chrono::seconds{now.tv_sec} + std::chrono::nanoseconds{now.tv_nsec};
}

void report(benchmark::State& state, std::chrono::nanoseconds elapsed, std::int64_t messages) {
  state.SetItemsProcessed(messages);
  state.counters["ns_per_hop"] = static_cast<double>(elapsed.count()) / static_cast<double>(messages * kHops);
}

// ---- synchronous peers: one thread, `width` messages per iteration --------

template <class Run>
void run_chains(benchmark::State& state, Run run) {
  auto messages = make_messages(state, state.range(1));
  const auto start = thread_cpu_time();
  for (auto _ : state) {
    for (auto& m : messages) {
      m = run(std::move(m));
      benchmark::DoNotOptimize(m);
    }
  }
  const auto elapsed = thread_cpu_time() - start;
  for (const auto& m : messages) {
    if (m.counter != static_cast<std::uint64_t>(state.iterations() * kHops)) {
      state.SkipWithError("a message missed a hop");
      return;
    }
  }
  report(state, elapsed, state.iterations() * state.range(1));
}

template <Message (*Add)(Message)>
void for_loop(benchmark::State& state) {
  run_chains(state, [](Message m) {
    for (std::int64_t i = 0; i < kHops; ++i) m = Add(std::move(m));
    return m;
  });
}

// `core.chain(prime::fn<&add>)`: a function known at compile time, as the
// hand-written loop knows it (a plain `core.chain(add)` would hold a pointer).
template <Message (*Add)(Message), std::size_t... I>
auto radiant_chain(prime::radiant::Core& core, std::index_sequence<I...>) {
  return (... | ((void)I, core.chain(prime::fn<Add>)));
}

template <Message (*Add)(Message)>
void radiant(benchmark::State& state) {
  prime::radiant::Core core;
  const auto chain = radiant_chain<Add>(core, std::make_index_sequence<kHops>{});
  run_chains(state, [&chain](Message m) { return chain(std::move(m)); });
}

prime::liberty::Chain<Message, Message> liberty_chain(prime::liberty::Core& core) {
  auto chain = core.chain(add);
  for (std::int64_t i = 1; i < kHops; ++i) chain = chain | core.chain(add);
  return chain;
}

void BM_For(benchmark::State& state) { for_loop<add>(state); }
void BM_Radiant(benchmark::State& state) { radiant<add>(state); }
void BM_Liberty(benchmark::State& state) {
  prime::liberty::Core core;
  const auto chain = liberty_chain(core);
  run_chains(state, [&chain](Message m) { return chain(std::move(m)); });
}

void BM_For_Inlined(benchmark::State& state) { for_loop<add_inlined>(state); }
void BM_Radiant_Inlined(benchmark::State& state) { radiant<add_inlined>(state); }

// ---- threaded peers: a producer thread, results read by this thread -------

// Emits every message it is given, in order, from a thread of its own, as a
// driver would.
class Producer {
 public:
  explicit Producer(std::function<void(Message)> emit) : emit_{std::move(emit)} {}

  void send(std::vector<Message>& messages) {
    {
      std::scoped_lock lock{mutex_};
      for (auto& m : messages) pending_.push_back(std::move(m));
    }
    messages.clear();
    ready_.notify_one();
  }

 private:
  void run(const std::stop_token& stop) {
    std::vector<Message> batch;
    while (true) {
      {
        std::unique_lock lock{mutex_};
        if (!ready_.wait(lock, stop, [&] { return !pending_.empty(); })) return;
        batch.swap(pending_);
      }
      for (auto& m : batch) {
        if (stop.stop_requested()) return;
        emit_(std::move(m));
      }
      batch.clear();
    }
  }

  std::function<void(Message)> emit_;
  std::mutex mutex_;
  std::condition_variable_any ready_;
  std::vector<Message> pending_;
  std::jthread thread_{[this](std::stop_token stop) { run(stop); }};  // last member: stops first
};

// A steady stream: two batches of kBatch messages circulate, so the peer is
// never drained between iterations. An iteration reads the kBatch * width
// results of one batch, one from each output in turn, checks that each went
// through every hop, and sends the last lane's results back to the producer as
// the next batch, so no payload is allocated per message; the copies a width
// of 2 makes for the other lane are dropped as they are read, as a consumer
// would.
//
// Both batches go round once before the clock starts: the threads are up and
// the heaps have grown to what the stream needs (with 10 KiB values that is
// megabytes of pages faulted in once, which a short run would count).
template <class Read>
void run_stream(benchmark::State& state, Producer& producer, Read read) {
  const auto width = state.range(1);
  auto batch = make_messages(state, 2 * kBatch);
  // Reads one batch's results; false (and the benchmark skipped) on an error.
  const auto read_batch = [&] {
    for (std::int64_t i = 0; i < kBatch; ++i) {
      for (std::int64_t lane = 0; lane < width; ++lane) {
        std::optional<Message> m = read(lane, Clock::now() + kReadTimeout);
        if (!m) {
          state.SkipWithError("a message did not arrive within 5 s");
          return false;
        }
        if (m->counter != static_cast<std::uint64_t>(kHops)) {
          state.SkipWithError("a message arrived without going through every hop");
          return false;
        }
        if (lane + 1 == width) {
          m->counter = 0;
          batch.push_back(std::move(*m));
        }
      }
    }
    return true;
  };
  producer.send(batch);
  if (!read_batch() || !read_batch()) return;
  const auto start = Clock::now();
  producer.send(batch);
  for (auto _ : state) {
    if (!read_batch()) return;
    producer.send(batch);
  }
  report(state, Clock::now() - start, state.iterations() * kBatch * width);
}

// Sources with the 100 hops as one Liberty chain (the kind a system assembles
// at run time, as DESIGN.md measures source -> chain throughput) or as one
// Radiant chain.
template <class Core, class MakeChain>
void sources(benchmark::State& state, MakeChain make_chain) {
  Core core;
  prime::Event<Message> event;
  auto input = core.source(event, "input", kQos);
  std::vector<prime::Reader<Message>> outputs;
  for (std::int64_t lane = 0; lane < state.range(1); ++lane) outputs.push_back((input | make_chain(core)).subscribe());

  Producer producer{[&event](Message m) { event.emit(std::move(m)); }};
  run_stream(state, producer, [&outputs](std::int64_t lane, Clock::time_point deadline) -> std::optional<Message> {
    auto sample = outputs[static_cast<std::size_t>(lane)].read_until(deadline);
    if (!sample) return std::nullopt;
    return std::move(sample->value);
  });
  // Workers go first: a producer still waiting for room in a queue is let go.
  core.stop();
}

void BM_Sources(benchmark::State& state) { sources<prime::liberty::Core>(state, liberty_chain); }
void BM_SourcesRadiant(benchmark::State& state) {
  sources<prime::radiant::Core>(state, [](prime::radiant::Core& core) {
    return radiant_chain<add>(core, std::make_index_sequence<kHops>{});
  });
}

void BM_CcrLike(benchmark::State& state) {
  namespace ccr = prime::bench::ccr;
  const auto width = static_cast<std::size_t>(state.range(1));
  constexpr auto kPorts = static_cast<std::size_t>(kHops) + 1;  // per lane: one per service, one for the result
  std::deque<ccr::Port<Message>> ports(width * kPorts);
  const auto port = [&ports](std::size_t lane, std::size_t i) -> ccr::Port<Message>& { return ports[lane * kPorts + i]; };

  ccr::Dispatcher<Message> dispatcher{kDispatcherThreads};  // after the ports: its threads stop before they go
  for (std::size_t lane = 0; lane < width; ++lane) {
    for (std::size_t i = 0; i < kPorts - 1; ++i) {
      port(lane, i).receive_with(dispatcher, [&next = port(lane, i + 1)](Message m) { next.post(add(std::move(m))); });
    }
  }

  Producer producer{[&](Message m) {
    for (std::size_t lane = 0; lane + 1 < width; ++lane) port(lane, 0).post(m);
    port(width - 1, 0).post(std::move(m));
  }};
  run_stream(state, producer, [&](std::int64_t lane, Clock::time_point deadline) {
    return port(static_cast<std::size_t>(lane), kPorts - 1).receive_until(deadline);
  });
}

}  // namespace

BENCHMARK(BM_For)->Apply(table1_args);
BENCHMARK(BM_Radiant)->Apply(table1_args);
BENCHMARK(BM_Liberty)->Apply(table1_args);
BENCHMARK(BM_Sources)->Apply(table1_args)->UseRealTime();
BENCHMARK(BM_SourcesRadiant)->Apply(table1_args)->UseRealTime();
BENCHMARK(BM_CcrLike)->Apply(table1_args)->UseRealTime();

// Not part of Table 1: FOR and Radiant with the service visible to the
// optimiser, to check that fusion folds whatever the loop folds.
BENCHMARK(BM_For_Inlined)->Apply(table1_args);
BENCHMARK(BM_Radiant_Inlined)->Apply(table1_args);

BENCHMARK_MAIN();
