#pragma once

// Described types the recording tests write as ROS 2 says them.

#include <array>
#include <cstdint>

#include "prime/common/schema.hpp"

namespace described {

// Laid out as CDR lays it out: recorded as its own bytes after the header.
struct Point {
  double x, y, z;
};
PRIME_DESCRIBE(Point, x, y, z)

struct Pose {
  Point position;
  std::array<double, 4> orientation;
  std::uint32_t frame;
};
PRIME_DESCRIBE(Pose, position, orientation, frame)

}  // namespace described
