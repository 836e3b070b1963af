// Two processes, one robot: a lidar driver publishes scans into shared
// memory; a planner process reads them in place, finds the nearest obstacle
// and steers away from it at a fixed rate.
//
//   process "lidar"                        process "planner"
//   ┌────────────────────────┐             ┌──────────────────────────────────────────────────────┐
//   │ driver ──loan/publish──┼──> shm ring ┼──> subscribe ──> nearest | collector ──> steer (20 Hz)│
//   └────────────────────────┘  "lidar/scan" └──────────────────────────────────────────────────────┘
//
// Usage: shm_robot [seconds]   (default 3)
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <string>
#include <thread>

#include "prime/liberty.hpp"
#include "prime/shm.hpp"

using namespace std::chrono_literals;

// The message: trivially copyable, so it lives in the ring as it is.
struct Scan {
  prime::bounded_string<16> frame;
  prime::bounded_vector<float, 360> ranges;  // metres, one per degree
};

struct Obstacle {
  float distance;
  float bearing_deg;
};

// Plain code, testable without Prime.
Obstacle nearest(const Scan& scan) {
  Obstacle best{INFINITY, 0};
  for (std::size_t i = 0; i < scan.ranges.size(); ++i)
    if (scan.ranges[i] < best.distance) best = {scan.ranges[i], static_cast<float>(i)};
  return best;
}

const prime::shm::TopicQos kScanQos{.capacity = 16, .max_held = 4};

// The lidar process: a wall that drifts around the robot, 40 scans a second.
int lidar(const std::string& domain, std::chrono::seconds run_for) {
  prime::shm::Core shm{domain, {.participant = "lidar"}};
  auto scans = shm.publisher<Scan>("lidar/scan", kScanQos);
  const auto end = std::chrono::steady_clock::now() + run_for;
  for (int tick = 0; std::chrono::steady_clock::now() < end; ++tick) {
    auto scan = scans.loan();  // a slot in shared memory: written in place, never copied
    if (!scan) {
      std::fprintf(stderr, "lidar: %s\n", scan.error().describe().c_str());
      return 1;
    }
    (*scan)->frame = "laser";
    (*scan)->ranges.resize(360);
    const int wall = (tick * 3) % 360;
    for (int deg = 0; deg < 360; ++deg) {
      const int off = std::min(std::abs(deg - wall), 360 - std::abs(deg - wall));
      (*scan)->ranges[static_cast<std::size_t>(deg)] = 1.0f + 0.02f * static_cast<float>(off);
    }
    std::move(*scan).publish();
    std::this_thread::sleep_for(25ms);
  }
  return 0;
}

// The planner process: the topic is a source like any other.
int planner(const std::string& domain, std::chrono::seconds run_for) {
  prime::shm::Core shm{domain, {.participant = "planner"}};
  prime::liberty::Core local;
  auto scans = shm.subscribe<Scan>("lidar/scan", {}, kScanQos);
  // The chain takes the view, so it reads the scan where the lidar wrote it;
  // a chain taking Scan would get a copy.
  auto in_place = [](const prime::shm::View<Scan>& scan) { return nearest(*scan); };
  auto obstacle = prime::collector(local, scans | local.chain(in_place, "nearest"), prime::or_nothing);
  std::printf("topology:\n%s\n", obstacle.graph().text().c_str());

  int steered = 0;
  const auto end = std::chrono::steady_clock::now() + run_for;
  while (std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(50ms);
    const auto o = obstacle(prime::Token{});
    if (!o) continue;  // no scan yet: the lidar is still starting
    const float turn = o->bearing_deg < 180 ? -1.0f : 1.0f;  // steer away from it
    if (++steered % 10 == 0)
      std::printf("nearest obstacle %.2f m at %3.0f deg -> turn %+.0f\n", o->distance, o->bearing_deg, turn);
  }
  const auto registry = shm.registry();
  std::printf("registry: %zu participants, topic '%s' (%s) published %llu scans\n", registry.participants.size(),
              registry.topics.at(0).name.c_str(), registry.topics.at(0).type.c_str(),
              static_cast<unsigned long long>(registry.topics.at(0).published));
  std::printf("steered %d times\n", steered);
  return steered > 0 ? 0 : 1;
}

int main(int argc, char** argv) {
  const std::chrono::seconds run_for{argc > 1 ? std::atoi(argv[1]) : 3};
  const std::string domain = "shm-robot-" + std::to_string(::getpid());
  const pid_t child = ::fork();  // before any thread or segment exists
  if (child == 0) std::_Exit(lidar(domain, run_for + 1s));
  const int result = planner(domain, run_for);
  int status = 0;
  ::waitpid(child, &status, 0);
  return result != 0 ? result : (WIFEXITED(status) ? WEXITSTATUS(status) : 1);
}
