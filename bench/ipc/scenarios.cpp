// Scenarios beyond one pair, for Prime's Shm medium: more processes than two,
// or a workload that is not a ping-pong.
//
//   FanOut/<n>     the parent publishes a 64 B sample to n subscriber
//                  processes (1, 2, 4); each acknowledges on its own cache
//                  line of a shared mapping. One message at a time, each
//                  50 µs after the last acknowledgement of the one before: a
//                  sample is the time from the publish until the parent sees
//                  the last acknowledgement (last_ns, and its percentiles),
//                  and publish_ns is what the publish itself cost the
//                  publisher (waking the subscribers included).
//   FanOutThroughput/<n>
//                  the parent publishes 64 B samples back to back, one at a
//                  time, on a `block` topic to n reader processes (1, 2, 4),
//                  which take every sample available in one read_some:
//                  msgs/s is the rate at which every reader gets every
//                  message, losslessly.
//   FanOutPublish/<n>
//                  the same on a drop_oldest topic, so the publisher never
//                  waits: publish_ns is what one loan + publish costs it while
//                  n readers take samples.
//   Loaded/64      Latency_Shm/64 (busy-polling on both sides) with a third
//                  process burning 100 % of the publisher's CPU at the same
//                  priority: the same counters, for the tail they get. The
//                  scheduler shares that CPU by time slices, so most round
//                  trips are untouched; the mean, p99.9 and max show the
//                  slices the publisher waits out.
//   Sleeping/<hz>  a sensor: the parent publishes at 10, 100 or 1000 Hz on a
//                  schedule; the subscriber sleeps in the blocking read at
//                  once (spin 0) and records, per message, receive time
//                  minus the publish time the message carries (steady_clock,
//                  one clock for every process): the wake-up latency. And
//                  cpu_ns_per_msg, the subscriber process's CPU time per
//                  message.
//
// CPUs: the harness pins the parent to the first CPU and every child to the
// second, so on the 2-CPU machine these run on, the n subscribers of FanOut
// share one CPU. That is why they sleep at once (spin 0) rather than
// busy-poll: a reader spinning on a shared CPU holds it from the sibling that
// has the next message to take, and the numbers would measure the spin
// budget and the scheduler's time slice, not the medium. So FanOut is a
// fan-out of futex wake-ups: publish_ns includes waking every sleeper, and
// last_ns the n wake-ups, run one after the other on the subscribers' CPU.

#include <sched.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <system_error>
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
using Clock = std::chrono::steady_clock;

constexpr std::size_t kBytes = 64;

// ---- shared helpers --------------------------------------------------------

template <class T>
T parse(const std::string& text) {
  T value{};
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc{} || end != text.data() + text.size())
    throw std::invalid_argument{"scenarios: bad number '" + text + "'"};
  return value;
}

std::uint32_t clamp_ns(Clock::duration d) {
  return static_cast<std::uint32_t>(std::clamp<std::int64_t>(d.count(), 0, UINT32_MAX));
}

double mean(std::uint64_t total_ns, std::uint64_t count) {
  return count == 0 ? 0.0 : static_cast<double>(total_ns) / static_cast<double>(count);
}

// Loans a sample, writes `seq` into it (and whatever `fill` adds) and publishes it.
template <class Fill>
void send(shm::Publisher<shm::Bytes>& publisher, std::uint64_t seq, Fill fill) {
  auto sample = publisher.loan(kBytes);
  if (!sample) throw ipc::PeerError{"shm: " + sample.error().describe()};
  ipc::stamp(sample->bytes().data(), seq);
  fill(sample->bytes().data());
  std::move(*sample).publish();
}
void send(shm::Publisher<shm::Bytes>& publisher, std::uint64_t seq) {
  send(publisher, seq, [](std::byte*) {});
}

using Subscriber = prime::Reader<shm::View<shm::Bytes>>;

