#pragma once

#include <chrono>

namespace prime {

// Every asynchronous value carries the time it was taken. Sources keep it as
// data flows through linked chains, so `sync` can align streams by when the
// sensor saw the world, not by when a thread happened to run.
using Clock = std::chrono::steady_clock;

template <class T>
struct Sample {
  T value;
  Clock::time_point stamp;
};

}  // namespace prime
