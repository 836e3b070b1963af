// Loop: a 1 kHz control loop that publishes a small stamped sample every
// tick to a subscriber in another process, both at the same real-time
// priority; the same loop written by hand for iceoryx; and cyclictest, the
// floor, at the same period and priority on the same CPU (issue 44).
// BM_Loop/load:0 measures them on the machine as it is, BM_Loop/load:1
// under load: stress-ng with one CPU hog per CPU, started before the first
// tick and stopped after the last.
//
//   publisher (CPU 0, SCHED_FIFO 80)           subscriber (CPU 1, SCHED_FIFO 80)
//   every 1 ms: lateness = now - tick time     asleep in the read
//               loan, write {seq},
//               publish stamped now ─────────► e2e = now - stamp
//
//   shm         prime::every on a shm::Core, with LoopOptions::realtime; the
//               subscriber sleeps in Reader::read_for (Shm's default spin,
//               then the futex).
//   iceoryx     the same loop written the classic way: a thread that sleeps
//               in clock_nanosleep(TIMER_ABSTIME) to each tick, loans a
//               chunk, writes {seq, stamp} and publishes it; the subscriber
//               sleeps in a WaitSet. RouDi as the Iceoryx peer starts it
//               (iceoryx_runtime.hpp).
//   cyclictest  cyclictest -m -t1 -d 0 -a <CPU 0> -p 80 -i 1000 -l <ticks>
//               -N -v: every tick's lateness, in nanoseconds.
//
// In slices, taken in turn: a shared machine's state moves within seconds,
// so each of the three runs a slice of 1000 ticks (1 s), then the next,
// round after round (each round starting one further on), and each one's
// figures pool its slices: all three are measured across the same stretch
// of the machine's state, the way `prime bench` takes its rounds.
//
// Lateness is what cyclictest measures: from the time a tick was due to
// the moment the loop's code runs. End to end (e2e) is from the stamp, the
// clock read once the sample is written into its loan, just before it is
// published, to the subscriber holding the sample. All three skip, not run
// in a burst, the ticks a late one let pass (Missed::skip, cyclictest's own
// catch-up). The first kWarmUpTicks ticks of every slice are not counted.
//
// Each asks for the same scheduling on every side. Where the machine
// refuses it, shm and iceoryx run at normal priority and say so (priority
// 0, the reason in the label); cyclictest runs at a real-time priority or
// not at all, and is then "not run" with its own message, as is any of the
// three whose program or RouDi could not start. As cyclictest does, the run
// locks its memory (mlockall) and holds /dev/cpu_dma_latency at 0, where the
// machine allows.
//
// Counters, per <who> of shm, iceoryx, cyclictest that ran:
// <who>_lateness_{p50,p99,p999,max}_ns, <who>_e2e_..._ns (not cyclictest),
// <who>_ticks (lateness samples), <who>_received (e2e samples), <who>_lost
// (samples the subscriber never saw), <who>_priority (the SCHED_FIFO
// priority every side got; 0: normal), <who>_busy (the share of the
// machine's CPU time busy during its slices: others' work too, on a shared
// machine); and slices, load, memory_locked, dma_latency. The label says,
// per who, "<Who>: <how it ran>" or "<Who>: not run: <why>", joined by " | ".
//
// Environment: PRIME_LOOP_SECONDS (ticks each of the three counts, in
// seconds at 1 kHz: 10; `prime bench --quick` sets 0.5), PRIME_LOOP_PRIORITY
// (80).

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "harness.hpp"
#include "iceoryx_posh/popo/untyped_publisher.hpp"
#include "iceoryx_posh/popo/untyped_subscriber.hpp"
#include "iceoryx_posh/popo/wait_set.hpp"
#include "iceoryx_runtime.hpp"
#include "memory_file.hpp"
#include "shm_domain.hpp"
#include "prime/shm.hpp"
#include "prime/topology/loop.hpp"
#include "prime/topology/realtime.hpp"

namespace {

namespace ipc = prime::bench::ipc;
namespace shm = prime::shm;
using namespace std::chrono_literals;
using Clock = prime::Clock;

constexpr Clock::duration kPeriod = 1ms;
constexpr std::uint64_t kWarmUpTicks = 100;  // of every slice, not counted
constexpr std::uint64_t kSliceTicks = 1000;  // counted per slice (fewer in a short run)

// ---- the run's setup -------------------------------------------------------

template <class T>
T parse(std::string_view text, const char* what) {
  T value{};
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc{} || end != text.data() + text.size())
    throw std::invalid_argument{std::string{"loop: bad "} + what + " '" + std::string{text} + "'"};
  return value;
}

struct Setup {
  std::uint64_t ticks = 10'000;  // counted by each of the three, after the warm-ups
  int priority = 80;             // SCHED_FIFO, asked of every side
  int loop_cpu = -1;             // the publishers' and cyclictest's CPU; -1: any

