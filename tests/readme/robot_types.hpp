// What the README's first example takes as given: the robot's message types.
#pragma once

#include <iostream>

struct Scan {};
struct Pose {};
struct Path {};

inline void follow(const Path&) {}
