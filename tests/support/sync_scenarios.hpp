#pragma once

// The sync scenarios every medium must agree on: the conformance suite plays
// them in one process, tests/shm across a real one. Every value is its own
// stamp, in milliseconds after the scenario's start, so a set shows which
// values it paired and its stamps can be checked against them.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <optional>
#include <tuple>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"

namespace prime::test {

struct SyncScenario {
  std::vector<int> odom;                    // published first
  std::vector<int> lidar;                   // then these
  std::vector<std::tuple<int, int>> sets;   // (lidar, odom): exactly these, in order, then no more
};

// Equal stamps only; the scan at 25 ms has no partner.
inline const SyncScenario kExactTimeScenario{{0, 10, 20, 30, 40, 50}, {10, 25, 40}, {{10, 10}, {40, 40}}};
// within_tolerance(3ms): only 21 and 20 lie within it.
inline const SyncScenario kWithinToleranceScenario{{0, 20}, {21, 50}, {{21, 20}}};
// approximate_time(): odometry every 10 ms, scans at 3, 24 and 47: each
// scan's best partner is the odometry nearest it. Then 100 and 101; 200
// and 201 only show that nothing nearer 100 and 101 is coming.
inline const SyncScenario kApproximateTimeScenario{
    {0, 10, 20, 30, 40, 50, 101, 201}, {3, 24, 47, 100, 200}, {{3, 0}, {24, 20}, {47, 50}, {100, 101}}};

// interpolate_at(lidar, odom, {.max_gap = 50ms}): odometry's value at each
// scan's stamp, or nothing (an error value) outside what odometry brackets.
struct InterpolationScenario {
  std::vector<int> odom{0, 10, 20, 100};
  std::vector<int> lidar{-5, 5, 12, 60};
  std::chrono::milliseconds max_gap{50};
  // Before the oldest odometry; halfway between 0 and 10; between 10 and
  // 20; between 20 and 100, too far apart.
  std::vector<std::pair<int, std::optional<double>>> sets{{-5, std::nullopt}, {5, 5.0}, {12, 12.0}, {60, std::nullopt}};
};

inline Clock::time_point at(Clock::time_point t0, int ms) { return t0 + std::chrono::milliseconds{ms}; }

// Publishes `s` through `emit(input, ms)` (0: lidar, 1: odom) and checks
// what `reader` (a reader of the sync of lidar and odom) gives.
template <class Emit, class Reader>
void play(const SyncScenario& s, Clock::time_point t0, Emit&& emit, Reader& reader) {
  for (const int ms : s.odom) emit(1, ms);
  for (const int ms : s.lidar) emit(0, ms);
  std::vector<std::tuple<int, int>> sets;
  for (std::size_t i = 0; i < s.sets.size(); ++i) {
    auto set = reader.read_for(std::chrono::seconds{5});
    ASSERT_TRUE(set) << "set " << i << ": " << set.error().describe();
    const int lidar = std::get<0>(set->value), odom = std::get<1>(set->value);
    sets.emplace_back(lidar, odom);
    EXPECT_EQ(set->value.template stamp<0>(), at(t0, lidar)) << "each part keeps its stamp";
    EXPECT_EQ(set->value.template stamp<1>(), at(t0, odom));
    EXPECT_EQ(set->stamp, at(t0, std::max(lidar, odom))) << "a set is stamped with its newest part";
  }
  EXPECT_EQ(sets, s.sets);
  EXPECT_FALSE(reader.read_for(std::chrono::milliseconds{20})) << "no further set";
}

template <class Emit, class Reader>
void play(const InterpolationScenario& s, Clock::time_point t0, Emit&& emit, Reader& reader) {
  for (const int ms : s.odom) emit(1, ms);
  for (const int ms : s.lidar) emit(0, ms);
  std::vector<std::pair<int, std::optional<double>>> got;
  for (std::size_t i = 0; i < s.sets.size(); ++i) {
    auto set = reader.read_for(std::chrono::seconds{5});
    ASSERT_TRUE(set) << "set " << i << ": " << set.error().describe();
    const auto& [scan, pose] = set->value;
    got.emplace_back(scan, pose ? std::optional<double>{*pose} : std::nullopt);
    if (!pose) {
      EXPECT_EQ(pose.error().code, Errc::no_data) << pose.error().message;
    }
    EXPECT_EQ(set->stamp, at(t0, scan)) << "a set is stamped with its trigger";
  }
  EXPECT_EQ(got, s.sets);
}

}  // namespace prime::test