  [[nodiscard]] std::uint64_t slices() const { return (ticks + kSliceTicks - 1) / kSliceTicks; }
  // Counted ticks of slice `i`: kSliceTicks, the last one what is left.
  [[nodiscard]] std::uint64_t slice_ticks(std::uint64_t i) const {
    return std::min(kSliceTicks, ticks - i * kSliceTicks);
  }
};

Setup setup() {
  Setup s;
  if (const char* seconds = std::getenv("PRIME_LOOP_SECONDS"); seconds && *seconds) {
    const double value = std::strtod(seconds, nullptr);
    if (!(value >= 0.01 && value <= 600)) throw std::invalid_argument{"loop: PRIME_LOOP_SECONDS must be in [0.01, 600]"};
    s.ticks = static_cast<std::uint64_t>(std::llround(value * 1000));
  }
  if (const char* priority = std::getenv("PRIME_LOOP_PRIORITY"); priority && *priority)
    s.priority = parse<int>(priority, "PRIME_LOOP_PRIORITY");
  // The harness pins this process to the first CPU it may use and the
  // subscribers to the second (harness.cpp): the loops run on the first.
  const cpu_set_t cpus = ipc::startup_cpus();
  int usable = 0;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu)
    if (CPU_ISSET(cpu, &cpus) && usable++ == 0) s.loop_cpu = cpu;
  if (usable < 2) s.loop_cpu = -1;
  return s;
}

std::uint32_t clamp_ns(Clock::duration d) {
  return static_cast<std::uint32_t>(std::clamp<std::int64_t>(std::chrono::nanoseconds{d}.count(), 0, UINT32_MAX));
}

// Reports p50, p99, p99.9 and max of `ns` (reordered) as <prefix>_p50_ns...
void report_spread(benchmark::State& state, const std::string& prefix, std::vector<std::uint32_t>& ns) {
  if (ns.empty()) return;
  auto at = [&](double q) {
    const auto k = std::min(ns.size() - 1, static_cast<std::size_t>(q * static_cast<double>(ns.size())));
    std::nth_element(ns.begin(), ns.begin() + static_cast<std::ptrdiff_t>(k), ns.end());
    return static_cast<double>(ns[k]);
  };
  // Rising quantiles: each nth_element leaves the part above k for the next.
  state.counters[prefix + "_p50_ns"] = at(0.5);
  state.counters[prefix + "_p99_ns"] = at(0.99);
  state.counters[prefix + "_p999_ns"] = at(0.999);
  state.counters[prefix + "_max_ns"] = static_cast<double>(*std::max_element(ns.begin(), ns.end()));
}

// The path of `program` on the PATH; throws naming the Debian package.
std::string find_program(const std::string& program, const std::string& package) {
  const char* path = std::getenv("PATH");
  const std::string all = path ? path : "";
  for (std::size_t from = 0; from <= all.size();) {
    const auto colon = std::min(all.find(':', from), all.size());
    const auto candidate = std::filesystem::path{all.substr(from, colon - from)} / program;
    if (::access(candidate.c_str(), X_OK) == 0) return candidate.string();
    from = colon + 1;
  }
  throw ipc::PeerError{program + " is not installed (Debian: " + package + ")"};
}

// The end of a program's output, on one line, for an error message.
std::string tail(std::string text, std::size_t bytes = 600) {
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  if (text.size() > bytes) text = "..." + text.substr(text.size() - bytes);
  std::replace(text.begin(), text.end(), '\n', ' ');
  return text;
}

// ---- what a real-time run holds, as cyclictest does --------------------------

// The process's memory locked (prime::lock_memory), unlocked again after
// the run, so the benchmarks this process runs next are not changed by it.
class MemoryLock {
 public:
  MemoryLock() : locked_{!prime::lock_memory(/*best_effort=*/true)} {}
  MemoryLock(const MemoryLock&) = delete;
  MemoryLock& operator=(const MemoryLock&) = delete;
  ~MemoryLock() {
    if (locked_) ::munlockall();
  }
  [[nodiscard]] bool locked() const noexcept { return locked_; }

 private:
  bool locked_;
};

// /dev/cpu_dma_latency held at 0 µs: no CPU of the machine enters a deep
// idle state while it is open (what cyclictest does by default).
class DmaLatency {
 public:
  DmaLatency() : fd_{::open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC)} {
    const std::int32_t zero = 0;
    if (fd_ && ::write(fd_.get(), &zero, sizeof zero) != sizeof zero) fd_ = ipc::UniqueFd{};
  }
  [[nodiscard]] bool held() const noexcept { return static_cast<bool>(fd_); }

 private:
  ipc::UniqueFd fd_;
};

// The machine's CPU time, from /proc/stat (every CPU's): how much of it was
// busy over a stretch is others' work, the load's and the run's own.
struct CpuTime {
  std::uint64_t total = 0;
  std::uint64_t idle = 0;  // idle and iowait

