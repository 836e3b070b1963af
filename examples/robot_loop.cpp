// An in-process robot control loop: emulated sensor drivers raise events,
// `sync` pairs each scan with the newest odometry, and a synchronous
// localize | plan | control chain runs at 50 Hz on what the collector holds.
//
//   lidar driver (40 Hz) ──> scans ─┐
//                                   ├─> sync(latest_of_each) ──> collector ──> localize | plan | control ──> robot
//   odom driver (100 Hz) ──> odom ──┘                              (Token)
//
// The robot starts in a corner of a 10 m x 10 m room and drives to the
// opposite corner; the demo stops by itself after a few seconds.
//
//   robot_loop [seconds] [--dot]     --dot prints the topology as Graphviz DOT and exits
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <mutex>
#include <numbers>
#include <string_view>
#include <thread>
#include <tuple>

#include "prime/radiant.hpp"

using namespace std::chrono_literals;

// ---- messages (plain, trivially copyable) ---------------------------------

struct Scan {
  std::array<float, 4> wall_distance;  // east, north, west, south, in metres
};
struct Odometry {
  double x, y, heading;  // dead reckoning: drifts
};
struct Pose {
  double x, y, heading;
};
struct Path {
  Pose from;
  double goal_x, goal_y;
};
struct Command {
  double speed, turn_rate;
};

// ---- algorithms: plain functions that know nothing of Prime ---------------

constexpr double kRoom = 10.0;

// Walls give the absolute position; odometry gives the heading.
Pose localize(const std::tuple<Scan, Odometry>& in) {
  const auto& [scan, odom] = in;
  const double x = (kRoom - scan.wall_distance[0] + scan.wall_distance[2]) / 2;
  const double y = (kRoom - scan.wall_distance[1] + scan.wall_distance[3]) / 2;
  return {x, y, odom.heading};
}

Path plan(const Pose& pose) { return {pose, 8.0, 8.0}; }

Command control(const Path& path) {
  const double dx = path.goal_x - path.from.x, dy = path.goal_y - path.from.y;
  const double distance = std::hypot(dx, dy);
  double error = std::atan2(dy, dx) - path.from.heading;
  error = std::remainder(error, 2 * std::numbers::pi);
  return {distance < 0.05 ? 0.0 : std::min(2.5, distance), 3.0 * error};
}

// ---- the emulated robot and its drivers -----------------------------------

class Robot {
 public:
  void drive(const Command& c, double dt) {
    std::scoped_lock lock{mutex_};
    heading_ += c.turn_rate * dt;
    x_ += c.speed * std::cos(heading_) * dt;
    y_ += c.speed * std::sin(heading_) * dt;
  }
  Scan scan() const {
    std::scoped_lock lock{mutex_};
    return {{float(kRoom - x_), float(kRoom - y_), float(x_), float(y_)}};
  }
  Odometry odometry() {
    std::scoped_lock lock{mutex_};
    drift_ += 0.0005;
    return {x_ + drift_, y_ - drift_, heading_};
  }
  std::tuple<double, double> where() const {
    std::scoped_lock lock{mutex_};
    return {x_, y_};
  }

 private:
  mutable std::mutex mutex_;
  double x_ = 1.0, y_ = 1.0, heading_ = 0.0, drift_ = 0.0;
};

template <class T, class Read>
std::jthread driver(prime::Event<T>& event, std::chrono::microseconds period, Read read, std::atomic<int>& count) {
  return std::jthread{[&event, period, read, &count](std::stop_token stop) {
    for (auto next = prime::Clock::now(); !stop.stop_requested(); next += period) {
      std::this_thread::sleep_until(next);
      event.emit(read());
      ++count;
    }
  }};
}

int main(int argc, char** argv) {
  double seconds = 5;
  bool dot = false;
  for (int i = 1; i < argc; ++i) {
    if (std::string_view{argv[i]} == "--dot")
      dot = true;
    else
      seconds = std::atof(argv[i]);
  }

  Robot robot;
  prime::Event<Scan> lidar;
  prime::Event<Odometry> odometer;

  prime::radiant::Core core;
  auto scans = core.source(lidar, "lidar", {.capacity = 8});
  auto odom = core.source(odometer, "odometry", {.capacity = 16});
  // The newest synchronised pair, or nothing before the first: "not yet" is a value.
  auto latest = prime::collector(core, prime::sync(prime::latest_of_each, scans, odom), prime::or_nothing, "latest");
  auto step = core.chain(localize, "localize") | core.chain(plan, "plan") | core.chain(control, "control");

  if (dot) {
    std::cout << latest.graph().dot() << step.graph().dot();
    return 0;
  }
  std::cout << "Topology:\n" << latest.graph().text() << step.graph().text() << '\n';

  std::atomic<int> scan_count{0}, odom_count{0};
  {
    auto lidar_driver = driver(lidar, 25ms, [&] { return robot.scan(); }, scan_count);
    auto odom_driver = driver(odometer, 10ms, [&] { return robot.odometry(); }, odom_count);

    constexpr auto kPeriod = 20ms;  // the control loop: 50 Hz, synchronous
    int cycles = 0, waiting = 0;
    const auto end = prime::Clock::now() + std::chrono::duration<double>(seconds);
    for (auto next = prime::Clock::now(); next < end; next += kPeriod) {
      std::this_thread::sleep_until(next);
      const auto sensed = latest(prime::Token{});
      if (!sensed) {
        ++waiting;  // no synchronised scan and odometry yet: hold still
        continue;
      }
      const Command cmd = step(*sensed);
      robot.drive(cmd, std::chrono::duration<double>(kPeriod).count());
      if (++cycles % 25 == 0) {
        const auto [x, y] = robot.where();
        std::printf("t=%4.1fs  robot at (%5.2f, %5.2f)  command: speed %.2f m/s, turn %+.2f rad/s\n",
                    cycles * 0.02, x, y, cmd.speed, cmd.turn_rate);
      }
    }
    const auto [x, y] = robot.where();
    std::printf("\n%d control cycles (%d before the first synchronised pair), %d scans, %d odometry messages\n",
                cycles, waiting, scan_count.load(), odom_count.load());
    std::printf("robot stopped at (%.2f, %.2f), goal (8.00, 8.00): %s\n", x, y,
                std::hypot(8 - x, 8 - y) < 0.5 ? "reached" : "not reached yet");
  }  // drivers stop; then the core stops and joins its workers
  return 0;
}
