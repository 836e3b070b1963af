#pragma once

#include <unistd.h>

#include <atomic>
#include <string>

namespace prime::test {

// A domain name no other test (or test process) uses.
inline std::string unique_domain(const std::string& what) {
  static std::atomic<int> made = 0;
  return "test-" + what + "-" + std::to_string(::getpid()) + "-" + std::to_string(made++);
}

}  // namespace prime::test
