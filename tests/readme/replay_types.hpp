// What docs/tool.md's replay example takes as given: two recorded message
// types and a plain function on a synchronised pair of them.
#pragma once

#include "prime/topology.hpp"

struct Scan {
  float wall_distance[4];
};
struct Odometry {
  double x, y, heading;
};
struct Path {
  double goal_x, goal_y;
};
inline Path plan(const prime::Synced<Scan, Odometry>&) { return {}; }
