#pragma once

// `prime hz`, `bw` and `delay` on any medium: what they keep of each
// sample, when they report and what they print. A medium only says how its
// next sample comes.

#include <cstddef>
#include <functional>
#include <optional>
#include <string>

#include "prime/logic/sample.hpp"
#include "shm_commands.hpp"

namespace prime::tool {

// A sample as these commands see it.
struct Arrival {
  std::size_t size = 0;
  std::optional<Clock::time_point> stamp{};  // its sensor's; none in a foreign one (delay passes it over)
};

// The next sample within `timeout`, or nothing.
using NextSample = std::function<std::optional<Arrival>(Clock::duration timeout)>;

// Runs `command` (hz, bw or delay) on the samples `next` gives until the
// duration, the count or Ctrl-C: a report every second and one at the end
// (a second with nothing new says so, instead of repeating figures about
// samples long gone). kOk, or kNothing when no sample came.
int watch(const Options& o, const std::string& command, const NextSample& next);

}  // namespace prime::tool
