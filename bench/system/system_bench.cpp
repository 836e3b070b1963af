// Sensor to command through components, in each placement, against the same
// pipeline wired by hand through Shm, in one run (`prime bench`'s system
// suite).
//
// The pipeline: a sensor publishes a stamped Reading; a planner turns each
// reading into a Command as it arrives and calls the driver's service
// "driver/command"; the driver notes the time the command reached it. This
// process hosts the sensor and the driver; the planner runs in another
// process (hand-wired, split, machines) or in this one (one). One reading
// is in flight at a time, and the benchmark's thread sleeps until the driver
// has it, so the three busy parts never share two CPUs with a spinner.
// Each iteration's time is the driver's clock less the reading's stamp.
//
//   BM_SensorToCommand_HandWired     shm publish, shm subscribe | forward, shm service call: today's hand-wired demo
//   BM_SensorToCommand_Split         the same as components, one process per placement's process (Shm links)
//   BM_SensorToCommand_One           the same components, all in this process (in-process links)
//   BM_SensorToCommand_Machines      the planner's links through a redis-server on loopback (Optimus)
//
// Counters: p50_ns, p99_ns (of the iterations' times).
#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "../ipc/child_process.hpp"
#include "optimus/support/redis_server.hpp"
#include "prime/system.hpp"
#include "prime/topology/forward.hpp"

namespace {

using namespace std::chrono_literals;
namespace sys = prime::system;

struct Reading {
  std::int64_t stamp_ns;
  double value;
};
struct Command {
  std::int64_t stamp_ns;
  double speed;
};
struct Applied {
  bool driving;
};

Command plan(const Reading& r) { return {r.stamp_ns, r.value * 0.5 + 1.0}; }

// What the driver saw: the last command's arrival, for the benchmark's thread.
struct Driver {
  std::mutex mutex;
  std::condition_variable arrived;
  std::uint64_t served = 0;
  std::int64_t latency_ns = 0;

  Applied serve(const Command& c) {
    const auto now = prime::Clock::now().time_since_epoch().count();
    {
      std::scoped_lock lock{mutex};
      latency_ns = now - c.stamp_ns;
      ++served;
    }
    arrived.notify_one();
    return {true};
  }
};
Driver driver_state;
std::optional<sys::Output<Reading>> sensor_output;

PRIME_COMPONENT(sys::Component{"bench.sensor"}.publishes<Reading>("sensor/reading", {.capacity = 16}).build([](sys::Context& ctx) {
  sensor_output.emplace(ctx.output<Reading>("sensor/reading"));
}));
PRIME_COMPONENT(sys::Component{"bench.planner"}
                    .subscribes<Reading>("sensor/reading", {.capacity = 16})
                    .calls<Command, Applied>("driver/command", {.timeout = 2s, .wait_for_service = 5s})
                    .build([](sys::Context& ctx) {
                      prime::forward(ctx.input<Reading>("sensor/reading"),
                                     [motors = ctx.client<Command, Applied>("driver/command")](const Reading& r, prime::Clock::time_point) {
                                       (void)motors.call(plan(r));
                                     });
                    }));
PRIME_COMPONENT(sys::Component{"bench.driver"}.serves<Command, Applied>("driver/command").build([](sys::Context& ctx) {
  ctx.serve<Command, Applied>("driver/command", [](const Command& c) { return driver_state.serve(c); });
}));

void say_ready() {
  if (const char* fd = std::getenv("PRIME_READY_FD")) {
    [[maybe_unused]] const auto n = ::write(std::atoi(fd), "ready\n", 6);
    ::close(std::atoi(fd));
  }
}

// The planner wired by hand, as the demo's planner was before components.
int hand_wired_planner(const std::string& domain) {
  sigset_t stop;
  sigemptyset(&stop);
  sigaddset(&stop, SIGTERM);
  sigaddset(&stop, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop, nullptr);
  prime::shm::Core shm{domain, {.participant = "planner"}};
  auto readings = shm.subscribe<Reading>("sensor/reading", {}, {.capacity = 16});
  auto motors = shm.chain<Command, Applied>("driver/command", {.timeout = 2s, .wait_for_service = 5s});
  prime::forward(readings, [motors](const prime::shm::View<Reading>& r, prime::Clock::time_point) { (void)motors.call(plan(*r)); });
  say_ready();
  int signal = 0;
  sigwait(&stop, &signal);
  shm.stop();
  return 0;
}

std::string self() { return std::filesystem::read_symlink("/proc/self/exe").string(); }

// Starts `args` (this program) and waits for it to say it is ready.
std::unique_ptr<prime::bench::ipc::ChildProcess> start_ready(const std::vector<std::string>& args) {
  int fds[2];
  if (::pipe(fds) != 0) throw std::runtime_error{"pipe"};
  ::setenv("PRIME_READY_FD", std::to_string(fds[1]).c_str(), 1);
  auto child = std::make_unique<prime::bench::ipc::ChildProcess>(self(), args,
                                                                  prime::bench::ipc::ChildProcess::Options{.inherit_fds = {fds[1]}});
  ::unsetenv("PRIME_READY_FD");
  ::close(fds[1]);
  char line[16]{};
  const auto n = ::read(fds[0], line, sizeof line);  // "ready", or nothing: it ended
  ::close(fds[0]);
  if (n <= 0) throw std::runtime_error{"the planner process did not start"};
  return child;
}

prime::test::RedisServer& redis() {
  static prime::test::RedisServer server;
  return server;
}

std::string unique_domain(const char* what) { return std::string{"bench-system-"} + what + "-" + std::to_string(::getpid()); }

// A system file with the three placements, this process hosting the
// sensor and the driver.
std::string system_file(const std::string& domain, bool machines) {
  const auto path = std::filesystem::temp_directory_path() / (domain + ".yaml");
  std::ofstream out{path};
  out << "system: " << domain << "\n";
  if (machines) out << "machines:\n  a: {redis: \"" << redis().url() << "\"}\n  b: {redis: \"" << redis().url() << "\"}\n";
  out << R"(components:
  sensor: {type: bench.sensor}
  planner: {type: bench.planner}
  driver: {type: bench.driver}
placements:
  one:
    bench: [sensor, planner, driver]
  split:
    bench: [sensor, driver]
    planner: [planner]
)";
  if (machines) out << "  machines:\n    bench: {components: [sensor, driver], machine: a}\n    planner: {components: [planner], machine: b}\n";
  return path.string();
}

