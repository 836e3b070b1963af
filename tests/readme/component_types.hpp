// What the components page's examples take as given: the robot's messages
// (trivially copyable, so they may cross processes) and its plain code.
#pragma once

#include <chrono>
#include <cstdint>

#include "prime/record/replay.hpp"
#include "prime/system.hpp"
#include "prime/topology/forward.hpp"

using namespace std::chrono_literals;

struct Scan {
  float ranges[4];
};
struct Odometry {
  double speed, turn_rate;
};
struct Pose {
  double x, y, heading;
};
struct Command {
  double speed, turn_rate;
};
struct Applied {
  bool driving;
};

inline Pose localize(const Scan&) { return {}; }
inline Command control(const Pose&) { return {}; }
inline Pose fuse(const Scan&, const Odometry&) { return {}; }