  static CpuTime now() {
    std::ifstream stat{"/proc/stat"};
    std::string cpu;
    CpuTime t;
    std::uint64_t field = 0;
    stat >> cpu;  // "cpu", then user nice system idle iowait irq softirq steal
    for (int i = 0; i < 8 && stat >> field; ++i) {
      t.total += field;
      if (i == 3 || i == 4) t.idle += field;
    }
    return t;
  }
  CpuTime& operator+=(const CpuTime& spent) {
    total += spent.total;
    idle += spent.idle;
    return *this;
  }
  [[nodiscard]] CpuTime since(const CpuTime& start) const { return {total - start.total, idle - start.idle}; }
  [[nodiscard]] double busy() const {
    return total == 0 ? 0.0 : 1.0 - static_cast<double>(idle) / static_cast<double>(total);
  }
};

// stress-ng with one CPU hog per CPU this process may use, for the load
// runs: started (and given a moment to spin up) by the constructor, stopped
// by the destructor; bounded by its own --timeout should both be missed.
class Load {
 public:
  Load(bool on, const Setup& s) {
    if (!on) return;
    const cpu_set_t cpus = ipc::startup_cpus();
    // Three loops' ticks and warm-ups, and room for their setup.
    const auto run = kPeriod * static_cast<Clock::rep>(3 * (s.ticks + s.slices() * kWarmUpTicks));
    const auto timeout = std::chrono::ceil<std::chrono::seconds>(run) + 30s;
    const auto program = find_program("stress-ng", "stress-ng");
    ipc::ChildProcess::Options options;
    options.cpus = cpus;  // not this process's pinned CPU: every one
    options.output_fd = output_.fd();
    process_.emplace(program,
                     std::vector<std::string>{program, "--cpu", std::to_string(CPU_COUNT(&cpus)), "--timeout",
                                              std::to_string(timeout.count()) + "s", "--quiet"},
                     options);
    std::this_thread::sleep_for(300ms);
    check();
  }
  Load(const Load&) = delete;
  Load& operator=(const Load&) = delete;
  ~Load() {
    if (!process_) return;
    process_->signal(SIGTERM);  // stress-ng stops its hogs and exits
    process_->wait_for(3s);     // then ~ChildProcess kills what is left
  }

  // Throws if the load has ended before the run did.
  void check() {
    if (!process_) return;
    if (const auto status = process_->poll())
      throw ipc::PeerError{"stress-ng " + ipc::ChildProcess::describe(*status) + " during the run: " + tail(output_.read())};
  }

 private:
  ipc::MemoryFile output_{"prime-loop-stress-ng.log"};
  std::optional<ipc::ChildProcess> process_;
};

// ---- scheduling --------------------------------------------------------------

prime::Realtime fifo(int priority, int cpu) {
  return {.policy = prime::Realtime::fifo, .priority = priority, .cpus = cpu >= 0 ? std::vector<int>{cpu} : std::vector<int>{}};
}

// Applies `realtime` to the calling thread, as a prime::every loop's
// thread applies it: the reason when the system refuses.
std::optional<std::string> take_realtime(const prime::Realtime& realtime, const std::string& who) {
  if (auto refused = prime::detail::apply_realtime(realtime, who)) return refused->message;
  return std::nullopt;
}

// ---- a slice's ticks ---------------------------------------------------------

// The ticks of one slice: kWarmUpTicks not counted, then `counted` whose
// lateness is kept, recorded by the loop's thread into room made before
// (no allocation while it ticks) and read once it has stopped.
class Slice {
 public:
  explicit Slice(std::uint64_t counted) : lateness_(counted) {}

  // The loop's thread, at each tick: whether this one is counted.
  bool record(Clock::duration lateness) {
    const auto n = ran_.load(std::memory_order_relaxed);
    const bool counted = n >= kWarmUpTicks && n - kWarmUpTicks < lateness_.size();
    if (counted) lateness_[n - kWarmUpTicks] = clamp_ns(lateness);
    ran_.store(n + 1, std::memory_order_release);
    return counted;
  }
  [[nodiscard]] std::uint64_t ran() const noexcept { return ran_.load(std::memory_order_acquire); }
  [[nodiscard]] std::uint64_t due() const noexcept { return kWarmUpTicks + lateness_.size(); }
  [[nodiscard]] bool done() const noexcept { return ran() >= due(); }
  [[nodiscard]] const std::vector<std::uint32_t>& lateness() const noexcept { return lateness_; }

 private:
  std::vector<std::uint32_t> lateness_;
  std::atomic<std::uint64_t> ran_{0};
};

// Sleeps until the slice has run its ticks, watching the subscriber and the
// load; throws if the loop falls far behind its schedule.
void wait_for(const Slice& slice, ipc::Link& child, Load& load) {
  const auto give_up = Clock::now() + 3 * kPeriod * static_cast<Clock::rep>(slice.due()) + 10s;
  while (!slice.done()) {
    child.check();
    load.check();
    if (Clock::now() > give_up)
      throw ipc::PeerError{"the loop ran " + std::to_string(slice.ran()) + " ticks of " + std::to_string(slice.due()) +
                           " in 3 times their time"};
    std::this_thread::sleep_for(10ms);
  }
}