// Takes `seq` if it is in.
bool try_take(Subscriber& reader, std::uint64_t seq) {
  auto sample = reader.try_read();
  if (!sample) return false;
  const auto got = ipc::seq_of(sample->value.bytes().data());
  if (got != seq) throw ipc::out_of_sequence(seq, got);
  return true;
}

// Waits for `seq` asleep in the blocking read, looking at the other process
// between reads of at most `slice`; `took` sees the sample before it is
// released.
template <ipc::Side S, class Took>
void sleep_and_take(S& side, Subscriber& reader, std::uint64_t seq, Clock::duration slice, Took took) {
  ipc::Patience<S> patience{side};
  while (true) {
    if (auto sample = reader.read_for(slice)) {
      const auto* bytes = sample->value.bytes().data();
      const auto got = ipc::seq_of(bytes);
      if (got != seq) throw ipc::out_of_sequence(seq, got);
      took(bytes);
      return;
    }
    patience.idle();
  }
}

// ---- FanOut ----------------------------------------------------------------

constexpr std::size_t kMaxFanOut = 4;
// Between two messages: far longer than a subscriber takes from its
// acknowledgement back into its futex wait (a few µs), so each message finds
// every subscriber asleep, as a sensor's subscribers are between samples.
// Back to back, a subscriber would often find the next message before it
// slept, and n = 1 would be part busy-wait, part wake-up.
constexpr auto kFanOutSettle = 50us;

// One cache line per subscriber, so that the acknowledgements do not share one.
struct alignas(64) Ack {
  std::atomic<std::uint64_t> seq{0};
};
struct Acks {
  Ack of[kMaxFanOut];
};
static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "atomics across processes must be lock-free");

// Whether each of the first `readers` has acknowledged `seq` (or a later one).
bool all_have(const Acks& acks, std::size_t readers, std::uint64_t seq) {
  for (std::size_t i = 0; i < readers; ++i)
    if (acks.of[i].seq.load(std::memory_order_acquire) < seq) return false;
  return true;
}

shm::TopicQos fan_out_qos() { return {.capacity = 4, .max_message_size = kBytes, .max_subscribers = kMaxFanOut}; }

// Child: subscriber number arg(1) of topic "fan" in domain arg(0).
void fan_out_subscriber(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  auto fan = core.subscribe<shm::Bytes>("fan", {.spin = 0us}, fan_out_qos()).subscribe();
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(Acks));
  auto& ack = mapping.as<Acks>().of[parse<std::size_t>(self.arg(1))];
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    sleep_and_take(self, fan, seq, 50ms, [](const std::byte*) {});
    ack.seq.store(seq, std::memory_order_release);
  }
}
const ipc::ChildEntry kFanOutSubscriber{"Scenario.fan_out_subscriber", fan_out_subscriber};

void BM_FanOut_Shm(benchmark::State& state) {
  ipc::run(state, [&](std::size_t subscribers) {
    if (subscribers == 0 || subscribers > kMaxFanOut) throw std::invalid_argument{"FanOut: 1 to 4 subscribers"};
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto fan = core.publisher<shm::Bytes>("fan", fan_out_qos());
    auto mapping = ipc::SharedMapping::create("prime-ipc-acks", sizeof(Acks));
    auto& acks = mapping.construct<Acks>();
    ipc::Links children;
    for (std::size_t i = 0; i < subscribers; ++i)
      children.start("Scenario.fan_out_subscriber", kBytes, {mapping.fd()}, {domain, std::to_string(i)});
    children.wait_ready();
    children.go();

    std::uint64_t seq = 0;
    for (int i = 0; i < ipc::kWarmUpMessages; ++i) {
      send(fan, ++seq);
      ipc::spin_until(children, [&] { return all_have(acks, subscribers, seq); });
    }
    std::vector<std::uint32_t> samples;
    samples.reserve(static_cast<std::size_t>(state.max_iterations));
    std::uint64_t publish_total = 0;
    std::uint64_t last_total = 0;
    for (auto _ : state) {
      // Untimed: every subscriber back asleep before the next message.
      const auto settled = Clock::now() + kFanOutSettle;
      ipc::spin_until(children, [&] { return Clock::now() >= settled; });
      ++seq;
      const auto start = Clock::now();
      send(fan, seq);
      const auto published = Clock::now();
      ipc::spin_until(children, [&] { return all_have(acks, subscribers, seq); });
      const auto last = Clock::now();
      publish_total += clamp_ns(published - start);
      samples.push_back(clamp_ns(last - start));
      last_total += samples.back();
      state.SetIterationTime(std::chrono::duration<double>(last - start).count());
    }
    const auto n = static_cast<std::uint64_t>(state.iterations());
    state.counters["last_ns"] = mean(last_total, n);
    state.counters["publish_ns"] = mean(publish_total, n);
    ipc::report_percentiles(state, samples, 1.0);
    children.stop();
  });
}
// The time column is last_ns: the settling pauses are not timed.
BENCHMARK(BM_FanOut_Shm)->Arg(1)->Arg(2)->Arg(4)->UseManualTime();

