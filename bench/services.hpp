#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace prime::bench {

// The message of the paper's Table 1: a counter each service bumps, and a
// payload that rides along. In-process media move it, so the payload size
// shows whether anything copies it.
struct Message {
  std::uint64_t counter = 0;
  std::vector<std::byte> payload;
};

[[nodiscard]] inline Message make_message(std::size_t bytes) { return {0, std::vector<std::byte>(bytes)}; }

// The trivial service of every hop. Defined in services.cpp, out of sight of
// the benchmarks, as a user's algorithm living in its own library would be:
// the optimiser cannot fold a hundred calls to it into one `counter += 100`.
[[nodiscard]] Message add(Message m);

}  // namespace prime::bench
