// The planner component: sync pairs each scan with the odometry nearest its
// stamp (adaptive approximate time: no tolerance to tune; knowing the
// sensors' rates lets it decide sooner); a collector holds the newest pair;
// a 50 Hz control loop runs localize | plan | control on it and calls the
// driver's motors with the command, stamped with the scan's time. With the
// parameter on_each_pair, the chain runs on each pair as soon as sync makes it.
#include <atomic>
#include <cstdio>
#include <memory>
#include <string>

#include "components.hpp"
#include "messages.hpp"
#include "planning.hpp"
#include "prime/topology/forward.hpp"

namespace robot {

using namespace std::chrono_literals;
// A synchronised set: the scan and the odometry, with their stamps.
using Sensed = prime::Synced<Scan, Odometry>;

prime::system::Component planner() {
  return prime::system::Component{"robot.planner"}
      .subscribes<Scan>("sensors/lidar", {.capacity = 16})
      .subscribes<Odometry>("sensors/odom", {.capacity = 32})
      .syncs<Scan, Odometry>("sensed", {"sensors/lidar", "sensors/odom"}, prime::approximate_time({.min_interval = {15ms, 5ms}}))
      .calls<MotorCommand, Applied>("driver/command", {.timeout = 50ms, .wait_for_service = 5s})
      .every("control", 20ms)
      .every("report", 1000ms)
      .param("on_each_pair", false, "run the chain on each synchronised pair instead of in the 50 Hz loop")
      .build([](prime::system::Context& ctx) {
        auto& local = ctx.local();
        auto sets = ctx.synced<Scan, Odometry>("sensed");
        auto step = local.chain(localize<Sensed>, "localize") | local.chain(plan, "plan") | local.chain(control, "control");
        struct Counts {
          std::atomic<std::uint64_t> sent = 0, waiting = 0;
        };
        auto counts = std::make_shared<Counts>();
        auto drive = [counts, step, motors = ctx.client<MotorCommand, Applied>("driver/command")](const Sensed& sensed) {
          if (auto applied = motors.call(step(sensed))) ++counts->sent;
          else std::printf("[planner] driver: %s\n", applied.error().describe().c_str());
        };
        const prime::Loop* loop = nullptr;
        if (!ctx.param<bool>("on_each_pair")) {
          // Periodic: the loop runs on the newest synchronised pair.
          auto newest = prime::collector(local, sets, prime::or_nothing);  // nothing before the first pair
          loop = &ctx.every("control", [counts, newest, drive](prime::Token) {
            if (const auto sensed = newest(prime::Token{})) drive(*sensed);
            else ++counts->waiting;  // no synchronised pair yet
          }, {.phase = 5ms, .deadline = 15ms});  // 5 ms after the sensors sample (both tick on the clock's multiples)
        } else {
          prime::forward(sets, [drive](const Sensed& sensed, prime::Clock::time_point) { drive(sensed); }, "drive");
        }
        ctx.every("report", [counts, loop](prime::Token) {
          std::string shown = std::to_string(counts->sent.exchange(0)) + " commands sent";
          if (loop) {
            const auto s = loop->stats();
            char text[160];
            std::snprintf(text, sizeof text, "; 50 Hz loop: %llu ticks, %llu overruns, lateness p99 %.3f ms, run p99 %.3f ms",
                          static_cast<unsigned long long>(s.ticks), static_cast<unsigned long long>(s.overruns),
                          std::chrono::duration<double, std::milli>{s.lateness.p99}.count(),
                          std::chrono::duration<double, std::milli>{s.run_time.p99}.count());
            shown += text;
          }
          if (counts->waiting.exchange(0) > 0) shown += " (waiting for the first synchronised pair)";
          std::printf("[planner] %s\n", shown.c_str());
          std::fflush(stdout);
        });
      });
}

}  // namespace robot

PRIME_COMPONENT(robot::planner());