// ---- the subscribers' record, shared with the parent -------------------------

struct ReceiverHeader {
  alignas(64) std::atomic<std::uint64_t> last_seq{0};  // the newest sample seen
  std::atomic<std::uint64_t> recorded{0};              // e2e samples written below
  std::atomic<std::uint64_t> lost{0};                  // samples never seen
  std::atomic<int> priority{-1};                       // what the subscriber got: 0 is normal priority
  char refused[512] = {};                              // why, when it asked for more
};

// A subscriber's end-to-end latencies: a header and `capacity` samples in
// memory both processes map.
class Receiver {
 public:
  static Receiver create(std::size_t capacity) {
    auto mapping = ipc::SharedMapping::create("prime-loop-receiver", bytes(capacity));
    mapping.construct<ReceiverHeader>();
    return Receiver{std::move(mapping), capacity};
  }
  static Receiver adopt(int fd, std::size_t capacity) {
    return Receiver{ipc::SharedMapping::adopt(fd, bytes(capacity)), capacity};
  }

  [[nodiscard]] int fd() const noexcept { return mapping_.fd(); }
  [[nodiscard]] ReceiverHeader& header() const { return mapping_.as<ReceiverHeader>(); }

  // The subscriber's side: asks for `priority` (0: none), and says what it got.
  void take_priority(int priority) {
    auto& h = header();
    if (priority > 0) {
      if (const auto refused = take_realtime(fifo(priority, -1), "the subscriber")) {
        const auto n = std::min(refused->size(), sizeof h.refused - 1);
        std::memcpy(h.refused, refused->data(), n);
        h.refused[n] = '\0';
        priority = 0;
      }
    }
    h.priority.store(priority, std::memory_order_release);
  }

  // Sample `seq` arrived `latency` after its stamp; kept if `counted`.
  void record(std::uint64_t seq, bool counted, Clock::duration latency) {
    auto& h = header();
    const auto last = h.last_seq.load(std::memory_order_relaxed);
    if (seq > last + 1) h.lost.store(h.lost.load(std::memory_order_relaxed) + (seq - last - 1), std::memory_order_relaxed);
    const auto n = h.recorded.load(std::memory_order_relaxed);
    if (counted && n < capacity_) {
      samples()[n] = clamp_ns(latency);
      h.recorded.store(n + 1, std::memory_order_release);
    }
    h.last_seq.store(seq, std::memory_order_release);
  }

  // The parent's side, once the subscriber has stopped.
  [[nodiscard]] std::vector<std::uint32_t> latencies() const {
    const auto n = std::min<std::uint64_t>(header().recorded.load(std::memory_order_acquire), capacity_);
    return {samples(), samples() + n};
  }

 private:
  Receiver(ipc::SharedMapping mapping, std::size_t capacity) : mapping_{std::move(mapping)}, capacity_{capacity} {}
  static std::size_t bytes(std::size_t capacity) { return sizeof(ReceiverHeader) + capacity * sizeof(std::uint32_t); }
  [[nodiscard]] std::uint32_t* samples() const {
    return reinterpret_cast<std::uint32_t*>(static_cast<std::byte*>(mapping_.data()) + sizeof(ReceiverHeader));
  }

  ipc::SharedMapping mapping_;
  std::size_t capacity_;
};

// What the parent hands each subscriber: its domain or topic, the priority
// to ask for, and how many samples to keep.
std::vector<std::string> subscriber_args(std::string name, int priority, std::uint64_t ticks) {
  return {std::move(name), std::to_string(priority), std::to_string(ticks)};
}

// Waits (briefly) for a subscriber to see the last sample published.
void wait_for_receiver(const Receiver& receiver, std::uint64_t last, ipc::Link& child) {
  const auto give_up = Clock::now() + 200ms;
  while (receiver.header().last_seq.load(std::memory_order_acquire) < last && Clock::now() < give_up) {
    child.check();
    std::this_thread::sleep_for(1ms);
  }
}

// ---- what the three have in common -------------------------------------------

// Why one of the three cannot run here (not installed, refused): it is then
// left out, said so, and the others go on.
class Unavailable : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// How one of the three ran, once it has: what every side's scheduling got,
// in words, and for a publishing loop its subscriber's record.
struct Outcome {
  int priority = 0;  // the SCHED_FIFO priority every side got; 0: normal
  std::string how;   // "SCHED_FIFO 80 on both sides; ...", "normal priority (why)"
  std::optional<std::vector<std::uint32_t>> e2e{};  // end to end, if it publishes
  std::uint64_t lost = 0;                           // samples its subscriber never saw
};

// One of the three loops: set up by its constructor (which throws
// Unavailable if it cannot run here), then run slice by slice (run()), then
// finished (finish(): its subscriber stopped, if it has one).
class Contender {
 public:
  Contender(const Contender&) = delete;
  Contender& operator=(const Contender&) = delete;
  virtual ~Contender() = default;

