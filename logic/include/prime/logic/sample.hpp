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

// The time `wait` after `now`: Clock::time_point::max() for a wait longer
// than the clock has left (a "forever" such as milliseconds::max(), which
// added as it is would overflow into the past and end the wait at once).
template <class Rep, class Period>
[[nodiscard]] Clock::time_point deadline_after(std::chrono::duration<Rep, Period> wait, Clock::time_point now = Clock::now()) {
  const std::chrono::duration<double> left = Clock::time_point::max() - now;
  if (std::chrono::duration<double>{wait} >= left) return Clock::time_point::max();
  return now + std::chrono::duration_cast<Clock::duration>(wait);
}

// `d` in units of `To`, held to To's range: a "forever" such as
// milliseconds::max() stays the longest `To` (in nanoseconds, it would
// overflow to a negative wait).
template <class To, class Rep, class Period>
[[nodiscard]] constexpr To saturating_cast(std::chrono::duration<Rep, Period> d) {
  using Wide = std::chrono::duration<double, typename To::period>;
  const Wide wide = d;
  if (wide >= Wide{To::max()}) return To::max();
  if (wide <= Wide{To::min()}) return To::min();
  return std::chrono::duration_cast<To>(d);
}

}  // namespace prime