// ---- FanOutThroughput, FanOutPublish -----------------------------------------

// A topic as deep as the two-process throughput stream's, with room for every
// reader to hold a batch: `block` (lossless) or `drop_oldest` (the publisher
// never waits).
constexpr std::size_t kReadBatch = 32;
shm::TopicQos fan_out_stream_qos(prime::Overflow overflow) {
  return {.capacity = ipc::kStreamDepth, .max_message_size = kBytes, .overflow = overflow,
          .block_timeout = 10s, .max_subscribers = kMaxFanOut, .max_held = kReadBatch};
}
prime::Overflow overflow_named(const std::string& name) {
  return name == "block" ? prime::Overflow::block : prime::Overflow::drop_oldest;
}
// Messages per timed iteration.
constexpr std::uint64_t kFanOutRound = 4096;

// Child: reader number arg(1) of topic "stream" in domain arg(0), whose
// overflow policy is arg(2). Takes every sample available (up to kReadBatch)
// in one read_some, checks that the sequence only goes up (and, lossless,
// that nothing is missing), and acknowledges the last one it took on its own
// line.
void fan_out_reader(ipc::Child& self) {
  const auto overflow = overflow_named(self.arg(2));
  shm::Core core{self.arg(0)};
  auto in = core.subscribe<shm::Bytes>("stream", {}, fan_out_stream_qos(overflow)).subscribe();
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(Acks));
  auto& ack = mapping.as<Acks>().of[parse<std::size_t>(self.arg(1))];
  std::vector<prime::Sample<shm::View<shm::Bytes>>> taken;
  taken.reserve(kReadBatch);
  self.ready();
  for (std::uint64_t last = 0;;) {
    taken.clear();
    if (!in.read_some(taken, kReadBatch, prime::Clock::now() + 50ms)) {
      self.check();
      continue;
    }
    for (const auto& sample : taken) {
      const auto seq = ipc::seq_of(sample.value.bytes().data());
      if (seq <= last || (overflow == prime::Overflow::block && seq != last + 1)) throw ipc::out_of_sequence(last + 1, seq);
      last = seq;
    }
    ack.seq.store(last, std::memory_order_release);
  }
}
const ipc::ChildEntry kFanOutReader{"Scenario.fan_out_reader", fan_out_reader};

