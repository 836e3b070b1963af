#pragma once

#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <string>

namespace prime::test {

// A domain name no other test (or test process) uses.
inline std::string unique_domain(const std::string& what) {
  static std::atomic<int> made = 0;
  return "test-" + what + "-" + std::to_string(::getpid()) + "-" + std::to_string(made++);
}

// How many segments of `domain` are in /dev/shm.
inline int segments_of(const std::string& domain) {
  int n = 0;
  for (const auto& entry : std::filesystem::directory_iterator{"/dev/shm"})
    n += entry.path().filename().string().starts_with("prime." + domain + ".") ? 1 : 0;
  return n;
}

}  // namespace prime::test