  // Runs one slice, kWarmUpTicks and then `counted` ticks, keeping the
  // counted ones' lateness; nothing once it turned out unavailable.
  void run_slice(std::uint64_t counted, Load& load) {
    if (unavailable_) return;
    const auto start = CpuTime::now();
    Slice slice{counted};
    try {
      run(slice, load);
    } catch (const Unavailable& e) {
      unavailable_ = e.what();
      lateness_.clear();
      return;
    }
    busy_ += CpuTime::now().since(start);
    lateness_.insert(lateness_.end(), slice.lateness().begin(), slice.lateness().end());
  }
  [[nodiscard]] bool available() const noexcept { return !unavailable_; }

  // After the last slice: finishes, and reports its counters as
  // <who in lower case>_...
  void report(benchmark::State& state) {
    if (unavailable_) return;
    outcome_ = finish();
    std::string prefix = who_;
    std::transform(prefix.begin(), prefix.end(), prefix.begin(), [](unsigned char c) { return std::tolower(c); });
    report_spread(state, prefix + "_lateness", lateness_);
    state.counters[prefix + "_ticks"] = static_cast<double>(lateness_.size());
    state.counters[prefix + "_busy"] = busy_.busy();
    state.counters[prefix + "_priority"] = outcome_.priority;
    if (outcome_.e2e) {
      state.counters[prefix + "_received"] = static_cast<double>(outcome_.e2e->size());
      state.counters[prefix + "_lost"] = static_cast<double>(outcome_.lost);
      report_spread(state, prefix + "_e2e", *outcome_.e2e);
    }
  }
  // After report(): "<Who>: <how it ran>", or "<Who>: not run: <why>".
  [[nodiscard]] std::string label() const {
    return who_ + ": " + (unavailable_ ? "not run: " + *unavailable_ : outcome_.how);
  }

 protected:
  explicit Contender(std::string who, std::optional<std::string> unavailable = std::nullopt)
      : who_{std::move(who)}, unavailable_{std::move(unavailable)} {}
  virtual void run(Slice& slice, Load& load) = 0;
  virtual Outcome finish() = 0;

 private:
  std::string who_;  // Shm, Iceoryx, Cyclictest
  std::optional<std::string> unavailable_;
  std::vector<std::uint32_t> lateness_;
  CpuTime busy_;
  Outcome outcome_;
};

// One that could not even be set up.
class NotRun final : public Contender {
 public:
  NotRun(std::string who, std::string why) : Contender{std::move(who), std::move(why)} {}

 private:
  void run(Slice&, Load&) override {}
  Outcome finish() override { return {}; }
};

// What shm's loop and iceoryx's share: the scheduling they ask for, what
// the loop's thread was refused, and the subscriber's record.
class Publishing {
 public:
  explicit Publishing(const Setup& s) : setup_{s}, receiver_{Receiver::create(s.ticks)} {}

  [[nodiscard]] const Setup& setup() const noexcept { return setup_; }
  [[nodiscard]] int receiver_fd() const noexcept { return receiver_.fd(); }
  // What the loop's thread asks for: the priority, on the loop's CPU, or
  // once refused that CPU alone.
  [[nodiscard]] prime::Realtime realtime() const {
    const auto asked = fifo(setup_.priority, setup_.loop_cpu);
    return refused_ ? prime::Realtime{.cpus = asked.cpus} : asked;
  }
  // The loop's thread, before its first tick: why its priority was refused.
  void refused(std::string why) { refused_ = std::move(why); }
  [[nodiscard]] bool refused() const noexcept { return refused_.has_value(); }

  // After the last slice: stops the subscriber once it has seen sample
  // `last_seq` (or after a moment), and says how both sides ran.
  Outcome finish(ipc::Link& child, std::uint64_t last_seq) {
    wait_for_receiver(receiver_, last_seq, child);
    child.stop();
    const auto& h = receiver_.header();
    const bool subscriber_refused = h.priority.load(std::memory_order_acquire) != setup_.priority;
    Outcome o{.priority = refused_ || subscriber_refused ? 0 : setup_.priority,
              .how = {},
              .e2e = receiver_.latencies(),
              .lost = h.lost.load(std::memory_order_acquire)};
    std::ostringstream how;
    if (o.priority > 0) {
      how << "SCHED_FIFO " << setup_.priority << " on both sides";
    } else {
      // Both sides are refused alike (one user, one machine): the loop's reason, once.
      how << "normal priority (";
      if (refused_) how << *refused_ << (subscriber_refused ? "; the subscriber's too" : "");
      else how << h.refused;
      how << ')';
    }
    if (setup_.loop_cpu >= 0) how << "; loop on CPU " << setup_.loop_cpu << ", subscriber on the next";
    o.how = how.str();
    return o;
  }

 private:
  const Setup setup_;
  Receiver receiver_;
  std::optional<std::string> refused_;
};

// ---- Shm ---------------------------------------------------------------------

struct ShmSample {
  std::uint64_t seq;
  std::uint32_t counted;  // 1: its e2e latency is kept
};

