#pragma once

#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <string>
#include <system_error>

namespace prime::test {

// A domain name no other test (or test process) uses.
inline std::string unique_domain(const std::string& what) {
  static std::atomic<int> made = 0;
  return "test-" + what + "-" + std::to_string(::getpid()) + "-" + std::to_string(made++);
}

// When the test program ends, what its domains left in /dev/shm goes: a
// peer killed with kill -9 leaves its segments, by design, for a look and
// `prime clean`, and a test machine should not fill up with them.
struct LeftoverSegments {
  ~LeftoverSegments() {
    const auto mine = "-" + std::to_string(::getpid()) + "-";
    std::error_code ignored;
    for (const auto& entry : std::filesystem::directory_iterator{"/dev/shm", ignored}) {
      const auto name = entry.path().filename().string();
      const auto domain_end = name.find('.', 6);  // prime.<domain>.<kind>.<name>
      if (!name.starts_with("prime.test-") || domain_end == std::string::npos) continue;
      if (name.substr(6, domain_end - 6).find(mine) != std::string::npos)  // unique_domain's, of this process
        std::filesystem::remove(entry.path(), ignored);
    }
  }
};
inline LeftoverSegments remove_leftover_segments_at_exit;

// How many segments of `domain` are in /dev/shm.
inline int segments_of(const std::string& domain) {
  int n = 0;
  for (const auto& entry : std::filesystem::directory_iterator{"/dev/shm"})
    n += entry.path().filename().string().starts_with("prime." + domain + ".") ? 1 : 0;
  return n;
}

}  // namespace prime::test
