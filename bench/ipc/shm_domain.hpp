#pragma once

#include <unistd.h>

#include <atomic>
#include <string>

namespace prime::bench::ipc {

// A Prime shared-memory domain no other benchmark run uses.
inline std::string new_shm_domain() {
  static std::atomic<int> next{0};
  return "prime-ipc-" + std::to_string(::getpid()) + "-" + std::to_string(next++);
}

}  // namespace prime::bench::ipc
