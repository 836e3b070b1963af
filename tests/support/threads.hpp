#pragma once

#include <sys/types.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

namespace prime::test {

// What /proc says thread `tid` of this process is doing: 'R' running,
// 'S' asleep in the kernel (a futex, a condition variable, a socket), ...
inline char thread_state(pid_t tid) {
  std::ifstream stat{"/proc/self/task/" + std::to_string(tid) + "/stat"};
  std::string line;
  if (!std::getline(stat, line)) return '?';
  const auto close = line.rfind(')');
  return close != std::string::npos && close + 2 < line.size() ? line[close + 2] : '?';
}

// Whether thread `tid` is asleep within `timeout`: a reader blocked in its
// read, a worker waiting for room. What a test waits for before it wakes
// one, instead of sleeping and hoping the other thread got there.
inline bool asleep_within(pid_t tid, std::chrono::milliseconds timeout = std::chrono::seconds{10}) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (thread_state(tid) != 'S') {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::yield();
  }
  return true;
}

// Whether every other thread of this process is asleep within `timeout`.
inline bool others_asleep_within(std::chrono::milliseconds timeout = std::chrono::seconds{10}) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  const auto me = ::gettid();
  while (true) {
    bool all = true;
    for (const auto& task : std::filesystem::directory_iterator{"/proc/self/task"}) {
      const auto tid = static_cast<pid_t>(std::stoi(task.path().filename().string()));
      if (tid != me && thread_state(tid) != 'S') all = false;
    }
    if (all) return true;
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::yield();
  }
}

}  // namespace prime::test