// The parent publishes on "stream" to `readers` reader processes; once every
// reader has the first sample, `timed(children, publisher, have, seq)` runs
// the timed iterations, where have(s) tells whether every reader has
// acknowledged s and `seq` is the last sequence published.
template <class Timed>
void fan_out_stream(std::size_t readers, prime::Overflow overflow, Timed timed) {
  if (readers == 0 || readers > kMaxFanOut) throw std::invalid_argument{"fan-out: 1 to 4 readers"};
  const auto domain = ipc::new_shm_domain();
  shm::Core core{domain};
  auto stream = core.publisher<shm::Bytes>("stream", fan_out_stream_qos(overflow));
  auto mapping = ipc::SharedMapping::create("prime-ipc-acks", sizeof(Acks));
  auto& acks = mapping.construct<Acks>();
  ipc::Links children;
  const std::string policy = overflow == prime::Overflow::block ? "block" : "drop_oldest";
  for (std::size_t i = 0; i < readers; ++i)
    children.start("Scenario.fan_out_reader", kBytes, {mapping.fd()}, {domain, std::to_string(i), policy});
  children.wait_ready();
  children.go();
  // Every reader has read something: all of them are in the topic's ring.
  auto have = [&](std::uint64_t seq) { return all_have(acks, readers, seq); };
  std::uint64_t seq = 0;
  send(stream, ++seq);
  ipc::spin_until(children, [&] { return have(seq); });
  timed(children, stream, have, seq);
  children.stop();
}

// Lossless: msgs/s is the rate at which every reader gets every message. The
// readers share the second CPU, so with n > 1 they take turns on it.
void BM_FanOutThroughput_Shm(benchmark::State& state) {
  ipc::run(state, [&](std::size_t readers) {
    fan_out_stream(readers, prime::Overflow::block, [&](ipc::Links& children, auto& stream, auto have, std::uint64_t& seq) {
      auto round = [&] {
        for (std::uint64_t i = 0; i < kFanOutRound; ++i) send(stream, ++seq);
        ipc::spin_until(children, [&] { return have(seq); });
      };
      round();  // untimed: page faults, cold caches
      const auto start = Clock::now();
      for (auto _ : state) round();
      const std::chrono::duration<double> elapsed = Clock::now() - start;
      state.counters["msgs/s"] = static_cast<double>(state.iterations() * kFanOutRound) / elapsed.count();
      state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(kFanOutRound));
    });
  });
}
BENCHMARK(BM_FanOutThroughput_Shm)->Arg(1)->Arg(2)->Arg(4)->UseRealTime();

// What a publish costs the publisher with n readers taking samples meanwhile:
// drop_oldest, so it never waits for them, and publish_ns is its time per
// loan + publish, back to back (it has the first CPU to itself). What grows
// with n is the cache lines the readers touch and the publisher then takes
// back.
void BM_FanOutPublish_Shm(benchmark::State& state) {
  ipc::run(state, [&](std::size_t readers) {
    fan_out_stream(readers, prime::Overflow::drop_oldest, [&](ipc::Links& children, auto& stream, auto, std::uint64_t& seq) {
      for (std::uint64_t i = 0; i < kFanOutRound; ++i) send(stream, ++seq);  // untimed
      const auto start = Clock::now();
      for (auto _ : state) {
        for (std::uint64_t i = 0; i < kFanOutRound; ++i) send(stream, ++seq);
        children.check();
      }
      const std::chrono::duration<double, std::nano> elapsed = Clock::now() - start;
      state.counters["publish_ns"] = elapsed.count() / static_cast<double>(state.iterations() * kFanOutRound);
    });
  });
}
BENCHMARK(BM_FanOutPublish_Shm)->Arg(1)->Arg(2)->Arg(4)->UseRealTime();

// ---- Loaded ----------------------------------------------------------------

shm::TopicQos latency_qos() { return {.capacity = 4, .max_message_size = kBytes}; }

// Child: answers each sample on "ping" with one on "pong", busy-polling, as
// Latency_Shm's child does (its own copy, so that the topics' QoS, which
// both ends must agree on, is written in this file only).
void echo(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  auto ping = core.subscribe<shm::Bytes>("ping", {}, latency_qos()).subscribe();
  auto pong = core.publisher<shm::Bytes>("pong", latency_qos());
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    ipc::spin_until(self, [&] { return try_take(ping, seq); });
    send(pong, seq);
  }
}
const ipc::ChildEntry kEcho{"Scenario.echo", echo};

