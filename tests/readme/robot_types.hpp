// What the front page's Liberty and Radiant examples take as given: the
// robot's message types.
#pragma once

#include <iostream>

struct Scan {};
struct Pose {};
struct Path {};
struct Command {};

inline void follow(const Path&) {}
