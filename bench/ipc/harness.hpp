#pragma once

// The harness of prime_ipc: every benchmark runs between two real processes
// (but PublisherAlone and PathAlone, in shm_peer.cpp: Shm's publishing side,
// and its whole path, by themselves in one thread, the figures the
// two-process ones are read against).
// This process (the parent) times; the other (the child) is this same binary
// re-executed as `prime_ipc --ipc-child <entry> ...`, which benchmark_main()
// hands to child_main() before Google Benchmark or any library sees it. So a child
// never inherits library state (iceoryx's runtime, say) from the parent, and
// the parent may start as many children as it likes: one per benchmark run.
// While it lives, the parent's thread runs on one CPU and the child on another
// (--ipc_no_pin turns that off).
//
// How a peer plugs in: one file, bench/ipc/<peer>_peer.cpp, holding both
// sides, added to prime_ipc's sources in CMakeLists.txt. floor_peer.cpp is the
// smallest example:
//
//   // Child side: a function registered under "<Peer>.<role>".
//   void echo(ipc::Child& self) {
//     auto line = ipc::SharedMapping::adopt(self.fd(0), sizeof(Line));
//     self.ready();                        // set up: wait for the parent's go()
//     for (std::uint64_t seq = 1;; ++seq) {
//       ipc::spin_until(self, [&] { return line.ping == seq; });
//       line.pong = seq;
//     }                                    // ends when the parent stops it
//   }
//   const ipc::ChildEntry kEcho{"Floor.echo", echo};
//
//   // Parent side: a Google Benchmark function.
//   void BM_Latency_Floor(benchmark::State& state) {
//     ipc::run(state, [&](std::size_t bytes) {           // bytes = state.range(0)
//       auto mapping = ipc::SharedMapping::create("floor", sizeof(Line));
//       auto& line = mapping.construct<Line>();
//       ipc::Link child{"Floor.echo", bytes, {mapping.fd()}};  // spawns the child
//       child.wait_ready();
//       child.go();
//       ipc::time_round_trips(state, [&](std::uint64_t seq) {
//         line.ping = seq;
//         ipc::spin_until(child, [&] { return line.pong == seq; });
//       });
//       child.stop();
//     });
//   }
//   BENCHMARK(BM_Latency_Floor)->Apply(ipc::latency_payloads);
//
// What the child gets: the payload size (self.bytes(), the Link's `bytes`),
// the file descriptors the Link was given (self.fd(0), ...: they stay open
// across the exec) and strings (self.arg(0), ...: names of queues, topics).
//
// Latency: the parent sends `seq`, the child answers with it, time_round_trips
// reports `one_way_ns` (round trip / 2). Throughput: the child streams
// seq = 1, 2, 3... as fast as the medium lets it, losslessly; the parent
// receives one message per iteration in time_stream (`msgs/s`), and hands the
// Link a drain (set_drain) so a producer blocked on a full queue can stop.
// Payloads: a zero-copy peer's message is an N-byte sample with the sequence
// number written into it (ipc::stamp / ipc::seq_of), nothing else touched; a
// copying peer moves a whole ipc::Payload of N bytes.
//
// Failure: every wait goes through spin_until, sleep_until or a Patience, so
// it sees a dead or failed child, or kPatience without progress: the parent
// throws PeerError, which run() turns into state.SkipWithError; a child
// throws (its message reaches the parent) or, asked to stop, ends via
// Stopped. A child is always reaped.
//
// Names: BM_Latency_<Peer>/<bytes> and BM_Throughput_<Peer>/<bytes>, which
// `prime bench` reads (tools/prime/bench/report.cpp): a new peer appears in
// its tables and plots under its own name.

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "child_process.hpp"
#include "shared_mapping.hpp"

