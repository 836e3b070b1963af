// The robot demo's planner chain on a recording the demo made
// (examples/robot/drive.mcap: 3 s of its lidar and odometry, taken with
// `prime record sensors/lidar sensors/odom`): replayed in one process, the
// same commands on every run; and the planner component itself, alone in a
// harness, fed the same recording.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/record/replay.hpp"
#include "prime/system.hpp"
#include "prime/topology.hpp"
#include "robot/components.hpp"
#include "robot/planning.hpp"

namespace {

using namespace std::chrono_literals;
using Sensed = prime::Synced<robot::Scan, robot::Odometry>;

std::vector<robot::MotorCommand> drive_once() {
  prime::liberty::Core core;
  prime::record::Replay replay{core, PRIME_ROBOT_RECORDING};
  // As the planner links them: sync, then localize | plan | control.
  auto sets = prime::sync(prime::approximate_time({.min_interval = {15ms, 5ms}}),
                          replay.source<robot::Scan>("sensors/lidar"), replay.source<robot::Odometry>("sensors/odom"));
  auto commands = sets | core.chain(robot::localize<Sensed>, "localize") | core.chain(robot::plan, "plan") |
                  core.chain(robot::control, "control");
  auto reader = commands.subscribe();
  replay.start();
  std::vector<robot::MotorCommand> out;
  const auto give_up = prime::Clock::now() + 20s;
  while (prime::Clock::now() < give_up) {
    if (auto c = reader.read_for(10ms)) {
      out.push_back(c->value);
    } else if (replay.finished()) {
      while (auto more = reader.try_read()) out.push_back(more->value);
      break;
    }
  }
  EXPECT_TRUE(replay.finished()) << "it waits for " << replay.waiting_for();
  core.stop();
  return out;
}

TEST(RobotReplay, ThePlannersChainOnTheDemosRecordingGivesTheSameCommandsOnEveryRun) {
  const auto first = drive_once();
  ASSERT_GE(first.size(), 110u) << "one command per scan (120), but for the last few";
  for (std::size_t i = 0; i < first.size(); ++i) {
    EXPECT_GE(first[i].speed, 0.0);
    EXPECT_LE(first[i].speed, 1.0);
    EXPECT_TRUE(std::isfinite(first[i].turn_rate));
    if (i > 0) EXPECT_GT(first[i].sensor_stamp_ns, first[i - 1].sensor_stamp_ns) << "in the scans' order";
  }
  for (int run = 0; run < 3; ++run) {
    const auto again = drive_once();
    ASSERT_EQ(again.size(), first.size()) << "run " << run;
    for (std::size_t i = 0; i < first.size(); ++i) {
      EXPECT_EQ(again[i].speed, first[i].speed);
      EXPECT_EQ(again[i].turn_rate, first[i].turn_rate);
      EXPECT_EQ(again[i].sensor_stamp_ns, first[i].sensor_stamp_ns);
    }
  }
}

// The planner component (run on each synchronised pair) with the recording
// fed into its two subscriptions and the test serving the driver's motors:
// what it calls the motors with, in order, once it has made `wanted`
// calls (or the replay is over and 20 s have passed).
std::vector<robot::MotorCommand> planner_on_recording(std::size_t wanted) {
  struct Calls {
    std::mutex mutex;
    std::condition_variable came;
    std::vector<robot::MotorCommand> commands;
  };
  auto calls = std::make_shared<Calls>();
  prime::system::Harness h{robot::planner(), {{"on_each_pair", true}}};
  prime::liberty::Core replaying;
  prime::record::Replay replay{replaying, PRIME_ROBOT_RECORDING};
  h.feed_from("sensors/lidar", replay.source<robot::Scan>("sensors/lidar"));
  h.feed_from("sensors/odom", replay.source<robot::Odometry>("sensors/odom"));
  h.serve<robot::MotorCommand, robot::Applied>("driver/command", [calls](const robot::MotorCommand& c) {
    {
      std::scoped_lock lock{calls->mutex};
      calls->commands.push_back(c);
    }
    calls->came.notify_all();
    return robot::Applied{.driving = c.speed > 0};
  });
  h.start();
  replay.start();
  const auto give_up = prime::Clock::now() + 20s;
  std::unique_lock lock{calls->mutex};
  while (!replay.finished() && prime::Clock::now() < give_up) calls->came.wait_for(lock, 10ms);
  EXPECT_TRUE(replay.finished()) << "it waits for " << replay.waiting_for();
  // Every set is made by now (the sync's output blocks, as the recording
  // does: none is dropped); the chain may still be calling with the last.
  calls->came.wait_until(lock, give_up, [&] { return calls->commands.size() >= wanted; });
  auto out = calls->commands;
  lock.unlock();
  h.stop();
  return out;
}

TEST(RobotReplay, ThePlannerComponentAloneOnTheRecordingCallsTheMotorsWithTheChainsCommands) {
  const auto chain = drive_once();
  ASSERT_GE(chain.size(), 110u);
  for (int run = 0; run < 2; ++run) {
    const auto component = planner_on_recording(chain.size());
    ASSERT_GE(component.size(), chain.size()) << "run " << run;
    for (std::size_t i = 0; i < chain.size(); ++i) {
      EXPECT_EQ(component[i].speed, chain[i].speed) << "command " << i;
      EXPECT_EQ(component[i].turn_rate, chain[i].turn_rate) << "command " << i;
      EXPECT_EQ(component[i].sensor_stamp_ns, chain[i].sensor_stamp_ns) << "command " << i;
    }
  }
}

}  // namespace
