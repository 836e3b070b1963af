#pragma once

// Runs a benchmark binary as a child process: its output captured, or
// appended to a log; ended with SIGKILL if it runs past a deadline.

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace prime::tool::bench {

struct Finished {
  int status = 0;          // the exit code, or 128 + the signal that ended it
  bool timed_out = false;  // it was killed at the deadline
  std::string output;      // stdout, when captured
};

// Runs `argv`; stdout and stderr go to `log` (appended), or, with no log,
// stdout is captured and stderr dropped. `tick` is called about ten times a
// second while it runs (progress); `stop` ends it early when it returns true.
inline Finished run_program(const std::vector<std::string>& argv, const std::optional<std::filesystem::path>& log,
                            std::chrono::seconds deadline, const std::function<void()>& tick = {},
                            const std::function<bool()>& stop = {}) {
  int fds[2] = {-1, -1};
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (log) {
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log->c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  } else {
    if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error{"pipe failed"};
    posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, "/dev/null", O_WRONLY, 0);
  }
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = -1;
  const int failed = ::posix_spawn(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (fds[1] >= 0) ::close(fds[1]);
  if (failed != 0) {
    if (fds[0] >= 0) ::close(fds[0]);
    throw std::runtime_error{"cannot start " + argv[0] + ": " + std::strerror(failed)};
  }

  Finished done;
  if (fds[0] >= 0) ::fcntl(fds[0], F_SETFL, O_NONBLOCK);
  const auto end = std::chrono::steady_clock::now() + deadline;
  int status = 0;
  for (int polls = 0;; ++polls) {
    if (fds[0] >= 0) {
      char buffer[4096];
      for (ssize_t n; (n = ::read(fds[0], buffer, sizeof buffer)) > 0;) done.output.append(buffer, static_cast<std::size_t>(n));
    }
    if (::waitpid(pid, &status, WNOHANG) == pid) break;
    if (std::chrono::steady_clock::now() > end || (stop && stop())) {
      done.timed_out = std::chrono::steady_clock::now() > end;
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      break;
    }
    if (tick && polls % 10 == 0) tick();
    std::this_thread::sleep_for(std::chrono::milliseconds{10});
  }
  if (fds[0] >= 0) {
    char buffer[4096];
    for (ssize_t n; (n = ::read(fds[0], buffer, sizeof buffer)) > 0;) done.output.append(buffer, static_cast<std::size_t>(n));
    ::close(fds[0]);
  }
  done.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return done;
}

// Whether `program` is on the PATH.
inline bool on_path(const std::string& program) {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::string all = path;
  for (std::size_t from = 0; from <= all.size();) {
    const auto colon = std::min(all.find(':', from), all.size());
    const std::filesystem::path candidate = std::filesystem::path{all.substr(from, colon - from)} / program;
    if (::access(candidate.c_str(), X_OK) == 0) return true;
    from = colon + 1;
  }
  return false;
}

}  // namespace prime::tool::bench