namespace prime::bench::ipc {

using namespace std::chrono_literals;

// ---- payloads --------------------------------------------------------------

inline constexpr std::int64_t kLatencyPayloads[] = {64, 4 << 10, 64 << 10, 1 << 20, 4 << 20};
inline constexpr std::int64_t kThroughputPayloads[] = {64, 1 << 20};
inline constexpr std::int64_t kRoundTripPayloads[] = {64, 4 << 10, 64 << 10, 1 << 20};
// Messages a throughput stream may have in flight: the depth of its queue. A
// full queue makes the producer wait, so no message is ever lost.
inline constexpr std::size_t kStreamDepth = 256;

// For BENCHMARK(...)->Apply(...): the payload sizes, timed by the wall clock.
void latency_payloads(benchmark::internal::Benchmark* b);
void throughput_payloads(benchmark::internal::Benchmark* b);
void round_trip_payloads(benchmark::internal::Benchmark* b);

// ---- failure and stopping --------------------------------------------------

// The other process died, failed or stopped answering.
class PeerError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Thrown in a child when the parent asks it to stop; the child then exits 0.
// Not a std::exception, so a peer's `catch (const std::exception&)` lets it by.
struct Stopped {};

// How long a wait may see no progress before it gives up.
inline constexpr auto kPatience = 10s;
// Polls of a busy wait between two looks at the other process.
inline constexpr std::uint32_t kPollsPerCheck = 4096;

namespace detail {

// The page both processes of a Link map, besides whatever the peer shares.
struct Control {
  enum : std::uint32_t { kStarting, kReady, kFailed };  // child -> parent
  enum : std::uint32_t { kWait, kGo, kStop };           // parent -> child
  alignas(64) std::atomic<std::uint32_t> child{kStarting};
  alignas(64) std::atomic<std::uint32_t> parent{kWait};
  char error[1024] = {};
};

}  // namespace detail

// ---- the parent side -------------------------------------------------------

class Link {
 public:
  // Starts the child entry `entry` with payload size `bytes`, the file
  // descriptors `fds` (the child's fd(0), fd(1)...) and the strings `args`
  // (its arg(0)...). Throws if the child cannot be started.
  Link(std::string entry, std::size_t bytes, std::vector<int> fds = {}, std::vector<std::string> args = {});
  Link(const Link&) = delete;
  Link& operator=(const Link&) = delete;
  // Without stop(): asks the child to stop, and kills it after a second.
  ~Link();

  // Waits until the child has called ready().
  void wait_ready();
  // Lets the child's ready() return.
  void go();
  // Throws PeerError if the child has ended or reported a failure.
  void check();
  // Asks the child to stop and waits for it to end. Throws PeerError if the
  // child failed or did not end within five seconds.
  void stop();
  // Gives stop() and the destructor something to do while they wait for the
  // child: a consumer's drain, so that a producer blocked on a full queue sees
  // the request to stop, also when the benchmark fails half-way.
  void set_drain(std::function<void()> drain) { drain_ = std::move(drain); }

  [[nodiscard]] const std::string& entry() const noexcept { return entry_; }

 private:
  [[noreturn]] void fail(const std::string& what);

  std::string entry_;
  SharedMapping control_mapping_;
  detail::Control& control_;
  std::optional<cpu_set_t> unpinned_;
  std::function<void()> drain_;
  std::optional<ChildProcess> process_;
};

// The children of one benchmark run beyond one pair. Each Link pins this
// process on start and restores the affinity it found when it ends, so they
// end in the reverse order of their start: the first restores what was there
// before any (a vector would end them first to last).
class Links {
 public:
  Links() = default;
  Links(const Links&) = delete;
  Links& operator=(const Links&) = delete;
  ~Links() {
    while (!links_.empty()) links_.pop_back();
  }