shm::TopicQos shm_qos() { return {.capacity = 64}; }

// Child: subscribes to "loop" in domain arg(0) at priority arg(1), keeps
// the e2e latency of up to arg(2) counted samples, until stopped.
void shm_subscriber(ipc::Child& self) {
  auto receiver = Receiver::adopt(self.fd(0), parse<std::size_t>(self.arg(2), "sample count"));
  receiver.take_priority(parse<int>(self.arg(1), "priority"));
  (void)prime::lock_memory(/*best_effort=*/true);
  shm::Core core{self.arg(0), {.participant = "loop-subscriber"}};
  auto samples = core.subscribe<ShmSample>("loop", {}, shm_qos()).subscribe();
  self.ready();
  for (;;) {
    if (auto sample = samples.read_for(50ms)) {
      const auto received = Clock::now();
      receiver.record(sample->value->seq, sample->value->counted != 0, received - sample->stamp);
    }
    self.check();
  }
}
const ipc::ChildEntry kShmSubscriber{"Loop.shm_subscriber", shm_subscriber};

class ShmLoop final : public Contender {
 public:
  explicit ShmLoop(const Setup& s)
      : Contender{"Shm"},
        publishing_{s},
        domain_{ipc::new_shm_domain()},
        core_{domain_, {.participant = "loop-publisher"}},
        publisher_{core_.publisher<ShmSample>("loop", shm_qos())},
        child_{"Loop.shm_subscriber", sizeof(ShmSample), {publishing_.receiver_fd()},
               subscriber_args(domain_, s.priority, s.ticks)} {
    child_.wait_ready();
    child_.go();
  }

 private:
  void run(Slice& slice, Load& load) override {
    auto tick = [this, &slice](prime::Token) {
      const auto began = Clock::now();
      const bool counted = slice.record(began - prime::this_tick()->time);
      auto loan = publisher_.loan();
      if (!loan) {
        failed_.fetch_add(1, std::memory_order_relaxed);
        return;
      }
      **loan = ShmSample{++seq_, counted ? 1u : 0u};
      std::move(*loan).publish(Clock::now());
    };
    prime::LoopOptions options{.name = "bench", .realtime = publishing_.realtime()};
    std::optional<prime::Loop> loop;
    try {
      loop.emplace(prime::every(core_, kPeriod, tick, options));
    } catch (const prime::Failure& f) {
      if (f.error().code != prime::Errc::refused || publishing_.refused()) throw;
      publishing_.refused(f.error().message);  // asked once; normal priority from here on
      options.realtime = publishing_.realtime();
      loop.emplace(prime::every(core_, kPeriod, tick, options));
    }
    wait_for(slice, child_, load);
    loop->stop();
    if (const auto n = failed_.load()) throw ipc::PeerError{"shm: " + std::to_string(n) + " loans failed"};
  }
  Outcome finish() override { return publishing_.finish(child_, seq_); }

  Publishing publishing_;
  std::string domain_;
  shm::Core core_;
  shm::Publisher<ShmSample> publisher_;
  ipc::Link child_;
  std::uint64_t seq_ = 0;  // the loop's thread's, between slices this one's
  std::atomic<std::uint64_t> failed_{0};
};

// ---- iceoryx -----------------------------------------------------------------

struct IceoryxSample {
  std::uint64_t seq;
  std::int64_t stamp_ns;  // steady_clock, one clock for every process
  std::uint32_t counted;  // 1: its e2e latency is kept
};

// Child: takes "loop" samples of iceoryx topic arg(0), asleep in a WaitSet,
// at priority arg(1), keeping the e2e latency of up to arg(2) counted
// samples, until stopped.
void iceoryx_subscriber(ipc::Child& self) {
  auto receiver = Receiver::adopt(self.fd(0), parse<std::size_t>(self.arg(2), "sample count"));
  receiver.take_priority(parse<int>(self.arg(1), "priority"));
  (void)prime::lock_memory(/*best_effort=*/true);
  ipc::iceoryx::start_child_runtime(self.arg(0));
  iox::popo::UntypedSubscriber subscriber{ipc::iceoryx::service(self.arg(0), "loop")};
  iox::popo::WaitSet<> waitset;
  if (waitset.attachState(subscriber, iox::popo::SubscriberState::HAS_DATA).has_error())
    throw ipc::PeerError{"iceoryx: cannot attach the subscriber to a WaitSet"};
  ipc::sleep_until(self, [&] { return subscriber.getSubscriptionState() == iox::SubscribeState::SUBSCRIBED; });
  self.ready();
  for (;;) {
    (void)waitset.timedWait(iox::units::Duration::fromMilliseconds(50));
    for (auto chunk = subscriber.take(); !chunk.has_error(); chunk = subscriber.take()) {
      const auto received = Clock::now();
      IceoryxSample sample;
      std::memcpy(&sample, chunk.value(), sizeof sample);
      subscriber.release(chunk.value());
      receiver.record(sample.seq, sample.counted != 0, received - Clock::time_point{Clock::duration{sample.stamp_ns}});
    }
    self.check();
  }
}
const ipc::ChildEntry kIceoryxSubscriber{"Loop.iceoryx_subscriber", iceoryx_subscriber};

