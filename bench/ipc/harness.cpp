#include "harness.hpp"

#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <map>
#include <thread>

namespace prime::bench::ipc {

namespace {

constexpr std::string_view kChildFlag = "--ipc-child";
constexpr auto kStopTimeout = 5s;

std::map<std::string, void (*)(Child&), std::less<>>& entries() {
  static std::map<std::string, void (*)(Child&), std::less<>> registry;
  return registry;
}

// Which CPUs the two processes of a Link run on: the first two this process
// may use, unless there is only one or pinning is off.
struct Pinning {
  cpu_set_t startup{};
  std::optional<int> parent;
  std::optional<int> child;
};

Pinning& pinning() {
  static Pinning p = [] {
    Pinning p;
    if (::sched_getaffinity(0, sizeof p.startup, &p.startup) != 0) return p;
    std::vector<int> cpus;
    for (int cpu = 0; cpu < CPU_SETSIZE && cpus.size() < 2; ++cpu)
      if (CPU_ISSET(cpu, &p.startup)) cpus.push_back(cpu);
    if (cpus.size() == 2) {
      p.parent = cpus[0];
      p.child = cpus[1];
    }
    return p;
  }();
  return p;
}

cpu_set_t only(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return set;
}

std::string self_path() {
  std::string path(4096, '\0');
  const ssize_t n = ::readlink("/proc/self/exe", path.data(), path.size());
  if (n <= 0) throw std::system_error{errno, std::generic_category(), "readlink /proc/self/exe"};
  path.resize(static_cast<std::size_t>(n));
  return path;
}

template <class T>
T parse_number(std::string_view text, const char* what) {
  T value{};
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc{} || end != text.data() + text.size())
    throw std::invalid_argument{std::string{"--ipc-child: bad "} + what + " '" + std::string{text} + "'"};
  return value;
}

}  // namespace

// ---- payloads --------------------------------------------------------------

void latency_payloads(benchmark::internal::Benchmark* b) {
  for (const auto bytes : kLatencyPayloads) b->Arg(bytes);
  b->UseRealTime();
}

void throughput_payloads(benchmark::internal::Benchmark* b) {
  for (const auto bytes : kThroughputPayloads) b->Arg(bytes);
  b->UseRealTime();
}

void round_trip_payloads(benchmark::internal::Benchmark* b) {
  for (const auto bytes : kRoundTripPayloads) b->Arg(bytes);
  b->UseRealTime();
}

void report_percentiles(benchmark::State& state, std::vector<std::uint32_t>& samples, double divisor) {
  if (samples.empty()) return;
  auto at = [&](double q) {
    const auto k = std::min(samples.size() - 1, static_cast<std::size_t>(q * static_cast<double>(samples.size())));
    std::nth_element(samples.begin(), samples.begin() + static_cast<std::ptrdiff_t>(k), samples.end());
    return static_cast<double>(samples[k]) / divisor;
  };
  // Rising quantiles: each nth_element leaves the part above k for the next.
  state.counters["p50_ns"] = at(0.5);
  state.counters["p90_ns"] = at(0.9);
  state.counters["p99_ns"] = at(0.99);
  state.counters["p999_ns"] = at(0.999);
  state.counters["max_ns"] = static_cast<double>(*std::max_element(samples.begin(), samples.end())) / divisor;
}

PeerError out_of_sequence(std::uint64_t expected, std::uint64_t got) {
  return PeerError{"message " + std::to_string(expected) + " expected, " + std::to_string(got) +
                   " arrived: the stream lost or reordered a message"};
}

// ---- the parent side -------------------------------------------------------

Link::Link(std::string entry, std::size_t bytes, std::vector<int> fds, std::vector<std::string> args)
    : entry_{std::move(entry)},
      control_mapping_{SharedMapping::create("prime-ipc-control", sizeof(detail::Control))},
      control_{control_mapping_.construct<detail::Control>()} {
  // argv: --ipc-child <entry> <control fd> <bytes> [--fd=N]... [--arg=S]...
  std::vector<std::string> argv{self_path(), std::string{kChildFlag}, entry_, std::to_string(control_mapping_.fd()),
                                std::to_string(bytes)};
  for (int fd : fds) argv.push_back("--fd=" + std::to_string(fd));
  for (auto& a : args) argv.push_back("--arg=" + std::move(a));

  ChildProcess::Options options;
  options.inherit_fds = std::move(fds);
  options.inherit_fds.push_back(control_mapping_.fd());
  const auto& pins = pinning();
  if (pins.child) options.cpus = only(*pins.child);
  // /proc/self/exe rather than the path: this very binary, even if a build
  // has replaced the file since.
  process_.emplace("/proc/self/exe", argv, options);

  // Last, so that nothing after it can throw and skip the destructor that
  // undoes it.
  cpu_set_t current;
  if (pins.parent && ::sched_getaffinity(0, sizeof current, &current) == 0) {
    const cpu_set_t mine = only(*pins.parent);
    if (::sched_setaffinity(0, sizeof mine, &mine) == 0) unpinned_ = current;
  }
}

Link::~Link() {
  if (process_ && !process_->poll()) {
    control_.parent.store(detail::Control::kStop, std::memory_order_relaxed);
    const auto deadline = std::chrono::steady_clock::now() + 1s;
    while (!process_->poll() && std::chrono::steady_clock::now() < deadline) {
      try {
        if (drain_) drain_();
        else std::this_thread::sleep_for(100us);
      } catch (...) {
        std::this_thread::sleep_for(100us);
      }
    }
  }
  process_.reset();  // kills and reaps the child if it still runs
  if (unpinned_) ::sched_setaffinity(0, sizeof *unpinned_, &*unpinned_);
}