// One reading at a time, to the driver; each iteration's time is the
// driver's arrival less the reading's stamp. `publish` sends one.
template <class Publish>
void measure(benchmark::State& state, Publish publish) {
  std::vector<std::int64_t> latencies;
  latencies.reserve(1 << 16);
  double value = 0;
  for (auto _ : state) {
    std::uint64_t before;
    {
      std::scoped_lock lock{driver_state.mutex};
      before = driver_state.served;
    }
    const auto stamp = prime::Clock::now();
    publish(Reading{stamp.time_since_epoch().count(), value += 1}, stamp);
    std::unique_lock lock{driver_state.mutex};
    if (!driver_state.arrived.wait_for(lock, 5s, [&] { return driver_state.served != before; })) {
      state.SkipWithError("no command reached the driver within 5 s");
      break;
    }
    latencies.push_back(driver_state.latency_ns);
    state.SetIterationTime(static_cast<double>(driver_state.latency_ns) / 1e9);
  }
  if (latencies.empty()) return;
  std::sort(latencies.begin(), latencies.end());
  const auto at = [&](double q) { return static_cast<double>(latencies[static_cast<std::size_t>(q * static_cast<double>(latencies.size() - 1))]); };
  state.counters["p50_ns"] = at(0.5);
  state.counters["p99_ns"] = at(0.99);
}

void BM_SensorToCommand_HandWired(benchmark::State& state) {
  const auto domain = unique_domain("hand");
  prime::shm::Core shm{domain, {.participant = "bench"}};
  auto readings = shm.publisher<Reading>("sensor/reading", {.capacity = 16});
  (void)shm.serve("driver/command", [](const Command& c) { return driver_state.serve(c); });
  auto planner = start_ready({self(), "--hand-wired-planner", domain});
  measure(state, [&](const Reading& r, prime::Clock::time_point stamp) { (void)readings.publish(r, stamp); });
  planner->signal(SIGTERM);
  planner->wait_for(5s);
}

void components(benchmark::State& state, const std::string& placement) {
  const auto domain = unique_domain(placement.c_str());
  const auto file = system_file(domain, placement == "machines");
  {
    std::unique_ptr<prime::bench::ipc::ChildProcess> planner;
    if (placement != "one") planner = start_ready({self(), "--prime-system", file, "--placement", placement, "--process", "planner"});
    const auto system = sys::load_system(file);
    sys::Host host{sys::plan_of(system, sys::Registry::global(), placement, "bench")};
    measure(state, [&](const Reading& r, prime::Clock::time_point stamp) { (void)sensor_output->publish(r, stamp); });
    if (planner) {
      planner->signal(SIGTERM);
      planner->wait_for(5s);
    }
    host.stop();
    sensor_output.reset();
  }
  std::filesystem::remove(file);
}

void BM_SensorToCommand_Split(benchmark::State& state) { components(state, "split"); }
void BM_SensorToCommand_One(benchmark::State& state) { components(state, "one"); }
void BM_SensorToCommand_Machines(benchmark::State& state) { components(state, "machines"); }

BENCHMARK(BM_SensorToCommand_HandWired)->UseManualTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SensorToCommand_Split)->UseManualTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SensorToCommand_One)->UseManualTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SensorToCommand_Machines)->UseManualTime()->Unit(benchmark::kMicrosecond);

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string_view{argv[1]} == "--hand-wired-planner") return hand_wired_planner(argv[2]);
  for (int i = 1; i < argc; ++i)
    if (std::string_view{argv[i]}.starts_with("--prime-")) return sys::run(argc, argv);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