  Link& start(std::string entry, std::size_t bytes, std::vector<int> fds = {}, std::vector<std::string> args = {}) {
    links_.push_back(std::make_unique<Link>(std::move(entry), bytes, std::move(fds), std::move(args)));
    return *links_.back();
  }
  void wait_ready() {
    for (auto& l : links_) l->wait_ready();
  }
  void go() {
    for (auto& l : links_) l->go();
  }
  void stop() {
    for (auto it = links_.rbegin(); it != links_.rend(); ++it) (*it)->stop();
  }
  // A Side for spin_until and sleep_until: throws if any child has died or failed.
  void check() {
    for (auto& l : links_) l->check();
  }

 private:
  std::vector<std::unique_ptr<Link>> links_;
};

// Runs one benchmark's parent side, `body(payload bytes)`, and turns whatever
// it throws into state.SkipWithError. The Link inside is stopped and reaped
// on every path.
template <class Body>
void run(benchmark::State& state, Body body) {
  try {
    body(static_cast<std::size_t>(state.range(0)));
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
  }
}

// ---- the child side --------------------------------------------------------

class Child {
 public:
  [[nodiscard]] std::size_t bytes() const noexcept { return bytes_; }
  [[nodiscard]] int fd(std::size_t i) const { return fds_.at(i); }
  [[nodiscard]] const std::string& arg(std::size_t i) const { return args_.at(i); }

  // Tells the parent this side is set up, then waits for go(). Throws Stopped
  // if the parent stops instead.
  void ready();
  // Throws Stopped once the parent has asked this child to stop.
  void check() const {
    if (control_.parent.load(std::memory_order_relaxed) == detail::Control::kStop) throw Stopped{};
  }

 private:
  friend int child_main(int argc, char** argv);
  Child(detail::Control& control, std::size_t bytes, std::vector<int> fds, std::vector<std::string> args)
      : control_{control}, bytes_{bytes}, fds_{std::move(fds)}, args_{std::move(args)} {}

  detail::Control& control_;
  std::size_t bytes_;
  std::vector<int> fds_;
  std::vector<std::string> args_;
};

// Registers a child entry under `name`; define one as a namespace-scope const.
class ChildEntry {
 public:
  ChildEntry(std::string_view name, void (*main)(Child&));
};

// The whole main() of a benchmark binary that uses this harness: a child
// command runs its child's whole life; otherwise the parent's own options
// (--ipc_no_pin) are taken from argv and Google Benchmark runs the rest. If
// the process has not ended 10 s after that (a library's static destructor
// waiting on a helper process that hangs), it says so and ends anyway, with
// status 3.
int benchmark_main(int argc, char** argv);

// The CPU affinity this process started with (for helpers like RouDi).
[[nodiscard]] cpu_set_t startup_cpus();

// ---- waiting ---------------------------------------------------------------

// Either side of a Link: check() throws if waiting on should end.
template <class S>
concept Side = requires(S& side) { side.check(); };

// Call idle() whenever a wait made no progress (a poll missed, a blocking
// call timed out): it throws when the other side is gone or asked to stop,
// or after kPatience without progress.
template <Side S>
class Patience {
 public:
  explicit Patience(S& side) : side_{side} {}

  void idle() {
    side_.check();
    const auto now = std::chrono::steady_clock::now();
    if (since_ == kNever) since_ = now;
    else if (now - since_ > kPatience) throw PeerError{"no answer from the other process for 10 s"};
  }

 private:
  static constexpr std::chrono::steady_clock::time_point kNever{};

