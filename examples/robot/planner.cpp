// The planner process: sync pairs each scan with the odometry nearest its
// stamp (adaptive approximate time: no tolerance to tune; knowing the
// sensors' rates lets it decide sooner); a collector holds the newest pair;
// a 50 Hz control loop runs localize | plan | control on it and calls the
// driver's service with the command, stamped with the scan's time.
#include <cstdio>
#include <optional>
#include <string>
#include <thread>
#include <tuple>

#include "messages.hpp"
#include "planning.hpp"
#include "prime/liberty.hpp"
#include "prime/shm.hpp"
#include "processes.hpp"

namespace robot {

using namespace std::chrono_literals;
// A synchronised set: the scan and the odometry, read in place, with their stamps.
using Sensed = prime::Synced<prime::shm::View<Scan>, prime::shm::View<Odometry>>;

int planner(const std::string& domain, Trigger trigger, const std::atomic<bool>& stop) {
  prime::shm::Core shm{domain, {.participant = "planner"}};
  prime::liberty::Core local;
  const prime::shm::TopicQos lidar_qos{.capacity = 16}, odom_qos{.capacity = 32};
  auto sets = prime::sync(prime::approximate_time({.min_interval = {15ms, 5ms}}),
                          shm.subscribe<Scan>("sensors/lidar", {}, lidar_qos), shm.subscribe<Odometry>("sensors/odom", {}, odom_qos));
  auto step = local.chain(localize<Sensed>, "localize") | local.chain(plan, "plan") | local.chain(control, "control");
  auto motors = shm.chain<MotorCommand, Applied>("driver/command", {.timeout = 50ms, .wait_for_service = 5s});
  std::atomic<std::uint64_t> sent = 0, waiting = 0;
  const auto drive = [&](const Sensed& sensed) {
    if (auto applied = motors.call(step(sensed))) ++sent;
    else std::printf("[planner] driver: %s\n", applied.error().describe().c_str());
  };

  // Periodic: a 50 Hz loop runs on the newest synchronised pair (a pair
  // waits up to a period for it). Event: the chain runs on each pair as soon
  // as sync makes it.
  std::optional<prime::Loop> loop;
  std::optional<prime::LocalSource<int>> on_each;
  if (trigger == Trigger::periodic) {
    auto newest = prime::collector(local, sets, prime::or_nothing);  // nothing before the first pair
    loop.emplace(prime::every(shm, 20ms, [&, newest](prime::Token) {
      if (const auto sensed = newest(prime::Token{})) drive(*sensed);
      else ++waiting;  // no synchronised pair yet
    }, {.name = "control", .deadline = 15ms}));
  } else {
    on_each.emplace(sets | local.chain([&](const Sensed& sensed) {
      drive(sensed);
      return 0;
    }, "drive"));
  }
  auto errors = shm.errors().subscribe();  // the loop's overruns; the chains' errors below
  auto chain_errors = local.errors().subscribe();
  while (!stop) {
    if (auto e = errors.read_for(1s)) std::printf("[planner] %s\n", e->value.describe().c_str());
    while (auto e = chain_errors.try_read()) std::printf("[planner] %s\n", e->value.describe().c_str());
    std::string shown = std::to_string(sent.exchange(0)) + " commands sent";
    if (loop) {
      const auto s = loop->stats();
      char text[160];
      std::snprintf(text, sizeof text, "; 50 Hz loop: %llu ticks, %llu overruns, lateness p99 %.3f ms, run p99 %.3f ms",
                    static_cast<unsigned long long>(s.ticks), static_cast<unsigned long long>(s.overruns),
                    std::chrono::duration<double, std::milli>{s.lateness.p99}.count(),
                    std::chrono::duration<double, std::milli>{s.run_time.p99}.count());
      shown += text;
    }
    if (waiting.exchange(0) > 0) shown += " (waiting for the first synchronised pair)";
    std::printf("[planner] %s\n", shown.c_str());
    std::fflush(stdout);
  }
  loop.reset();
  shm.stop();  // joins the workers (the event chain's too) before what they use goes
  return 0;
}

}  // namespace robot
