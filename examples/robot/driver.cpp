// The driver component: serves the motors as the service "driver/command",
// measures each command's age (sensor stamp to motors), publishes the
// robot's state from a 100 Hz loop and what it saw each second. A watchdog
// holds the robot safe (motors stopped) when no command came for
// safe_after_ms, until commands return.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

#include "components.hpp"
#include "messages.hpp"
#include "prime/topology/watchdog.hpp"

namespace robot {

using namespace std::chrono_literals;

prime::system::Component driver() {
  return prime::system::Component{"robot.driver"}
      .serves<MotorCommand, Applied>("driver/command")
      .publishes<State>("driver/state", {.capacity = 8})
      .publishes<DriverStats>("driver/stats", {.capacity = 8})
      .every("motors", 10ms)
      .every("report", 1000ms)
      .param("safe_after_ms", 100, "no command for this long holds the robot safe")
      .build([](prime::system::Context& ctx) {
        struct Motors {
          std::mutex mutex;
          State state{1, 1, 0, 0, 0};
          std::vector<double> latencies_ms;
          bool safe = true;
          std::uint32_t safe_stops = 0;  // since the last report
          std::optional<prime::Watchdog> commands;
        };
        auto m = std::make_shared<Motors>();
        m->latencies_ms.reserve(4096);
        const auto safe_after = std::chrono::milliseconds{ctx.param<std::int64_t>("safe_after_ms")};
        // The safe stop: a deadline monitor on the commands.
        m->commands.emplace(prime::watchdog(ctx.local(), safe_after, [weak = std::weak_ptr<Motors>{m}, safe_after] {
          auto m = weak.lock();
          if (!m) return;
          std::scoped_lock lock{m->mutex};
          if (m->safe) return;
          m->safe = true;
          ++m->safe_stops;
          m->state.speed = m->state.turn_rate = 0;
          std::printf("[driver] no command for %lld ms: holding the robot safe (motors stopped)\n",
                      static_cast<long long>(safe_after.count()));
          std::fflush(stdout);
        }, {.name = "commands"}));
        ctx.serve<MotorCommand, Applied>("driver/command", [m](const MotorCommand& c) {
          const auto now = prime::Clock::now();
          m->commands->feed();
          std::scoped_lock lock{m->mutex};
          m->state.speed = c.speed;
          m->state.turn_rate = c.turn_rate;
          m->latencies_ms.push_back(static_cast<double>(now.time_since_epoch().count() - c.sensor_stamp_ns) / 1e6);
          if (m->safe) std::printf("[driver] commands again: driving\n");
          m->safe = false;
          return Applied{true};
        });
        // The motors at 100 Hz: the robot moves as commanded, its state goes out.
        ctx.every("motors", [m, state_out = ctx.output<State>("driver/state")](prime::Token) {
          State now;
          {
            std::scoped_lock lock{m->mutex};
            auto& s = m->state;
            s.heading += s.turn_rate * 0.01;
            s.x = std::clamp(s.x + s.speed * std::cos(s.heading) * 0.01, 0.5, kRoom - 0.5);
            s.y = std::clamp(s.y + s.speed * std::sin(s.heading) * 0.01, 0.5, kRoom - 0.5);
            now = s;
          }
          (void)state_out.publish(now, prime::Clock::now());
        });
        ctx.every("report", [m, stats_out = ctx.output<DriverStats>("driver/stats")](prime::Token) {
          DriverStats s{};
          State at{};
          {
            std::scoped_lock lock{m->mutex};
            auto& l = m->latencies_ms;
            s = DriverStats{static_cast<std::uint32_t>(l.size()), 0, 0, 0, m->safe, std::exchange(m->safe_stops, 0u)};
            if (!l.empty()) {
              std::sort(l.begin(), l.end());
              for (double v : l) s.mean_ms += v / static_cast<double>(l.size());
              s.p99_ms = l[static_cast<std::size_t>(0.99 * static_cast<double>(l.size() - 1))];
              s.max_ms = l.back();
            }
            l.clear();
            at = m->state;
          }
          std::printf("[driver] %u commands/s; sensor to motors: mean %.2f ms, p99 %.2f ms, max %.2f ms%s; at (%.1f, %.1f)\n",
                      s.commands, s.mean_ms, s.p99_ms, s.max_ms, s.safe_stop ? "; SAFE STOP" : "", at.x, at.y);
          std::fflush(stdout);
          (void)stats_out.publish(s, prime::Clock::now());
        });
      });
}

}  // namespace robot

PRIME_COMPONENT(robot::driver());
