#pragma once

// The robot's three components. Each declares its ports and names no
// medium: robot.yaml places them in one process, in three, or over two
// machines, and `prime launch` links each port accordingly.
//
//   sensors: lidar (40 Hz) and odometry (100 Hz), seeing the robot's true state
//   planner: sync of scan and odometry, then localize | plan | control, and a
//            call of the driver's motors (a 50 Hz loop, or on each pair)
//   driver:  serves the motors, moves the robot (100 Hz), holds it safe
//            when commands stop, reports the sensor-to-motors latency

#include "prime/system.hpp"

namespace robot {

prime::system::Component sensors();
prime::system::Component planner();
prime::system::Component driver();

}  // namespace robot