timespec to_timespec(Clock::time_point t) {
  const auto ns = std::chrono::nanoseconds{t.time_since_epoch()}.count();
  return {static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
}

// RouDi first: it must be up before the publisher is made.
std::string started_iceoryx_topic() {
  try {
    ipc::iceoryx::start_iceoryx();
  } catch (const std::exception& e) {
    throw Unavailable{e.what()};
  }
  return ipc::iceoryx::new_topic();
}

class IceoryxLoop final : public Contender {
 public:
  explicit IceoryxLoop(const Setup& s)
      : Contender{"Iceoryx"},
        publishing_{s},
        topic_{started_iceoryx_topic()},
        publisher_{ipc::iceoryx::service(topic_, "loop")},
        files_{topic_},
        child_{"Loop.iceoryx_subscriber", sizeof(IceoryxSample), {publishing_.receiver_fd()},
               subscriber_args(topic_, s.priority, s.ticks)} {
    child_.wait_ready();
    ipc::sleep_until(child_, [&] { return publisher_.hasSubscribers(); });
    child_.go();
  }

 private:
  void run(Slice& slice, Load& load) override {
    std::atomic<bool> stop{false};
    std::thread loop{[&] { classic_loop(slice, stop); }};
    try {
      wait_for(slice, child_, load);
    } catch (...) {
      stop = true;
      loop.join();
      throw;
    }
    loop.join();
    if (const auto n = failed_.load()) throw ipc::PeerError{"iceoryx could not loan " + std::to_string(n) + " chunks"};
  }
  Outcome finish() override { return publishing_.finish(child_, seq_); }

  // The classic real-time loop: its scheduling set on its own thread, then
  // sleep to each tick's absolute time, do the work, skip the ticks that
  // passed meanwhile (as cyclictest does).
  void classic_loop(Slice& slice, const std::atomic<bool>& stop) {
    if (auto why = take_realtime(publishing_.realtime(), "the iceoryx loop"); why && !publishing_.refused()) {
      publishing_.refused(std::move(*why));  // asked once; normal priority from here on
      (void)take_realtime(publishing_.realtime(), "the iceoryx loop");  // the same CPU at least
    }
    auto next = Clock::time_point{Clock::now().time_since_epoch() / kPeriod * kPeriod} + kPeriod;
    while (!stop.load(std::memory_order_relaxed)) {
      const timespec at = to_timespec(next);
      while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, nullptr) == EINTR) {
      }
      const auto began = Clock::now();
      const bool counted = slice.record(began - next);
      auto chunk = publisher_.loan(sizeof(IceoryxSample));
      if (chunk.has_error()) {
        failed_.fetch_add(1, std::memory_order_relaxed);
      } else {
        IceoryxSample sample{++seq_, 0, counted ? 1u : 0u};
        sample.stamp_ns = Clock::now().time_since_epoch().count();
        std::memcpy(chunk.value(), &sample, sizeof sample);
        publisher_.publish(chunk.value());
      }
      if (slice.done()) return;
      const auto now = Clock::now();
      do next += kPeriod;
      while (next <= now);
    }
  }

  Publishing publishing_;
  std::string topic_;
  iox::popo::UntypedPublisher publisher_;
  const ipc::iceoryx::ChildRuntimeFiles files_;  // removed once the child is gone
  ipc::Link child_;
  std::uint64_t seq_ = 0;  // the loop's thread's, between slices this one's
  std::atomic<std::uint64_t> failed_{0};
};

// ---- cyclictest --------------------------------------------------------------

// cyclictest -v prints every tick's lateness as "<thread>: <tick>: <ns>".
std::vector<std::uint32_t> cyclictest_lateness(const std::string& output) {
  std::vector<std::uint32_t> lateness;
  std::istringstream lines{output};
  for (std::string line; std::getline(lines, line);) {
    std::uint64_t thread = 0, tick = 0, ns = 0;
    char colon1 = 0, colon2 = 0;
    std::istringstream fields{line};
    if (!(fields >> thread >> colon1 >> tick >> colon2 >> ns) || colon1 != ':' || colon2 != ':') continue;
    if (tick >= kWarmUpTicks) lateness.push_back(static_cast<std::uint32_t>(std::min<std::uint64_t>(ns, UINT32_MAX)));
  }
  return lateness;
}

std::string cyclictest_program() {
  try {
    return find_program("cyclictest", "rt-tests");
  } catch (const std::exception& e) {
    throw Unavailable{e.what()};
  }
}

class Cyclictest final : public Contender {
 public:
  explicit Cyclictest(const Setup& s) : Contender{"Cyclictest"}, setup_{s}, program_{cyclictest_program()} {}

