// The driver process: serves the motors as the service "driver/command",
// measures each command's age (sensor stamp to motors), publishes the
// robot's state (100 Hz) and what it saw each second. With no command for
// 100 ms it holds the robot safe: motors stopped, until commands return.
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
  auto last_command = prime::Clock::now();
  bool safe = true;
  (void)shm.serve("driver/command", [&](const MotorCommand& c) {
    const auto now = prime::Clock::now();
    std::scoped_lock lock{mutex};
    state.speed = c.speed;
    state.turn_rate = c.turn_rate;
    latencies_ms.push_back(static_cast<double>(now.time_since_epoch().count() - c.sensor_stamp_ns) / 1e6);
    last_command = now;
    if (safe) std::printf("[driver] commands again: driving\n");
    safe = false;
    return Applied{true};
  });
  auto last_stats = prime::Clock::now();
  for (auto next = prime::Clock::now(); !stop; next += 10ms) {
    std::this_thread::sleep_until(next);
    std::scoped_lock lock{mutex};
    const auto now = prime::Clock::now();
    if (!safe && now - last_command > 100ms) {
      safe = true;
      state.speed = state.turn_rate = 0;
      std::printf("[driver] no command for 100 ms: holding the robot safe (motors stopped)\n");
      std::fflush(stdout);
    }
    state.heading += state.turn_rate * 0.01;
    state.x = std::clamp(state.x + state.speed * std::cos(state.heading) * 0.01, 0.5, kRoom - 0.5);
    state.y = std::clamp(state.y + state.speed * std::sin(state.heading) * 0.01, 0.5, kRoom - 0.5);
    (void)state_out.publish(state, now);
    if (now - last_stats >= 1s) {
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
      (void)stats_out.publish(s, now);
      latencies_ms.clear();
      last_stats = now;
    }
  }
  return 0;
}

}  // namespace robot
