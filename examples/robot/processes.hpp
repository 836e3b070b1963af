#pragma once

// The three processes of the split robot; each runs until `stop` (set by
// SIGTERM or SIGINT) or for `seconds`.

#include <atomic>
#include <chrono>
#include <string>

namespace robot {

int sensors(const std::string& domain, const std::atomic<bool>& stop);
// How the planner runs its chain: in a periodic loop, or on each synchronised set.
enum class Trigger { periodic, event };

int planner(const std::string& domain, Trigger trigger, const std::atomic<bool>& stop);
int driver(const std::string& domain, const std::atomic<bool>& stop);

}  // namespace robot
