#pragma once

#include <sched.h>
#include <sys/types.h>

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace prime::bench::ipc {

// A process this one started, always reaped: the destructor kills a child that
// is still running (SIGKILL) and waits for it. The child also gets SIGKILL if
// this process dies first, so nothing outlives a crashed benchmark.
class ChildProcess {
 public:
  struct Options {
    std::vector<int> inherit_fds;      // stay open in the child, at the same numbers
    std::optional<cpu_set_t> cpus;     // the child's CPU affinity; unset: this process's
    int output_fd = -1;                // becomes the child's stdout and stderr; -1: this process's
  };

  // Forks and execs `argv[0]` with `argv`. Throws std::system_error if the
  // exec fails (reported back through a close-on-exec pipe).
  ChildProcess(std::string path, const std::vector<std::string>& argv, const Options& options);
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;
  ~ChildProcess();

  [[nodiscard]] pid_t pid() const noexcept { return pid_; }

  // The wait status once the child has ended (reaping it), nullopt while it runs.
  std::optional<int> poll();
  // As poll(), but waits up to `timeout` for the child to end.
  std::optional<int> wait_for(std::chrono::milliseconds timeout);
  void signal(int sig) const;

  // "exited with status 1", "was killed by signal 9 (Killed)".
  [[nodiscard]] static std::string describe(int status);

 private:
  pid_t pid_ = -1;
  std::optional<int> status_;
};

}  // namespace prime::bench::ipc
