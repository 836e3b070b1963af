#pragma once

// The planner's chain, localize | plan | control: plain functions, used by
// the planner process on live sensor data and by a test on a recording of
// it (tests/record/robot_replay_test.cpp).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>

#include "messages.hpp"

namespace robot {

struct Pose {
  double x, y, heading;
  std::int64_t stamp_ns;
};
struct Path {
  Pose from;
  double goal_x, goal_y;
};

// Plain code, testable without Prime: walls give the position, odometry the
// heading. `in` is a synchronised scan and odometry, read in place (shm
// views, in the planner) or as values (replayed from a recording).
template <class Sensed>
Pose localize(const Sensed& in) {
  const auto& [scan_part, odom_part] = in;
  const Scan& scan = scan_part;
  const Odometry& odom = odom_part;
  const double x = (kRoom - scan.wall_distance[0] + scan.wall_distance[2]) / 2;
  const double y = (kRoom - scan.wall_distance[1] + scan.wall_distance[3]) / 2;
  return {x, y, odom.heading, in.template stamp<0>().time_since_epoch().count()};
}
inline Path plan(const Pose& p) {  // drive a square: corner to corner
  const double goal = (std::fmod(static_cast<double>(p.stamp_ns) / 1e9, 20.0) < 10.0) ? kRoom - 1 : 1;
  return {p, goal, goal};
}
inline MotorCommand control(const Path& path) {
  const double dx = path.goal_x - path.from.x, dy = path.goal_y - path.from.y;
  const double distance = std::hypot(dx, dy);
  double turn = std::atan2(dy, dx) - path.from.heading;
  while (turn > std::numbers::pi) turn -= 2 * std::numbers::pi;
  while (turn < -std::numbers::pi) turn += 2 * std::numbers::pi;
  return {std::min(1.0, distance), 2 * turn, path.from.stamp_ns};
}

}  // namespace robot
