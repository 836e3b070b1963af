#pragma once

// What the robot's processes send each other: trivially copyable messages,
// each described for `prime echo` and `prime pub`.

#include <array>
#include <cstdint>

#include "prime/common/schema.hpp"

namespace robot {

// The true state of the robot, which the driver moves and the sensors see.
struct State {
  double x, y, heading;
  double speed, turn_rate;  // as the motors drive it now
};
PRIME_DESCRIBE(State, x, y, heading, speed, turn_rate)

// A lidar scan: the distance to each wall.
struct Scan {
  std::array<float, 4> wall_distance;  // east, north, west, south, in metres
};
PRIME_DESCRIBE(Scan, wall_distance)

// Odometry: dead reckoning, with the heading it measured.
struct Odometry {
  double x, y, heading;
};
PRIME_DESCRIBE(Odometry, x, y, heading)

// What the planner asks the motors to do, and the stamp of the sensor data
// it was computed from (for the end-to-end latency).
struct MotorCommand {
  double speed, turn_rate;
  std::int64_t sensor_stamp_ns;
};
PRIME_DESCRIBE(MotorCommand, speed, turn_rate, sensor_stamp_ns)

// The driver's answer: whether it applied the command.
struct Applied {
  bool driving;
};
PRIME_DESCRIBE(Applied, driving)

// What the driver saw over the last second: commands applied and their
// latency, sensor stamp to motors.
struct DriverStats {
  std::uint32_t commands;
  double mean_ms, p99_ms, max_ms;
  bool safe_stop;            // no command for safe_after_ms: the motors are stopped now
  std::uint32_t safe_stops;  // times in this second it stopped the motors so
};
PRIME_DESCRIBE(DriverStats, commands, mean_ms, p99_ms, max_ms, safe_stop, safe_stops)

inline constexpr double kRoom = 10.0;  // metres, square

}  // namespace robot
