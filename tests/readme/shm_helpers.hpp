// What the Shm examples (README.md, docs/shm.md) take as given: the user's own code.
#pragma once

#include <chrono>

#include "prime/logic/sample.hpp"

using namespace std::chrono_literals;

inline prime::Clock::time_point sensor_time() { return prime::Clock::now(); }

float closest(const auto& scan) {
  float best = 1e9f;
  for (float r : scan.ranges) best = r < best ? r : best;
  return best;
}

void use(const auto&, prime::Clock::time_point) {}