  S& side_;
  std::chrono::steady_clock::time_point since_ = kNever;  // the first idle()
};

// Busy-waits until done(), looking at the other process every kPollsPerCheck
// polls; the fast path is nothing but done().
template <Side S, std::predicate Done>
void spin_until(S& side, Done done) {
  Patience<S> patience{side};
  for (std::uint32_t polls = 1; !done(); ++polls)
    if (polls % kPollsPerCheck == 0) patience.idle();
}

// Sleeps between polls of done(): for setup, never for what is timed.
template <Side S, std::predicate Done>
void sleep_until(S& side, Done done) {
  Patience<S> patience{side};
  while (!done()) {
    patience.idle();
    std::this_thread::sleep_for(1ms);
  }
}

// For a wait that finds the connection gone (EOF, EPIPE, ECONNRESET): the
// other process may be dying, or this child may be about to be stopped, so
// look at it for a moment before blaming the connection.
template <Side S>
[[noreturn]] void hung_up(S& side, const std::string& what) {
  for (int i = 0; i < 100; ++i) {
    side.check();
    std::this_thread::sleep_for(1ms);
  }
  throw PeerError{what + ": the other process hung up"};
}

// ---- timing ----------------------------------------------------------------

// Untimed, before the timed iterations: the first messages of a run pay for
// page faults and cold caches.
inline constexpr int kWarmUpMessages = 10;

// Reports the distribution of `samples` (nanoseconds, reordered) divided by
// `divisor` as the counters p50_ns, p90_ns, p99_ns, p999_ns and max_ns.
void report_percentiles(benchmark::State& state, std::vector<std::uint32_t>& samples, double divisor);

// Times the benchmark's iterations, one round trip each, and reports
// `one_way_ns`, half a round trip on average, and the percentiles of the
// one-way time from every round trip's own timing (one clock read per
// round trip: the end of one is the start of the next). round_trip(seq)
// sends `seq` and returns once the answer carrying it is back. A few run
// untimed first.
template <class RoundTrip>
void time_round_trips(benchmark::State& state, RoundTrip round_trip) {
  std::uint64_t seq = 0;
  for (int i = 0; i < kWarmUpMessages; ++i) round_trip(++seq);
  std::vector<std::uint32_t> samples;
  samples.reserve(static_cast<std::size_t>(state.max_iterations));
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  for (auto _ : state) {
    round_trip(++seq);
    const auto now = std::chrono::steady_clock::now();
    samples.push_back(static_cast<std::uint32_t>(std::min<std::int64_t>((now - last).count(), UINT32_MAX)));
    last = now;
  }
  const std::chrono::duration<double, std::nano> elapsed = last - start;
  state.counters["one_way_ns"] = elapsed.count() / (2.0 * static_cast<double>(state.iterations()));
  report_percentiles(state, samples, 2.0);
}

// Times the benchmark's iterations, one message received each, and reports
// `msgs/s`. receive(seq) returns once the message carrying `seq` is in; it
// throws PeerError on any other number, so a stream that loses or reorders a
// message fails. A few messages are received untimed first.
template <class Receive>
void time_stream(benchmark::State& state, Receive receive) {
  std::uint64_t seq = 0;
  for (int i = 0; i < kWarmUpMessages; ++i) receive(++seq);
  const auto start = std::chrono::steady_clock::now();
  for (auto _ : state) receive(++seq);
  const std::chrono::duration<double> elapsed = std::chrono::steady_clock::now() - start;
  state.counters["msgs/s"] = static_cast<double>(state.iterations()) / elapsed.count();
  state.SetItemsProcessed(state.iterations());
}

// Times the benchmark's iterations, each sending one message or one batch,
// and reports `msgs/s`, counting messages. send(seq) sends seq, seq + 1...
// and returns how many it sent. A few messages are sent untimed first.
template <class Send>
void time_sending(benchmark::State& state, Send send) {
  std::uint64_t seq = 1;
  while (seq <= kWarmUpMessages) seq += send(seq);
  std::uint64_t sent = 0;
  const auto start = std::chrono::steady_clock::now();
  for (auto _ : state) {
    const std::uint64_t n = send(seq);
    seq += n;
    sent += n;
  }
  const std::chrono::duration<double> elapsed = std::chrono::steady_clock::now() - start;
  state.counters["msgs/s"] = static_cast<double>(sent) / elapsed.count();
  state.SetItemsProcessed(static_cast<std::int64_t>(sent));
}

// The PeerError for a stream that delivered `got` where `expected` was due.
[[nodiscard]] PeerError out_of_sequence(std::uint64_t expected, std::uint64_t got);

}  // namespace prime::bench::ipc
