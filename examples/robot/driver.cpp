// The driver process: serves the motors as the service "driver/command",
// measures each command's age (sensor stamp to motors), publishes the
// robot's state from a 100 Hz loop and what it saw each second. A watchdog
// holds the robot safe (motors stopped) when no command came for 100 ms,
// until commands return.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <thread>
#include <vector>

#include "messages.hpp"
#include "prime/shm.hpp"
#include "processes.hpp"

namespace robot {

using namespace std::chrono_literals;

int driver(const std::string& domain, const std::atomic<bool>& stop) {
  prime::shm::Core shm{domain, {.participant = "driver"}};
  auto state_out = shm.publisher<State>("driver/state", {.capacity = 8});
  auto stats_out = shm.publisher<DriverStats>("driver/stats", {.capacity = 8});
  std::mutex mutex;
  State state{1, 1, 0, 0, 0};
  std::vector<double> latencies_ms;
  latencies_ms.reserve(4096);
  bool safe = true;
  // The safe stop: a deadline monitor on the commands.
  auto commands = prime::watchdog(shm, 100ms, [&] {
    std::scoped_lock lock{mutex};
    if (safe) return;
    safe = true;
    state.speed = state.turn_rate = 0;
    std::printf("[driver] no command for 100 ms: holding the robot safe (motors stopped)\n");
    std::fflush(stdout);
  }, {.name = "commands"});
  (void)shm.serve("driver/command", [&](const MotorCommand& c) {
    const auto now = prime::Clock::now();
    commands.feed();
    std::scoped_lock lock{mutex};
    state.speed = c.speed;
    state.turn_rate = c.turn_rate;
    latencies_ms.push_back(static_cast<double>(now.time_since_epoch().count() - c.sensor_stamp_ns) / 1e6);
    if (safe) std::printf("[driver] commands again: driving\n");
    safe = false;
    return Applied{true};
  });
  // The motors at 100 Hz: the robot moves as commanded, its state goes out.
  auto motors = prime::every(shm, 10ms, [&](prime::Token) {
    std::scoped_lock lock{mutex};
    state.heading += state.turn_rate * 0.01;
    state.x = std::clamp(state.x + state.speed * std::cos(state.heading) * 0.01, 0.5, kRoom - 0.5);
    state.y = std::clamp(state.y + state.speed * std::sin(state.heading) * 0.01, 0.5, kRoom - 0.5);
    (void)state_out.publish(state, prime::Clock::now());
  }, {.name = "motors"});
  auto errors = shm.errors().subscribe();
  for (auto last_stats = prime::Clock::now(); !stop;) {
    if (auto e = errors.read_for(last_stats + 1s - prime::Clock::now())) std::printf("[driver] %s\n", e->value.describe().c_str());
    if (prime::Clock::now() < last_stats + 1s) continue;
    last_stats = prime::Clock::now();
    std::scoped_lock lock{mutex};
    DriverStats s{static_cast<std::uint32_t>(latencies_ms.size()), 0, 0, 0, safe};
    if (!latencies_ms.empty()) {
      std::sort(latencies_ms.begin(), latencies_ms.end());
      for (double l : latencies_ms) s.mean_ms += l / static_cast<double>(latencies_ms.size());
      s.p99_ms = latencies_ms[static_cast<std::size_t>(0.99 * static_cast<double>(latencies_ms.size() - 1))];
      s.max_ms = latencies_ms.back();
    }
    std::printf("[driver] %u commands/s; sensor to motors: mean %.2f ms, p99 %.2f ms, max %.2f ms%s; at (%.1f, %.1f)\n",
                s.commands, s.mean_ms, s.p99_ms, s.max_ms, safe ? "; SAFE STOP" : "", state.x, state.y);
    std::fflush(stdout);
    (void)stats_out.publish(s, prime::Clock::now());
    latencies_ms.clear();
  }
  motors.stop();
  commands.stop();
  shm.stop();  // joins the service's workers before what they use goes
  return 0;
}

}  // namespace robot
