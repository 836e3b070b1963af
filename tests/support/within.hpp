#pragma once

#include <chrono>
#include <thread>

namespace prime::test {

// Whether `condition` holds within `timeout`: a poll of state another
// thread or process changes (who sleeps, where a cursor stands, what a
// worker did), never a sleep standing in for it.
template <class Condition>
bool within(std::chrono::milliseconds timeout, Condition condition) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!condition()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::yield();
  }
  return true;
}

}  // namespace prime::test