void Link::fail(const std::string& what) { throw PeerError{entry_ + ": " + what}; }

void Link::check() {
  if (control_.child.load(std::memory_order_acquire) == detail::Control::kFailed)
    fail(std::string{"the child failed: "} + control_.error);
  if (const auto status = process_->poll())
    fail("the child " + ChildProcess::describe(*status) + " before it was asked to stop");
}

void Link::wait_ready() {
  sleep_until(*this, [this] { return control_.child.load(std::memory_order_acquire) == detail::Control::kReady; });
}

void Link::go() { control_.parent.store(detail::Control::kGo, std::memory_order_release); }

void Link::stop() {
  control_.parent.store(detail::Control::kStop, std::memory_order_relaxed);
  const auto deadline = std::chrono::steady_clock::now() + kStopTimeout;
  for (;;) {
    if (const auto status = process_->poll()) {
      if (control_.child.load(std::memory_order_acquire) == detail::Control::kFailed)
        fail(std::string{"the child failed: "} + control_.error);
      if (*status != 0) fail("the child " + ChildProcess::describe(*status));
      return;
    }
    if (std::chrono::steady_clock::now() > deadline) fail("the child did not stop within 5 s");
    if (drain_) drain_();
    else std::this_thread::sleep_for(100us);
  }
}

// ---- the child side --------------------------------------------------------

ChildEntry::ChildEntry(std::string_view name, void (*main)(Child&)) { entries().emplace(std::string{name}, main); }

void Child::ready() {
  control_.child.store(detail::Control::kReady, std::memory_order_release);
  while (control_.parent.load(std::memory_order_acquire) == detail::Control::kWait) std::this_thread::sleep_for(50us);
  check();
}

static bool is_child_command(int argc, char** argv) { return argc >= 2 && argv[1] == kChildFlag; }

int child_main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: %s --ipc-child <entry> <control fd> <bytes> [--fd=N]... [--arg=S]...\n", argv[0]);
    return 2;
  }
  const std::string_view name = argv[2];
  std::optional<SharedMapping> control;
  auto report = [&](std::string_view what) {
    std::fprintf(stderr, "prime_ipc child %.*s: %.*s\n", static_cast<int>(name.size()), name.data(),
                 static_cast<int>(what.size()), what.data());
    if (!control) return 1;
    auto& shared = control->as<detail::Control>();
    const auto n = std::min(what.size(), sizeof shared.error - 1);
    std::memcpy(shared.error, what.data(), n);
    shared.error[n] = '\0';
    shared.child.store(detail::Control::kFailed, std::memory_order_release);
    return 1;
  };
  try {
    control.emplace(SharedMapping::adopt(parse_number<int>(argv[3], "control fd"), sizeof(detail::Control)));
    std::vector<int> fds;
    std::vector<std::string> args;
    for (int i = 5; i < argc; ++i) {
      const std::string_view a = argv[i];
      if (a.starts_with("--fd=")) fds.push_back(parse_number<int>(a.substr(5), "fd"));
      else if (a.starts_with("--arg=")) args.emplace_back(a.substr(6));
      else throw std::invalid_argument{"--ipc-child: unknown argument '" + std::string{a} + "'"};
    }
    const auto entry = entries().find(name);
    if (entry == entries().end()) throw std::invalid_argument{"--ipc-child: no child entry '" + std::string{name} + "'"};
    Child self{control->as<detail::Control>(), parse_number<std::size_t>(argv[4], "payload size"), std::move(fds),
               std::move(args)};
    entry->second(self);
    return 0;
  } catch (const Stopped&) {
    return 0;
  } catch (const std::exception& e) {
    return report(e.what());
  }
}

static void configure_parent(int& argc, char** argv) {
  bool pin = true;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    if (std::string_view{argv[i]} == "--ipc_no_pin") pin = false;
    else argv[kept++] = argv[i];
  }
  argc = kept;
  argv[argc] = nullptr;

  auto& pins = pinning();
  if (!pin) {
    pins.parent.reset();
    pins.child.reset();
  }
  benchmark::AddCustomContext("ipc_pinning", pins.child ? "parent on CPU " + std::to_string(*pins.parent) +
                                                              ", child on CPU " + std::to_string(*pins.child)
                                                        : std::string{"off"});
}

static void bound_exit(std::chrono::seconds timeout) {
  std::thread{[timeout] {
    std::this_thread::sleep_for(timeout);
    const char message[] =
        "prime_ipc: still not ended after main returned; a static destructor is stuck (iceoryx's runtime waits "
        "for RouDi without a timeout, and RouDi hangs on the port lock of a child that was killed); ending anyway\n";
    [[maybe_unused]] const auto written = ::write(STDERR_FILENO, message, sizeof message - 1);
    ::_exit(3);
  }}.detach();
}

int benchmark_main(int argc, char** argv) {
  if (is_child_command(argc, argv)) return child_main(argc, argv);
  configure_parent(argc, argv);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  bound_exit(std::chrono::seconds{10});
  return 0;
}

cpu_set_t startup_cpus() { return pinning().startup; }

}  // namespace prime::bench::ipc
