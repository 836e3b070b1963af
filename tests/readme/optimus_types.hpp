// What the Optimus examples take as given: the robot's message types and blocks.
#pragma once

#include <chrono>
#include <iostream>
#include <vector>

#include "prime/logic/sample.hpp"

using namespace std::chrono_literals;

struct Scan { float ranges[360]; };
struct Pose { double x, y, theta; };
struct Path { Pose waypoints[32]; int count; };
struct Imu { double gyro[3], accel[3]; };

struct Localize {
  Pose operator()(const Scan&) const { return {}; }
};
