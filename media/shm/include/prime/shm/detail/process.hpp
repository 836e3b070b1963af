#pragma once

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>

namespace prime::shm::detail {

// A process, told apart from a later one that reuses its pid: the pid (22
// bits, Linux's pid_max limit) with the process's start time in clock ticks
// since boot above it. One word, so a shared slot claims it with one CAS.
// Zero means "nobody".
using ProcessId = std::uint64_t;

inline constexpr int kPidBits = 22;

[[nodiscard]] inline std::uint32_t pid_of(ProcessId id) noexcept {
  return static_cast<std::uint32_t>(id & ((1u << kPidBits) - 1));
}

// Field 22 of /proc/<pid>/stat, or 0 when the process is gone.
[[nodiscard]] inline std::uint64_t start_time_of(std::uint32_t pid) {
  std::ifstream stat{"/proc/" + std::to_string(pid) + "/stat"};
  std::string line;
  if (!std::getline(stat, line)) return 0;
  const auto close = line.rfind(')');  // the command name may hold spaces and parentheses
  if (close == std::string::npos) return 0;
  std::istringstream fields{line.substr(close + 2)};
  std::string field;
  for (int i = 3; i <= 22 && fields >> field; ++i) {
    if (i == 22) return std::stoull(field);
  }
  return 0;
}

[[nodiscard]] inline ProcessId process_id(std::uint32_t pid) {
  return (start_time_of(pid) << kPidBits) | pid;
}

[[nodiscard]] inline ProcessId this_process() {
  // Not cached: a forked child is another process.
  return process_id(static_cast<std::uint32_t>(::getpid()));
}

// True while the process `id` names still runs (a zombie counts as gone).
[[nodiscard]] inline bool alive(ProcessId id) {
  if (id == 0) return false;
  const auto pid = pid_of(id);
  if (::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) return false;
  std::ifstream stat{"/proc/" + std::to_string(pid) + "/stat"};
  std::string line;
  if (!std::getline(stat, line)) return false;
  const auto close = line.rfind(')');
  if (close != std::string::npos && close + 2 < line.size() && line[close + 2] == 'Z') return false;
  return process_id(pid) == id;
}

}  // namespace prime::shm::detail
