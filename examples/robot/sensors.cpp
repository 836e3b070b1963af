// The sensors process: an emulated lidar (40 Hz) and odometry (100 Hz),
// each published by loan — written in place in shared memory, never copied —
// with the time the sensor took it. They see the robot's true state, which
// the driver publishes.
#include <cmath>
#include <cstdio>
#include <random>
#include <thread>

#include "messages.hpp"
#include "prime/shm.hpp"
#include "processes.hpp"

namespace robot {

using namespace std::chrono_literals;

int sensors(const std::string& domain, const std::atomic<bool>& stop) {
  prime::shm::Core shm{domain, {.participant = "sensors"}};
  auto lidar = shm.publisher<Scan>("sensors/lidar", {.capacity = 16});
  auto odom = shm.publisher<Odometry>("sensors/odom", {.capacity = 32});
  auto world = shm.subscribe<State>("driver/state", {.spin = 0us}, {.capacity = 8}).subscribe();
  State state{1, 1, 0, 0, 0};
  std::mt19937 noise{7};
  std::normal_distribution<float> jitter{0, 0.01f};
  const auto start = prime::Clock::now();
  std::uint64_t ticks = 0, scans = 0, odoms = 0;
  auto last_print = start;
  for (auto next = start; !stop; next += 10ms, ++ticks) {
    std::this_thread::sleep_until(next);
    if (auto s = world.latest()) state = *s->value;
    const auto now = prime::Clock::now();
    if (auto o = odom.loan()) {  // 100 Hz
      **o = Odometry{state.x, state.y, state.heading};
      std::move(*o).publish(now);
      ++odoms;
    }
    if (ticks % 10 == 0 || ticks % 10 == 3 || ticks % 10 == 5 || ticks % 10 == 8) {  // 40 Hz
      if (auto scan = lidar.loan()) {
        (*scan)->wall_distance = {static_cast<float>(kRoom - state.x) + jitter(noise), static_cast<float>(kRoom - state.y) + jitter(noise),
                                  static_cast<float>(state.x) + jitter(noise), static_cast<float>(state.y) + jitter(noise)};
        std::move(*scan).publish(now);
        ++scans;
      }
    }
    if (now - last_print >= 1s) {
      std::printf("[sensors] lidar %llu Hz, odometry %llu Hz\n", static_cast<unsigned long long>(scans),
                  static_cast<unsigned long long>(odoms));
      std::fflush(stdout);
      scans = odoms = 0;
      last_print = now;
    }
  }
  return 0;
}

}  // namespace robot