// Child: moves itself to the CPUs named in arg(0) ("0", "0,1") and burns
// them until stopped.
void burn(ipc::Child& self) {
  cpu_set_t cpus;
  CPU_ZERO(&cpus);
  const std::string& list = self.arg(0);
  for (std::size_t at = 0; at < list.size();) {
    const auto comma = std::min(list.find(',', at), list.size());
    CPU_SET(parse<int>(list.substr(at, comma - at)), &cpus);
    at = comma + 1;
  }
  if (::sched_setaffinity(0, sizeof cpus, &cpus) != 0)
    throw std::system_error{errno, std::generic_category(), "sched_setaffinity " + list};
  self.ready();
  std::uint64_t spins = 0;
  for (;;) {
    self.check();  // one relaxed load: the loop stays a loop of loads and adds
    benchmark::DoNotOptimize(++spins);
  }
}
const ipc::ChildEntry kBurn{"Scenario.burn", burn};

// The CPUs this process may run on now, as "0,1".
std::string current_cpus() {
  cpu_set_t cpus;
  if (::sched_getaffinity(0, sizeof cpus, &cpus) != 0) throw std::system_error{errno, std::generic_category(), "sched_getaffinity"};
  std::string list;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu)
    if (CPU_ISSET(cpu, &cpus)) list += (list.empty() ? "" : ",") + std::to_string(cpu);
  return list;
}

void BM_Loaded_Shm(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    if (bytes != kBytes) throw std::invalid_argument{"Loaded: 64 B only"};
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto ping = core.publisher<shm::Bytes>("ping", latency_qos());
    auto pong = core.subscribe<shm::Bytes>("pong", {}, latency_qos()).subscribe();
    ipc::Links children;
    children.start("Scenario.echo", kBytes, {}, {domain});
    // Started after the echo, whose Link has pinned this process: the burner
    // goes where the publisher now runs.
    children.start("Scenario.burn", kBytes, {}, {current_cpus()});
    children.wait_ready();
    children.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      send(ping, seq);
      ipc::spin_until(children, [&] { return try_take(pong, seq); });
    });
    children.stop();
  });
}
BENCHMARK(BM_Loaded_Shm)->Arg(64)->UseRealTime();

// ---- Sleeping --------------------------------------------------------------

// Messages per run at each rate: at most 2 s of schedule each, and a few
// more before it, untimed and back to back, for the page faults.
constexpr std::size_t kSensorMessagesMax = 1000;
constexpr std::uint64_t kSensorWarmUp = 3;
std::size_t sensor_messages(std::int64_t hz) { return hz <= 10 ? 20 : hz <= 100 ? 200 : kSensorMessagesMax; }

struct SensorReport {
  alignas(64) std::atomic<std::uint64_t> received{0};  // last seq taken; the rest is written before it
  std::uint64_t cpu_ns = 0;                             // the subscriber's CPU time over the timed messages
  std::uint32_t latency_ns[kSensorMessagesMax] = {};
};

shm::TopicQos sensor_qos() {
  // Deep enough that a subscriber held up for a while at 1 kHz loses nothing
  // (a loss fails the run as out of sequence).
  return {.capacity = 256, .max_message_size = kBytes};
}

std::uint64_t process_cpu_ns() {
  timespec t{};
  if (::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t) != 0)
    throw std::system_error{errno, std::generic_category(), "clock_gettime"};
  return static_cast<std::uint64_t>(t.tv_sec) * 1'000'000'000u + static_cast<std::uint64_t>(t.tv_nsec);
}

// The publish time a sensor message carries after its sequence number.
void write_sent(std::byte* message, Clock::time_point sent) {
  const std::int64_t ns = sent.time_since_epoch().count();
  std::memcpy(message + sizeof(std::uint64_t), &ns, sizeof ns);
}
Clock::time_point read_sent(const std::byte* message) {
  std::int64_t ns;
  std::memcpy(&ns, message + sizeof(std::uint64_t), sizeof ns);
  return Clock::time_point{Clock::duration{ns}};
}