 private:
  // It runs at its priority or not at all.
  Outcome finish() override {
    return {.priority = setup_.priority,
            .how = "SCHED_FIFO " + std::to_string(setup_.priority) +
                   (setup_.loop_cpu >= 0 ? " on CPU " + std::to_string(setup_.loop_cpu) : std::string{})};
  }

  // One cyclictest process per slice: its own warm-up, then the counted ticks.
  void run(Slice& slice, Load& load) override {
    ipc::MemoryFile output{"prime-loop-cyclictest.log"};
    std::vector<std::string> argv{program_, "-m", "-t1", "-d", "0", "-p", std::to_string(setup_.priority), "-i",
                                  std::to_string(std::chrono::duration_cast<std::chrono::microseconds>(kPeriod).count()),
                                  "-l", std::to_string(slice.due()), "-N", "-v"};
    if (setup_.loop_cpu >= 0) argv.insert(argv.begin() + 1, {"-a", std::to_string(setup_.loop_cpu)});
    ipc::ChildProcess::Options options;
    options.cpus = ipc::startup_cpus();
    options.output_fd = output.fd();
    ipc::ChildProcess cyclictest{program_, argv, options};
    const auto give_up = Clock::now() + 3 * kPeriod * static_cast<Clock::rep>(slice.due()) + 10s;
    std::optional<int> status;
    while (!(status = cyclictest.poll())) {
      load.check();
      if (Clock::now() > give_up) throw ipc::PeerError{"cyclictest did not end in 3 times its run's time"};
      std::this_thread::sleep_for(10ms);
    }
    // cyclictest runs at a real-time priority or not at all: where the
    // machine refuses it, it says so and ends with status 1.
    if (*status != 0)
      throw Unavailable{"cyclictest could not run (" +
                        (WIFEXITED(*status) ? "exit code " + std::to_string(WEXITSTATUS(*status))
                                            : ipc::ChildProcess::describe(*status)) +
                        "): " + tail(output.read())};
    // Its ticks, as a loop's thread records them (the warm-up is left out above).
    const auto lateness = cyclictest_lateness(output.read());
    if (lateness.size() + kWarmUpTicks != slice.due())
      throw ipc::PeerError{"cyclictest reported " + std::to_string(lateness.size()) + " ticks after its warm-up, not " +
                           std::to_string(slice.due() - kWarmUpTicks) + ": " + tail(output.read())};
    for (std::uint64_t i = 0; i < kWarmUpTicks; ++i) (void)slice.record(Clock::duration{});
    for (const auto ns : lateness) (void)slice.record(std::chrono::nanoseconds{ns});
  }
  const Setup setup_;
  std::string program_;
};

// ---- the benchmark -----------------------------------------------------------

// Contender C, or one that says why C cannot run here.
template <class C>
std::unique_ptr<Contender> start(const char* who, const Setup& s) {
  try {
    return std::make_unique<C>(s);
  } catch (const Unavailable& e) {
    return std::make_unique<NotRun>(who, e.what());
  }
}

void BM_Loop(benchmark::State& state) {
  ipc::run(state, [&](std::size_t load) {
    const auto s = setup();
    const MemoryLock memory;
    const DmaLatency dma;
    Load stress{load != 0, s};
    // Each Link pins this thread on start and restores what it found when
    // it ends, so the contenders end last to first (see ipc::Links).
    std::vector<std::unique_ptr<Contender>> contenders;
    const auto end = [&] {
      while (!contenders.empty()) contenders.pop_back();
    };
    std::string label;
    try {
      contenders.push_back(start<ShmLoop>("Shm", s));
      contenders.push_back(start<IceoryxLoop>("Iceoryx", s));
      contenders.push_back(start<Cyclictest>("Cyclictest", s));
      for (auto _ : state) {
        // Round r runs each one's slice r, starting with contender r.
        for (std::uint64_t round = 0; round < s.slices(); ++round)
          for (std::size_t k = 0; k < contenders.size(); ++k)
            contenders[(round + k) % contenders.size()]->run_slice(s.slice_ticks(round), stress);
        state.SetIterationTime(std::chrono::duration<double>{kPeriod * static_cast<Clock::rep>(s.ticks)}.count());
      }
      for (auto& c : contenders) {
        c->report(state);
        label += (label.empty() ? "" : " | ") + c->label();
      }
      if (std::none_of(contenders.begin(), contenders.end(), [](const auto& c) { return c->available(); }))
        throw ipc::PeerError{"none of the three could run: " + label};
    } catch (...) {
      end();
      throw;
    }
    end();
    state.counters["slices"] = static_cast<double>(s.slices());
    state.counters["load"] = load != 0 ? 1 : 0;
    state.counters["memory_locked"] = memory.locked() ? 1 : 0;
    state.counters["dma_latency"] = dma.held() ? 1 : 0;
    state.SetLabel(label);
  });
}
BENCHMARK(BM_Loop)->ArgName("load")->Arg(0)->Arg(1)->Iterations(1)->UseManualTime()->Unit(benchmark::kMillisecond);

}  // namespace