// Child: takes arg(1) timed messages of topic "sensor" in domain arg(0),
// asleep in the read between them, then waits to be stopped.
void sensor_subscriber(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  auto sensor = core.subscribe<shm::Bytes>("sensor", {.spin = 0us}, sensor_qos()).subscribe();
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(SensorReport));
  auto& report = mapping.as<SensorReport>();
  const auto messages = parse<std::size_t>(self.arg(1));
  if (messages > kSensorMessagesMax) throw std::invalid_argument{"sensor_subscriber: too many messages"};
  self.ready();
  std::uint64_t cpu_start = 0;
  const std::uint64_t last = kSensorWarmUp + messages;
  for (std::uint64_t seq = 1; seq <= last; ++seq) {
    // Read slices far longer than the slowest period: a sleeping reader
    // wakes for a message, not for a timeout.
    sleep_and_take(self, sensor, seq, 1s, [&](const std::byte* message) {
      const auto received = Clock::now();
      if (seq > kSensorWarmUp) report.latency_ns[seq - kSensorWarmUp - 1] = clamp_ns(received - read_sent(message));
    });
    if (seq == kSensorWarmUp) cpu_start = process_cpu_ns();
    if (seq == last) report.cpu_ns = process_cpu_ns() - cpu_start;
    report.received.store(seq, std::memory_order_release);
  }
  for (;;) {  // until stopped (or killed with the parent)
    self.check();
    std::this_thread::sleep_for(1ms);
  }
}
const ipc::ChildEntry kSensorSubscriber{"Scenario.sensor_subscriber", sensor_subscriber};

void BM_Sleeping_Shm(benchmark::State& state) {
  ipc::run(state, [&](std::size_t hz) {
    const auto messages = sensor_messages(static_cast<std::int64_t>(hz));
    const auto period = std::chrono::duration_cast<Clock::duration>(1s) / static_cast<Clock::rep>(hz);
    const auto domain = ipc::new_shm_domain();
    shm::Core core{domain};
    auto sensor = core.publisher<shm::Bytes>("sensor", sensor_qos());
    auto mapping = ipc::SharedMapping::create("prime-ipc-sensor", sizeof(SensorReport));
    auto& report = mapping.construct<SensorReport>();
    ipc::Links children;
    auto& child = children.start("Scenario.sensor_subscriber", kBytes, {mapping.fd()}, {domain, std::to_string(messages)});
    children.wait_ready();
    children.go();
    auto received = [&](std::uint64_t seq) { return report.received.load(std::memory_order_acquire) >= seq; };

    std::uint64_t seq = 0;
    for (std::uint64_t i = 0; i < kSensorWarmUp; ++i) {
      send(sensor, ++seq, [](std::byte* message) { write_sent(message, Clock::now()); });
      ipc::spin_until(child, [&] { return received(seq); });
    }
    for (auto _ : state) {
      // The schedule is the workload: this process sleeps until each
      // message is due, the subscriber until it arrives.
      const auto start = Clock::now() + period;
      for (std::size_t i = 0; i < messages; ++i) {
        std::this_thread::sleep_until(start + period * static_cast<Clock::rep>(i));
        child.check();
        send(sensor, ++seq, [](std::byte* message) { write_sent(message, Clock::now()); });
      }
      ipc::sleep_until(child, [&] { return received(seq); });
      std::vector<std::uint32_t> samples(report.latency_ns, report.latency_ns + messages);
      std::uint64_t total = 0;
      for (const auto s : samples) total += s;
      const double wake_ns = mean(total, messages);
      state.SetIterationTime(wake_ns * 1e-9);
      state.counters["wake_ns"] = wake_ns;
      state.counters["cpu_ns_per_msg"] = mean(report.cpu_ns, messages);
      state.counters["msgs"] = static_cast<double>(messages);
      ipc::report_percentiles(state, samples, 1.0);
    }
    children.stop();
  });
}
// One run of a fixed schedule each; the time column is the mean wake-up latency.
BENCHMARK(BM_Sleeping_Shm)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1)->UseManualTime();

}  // namespace
