#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

extern char** environ;

namespace prime::test {

// The shm_peer program (or any command), started for real as another
// process, with its stdout read line by line. Killed and reaped on destruction.
class PeerProcess {
 public:
  // shm_peer with `args`.
  explicit PeerProcess(std::vector<std::string> args) : PeerProcess{with_peer(std::move(args)), 0} {}

  // Any command, found on the PATH: `{"unshare", "--pid", ..., SHM_PEER_PATH, ...}`;
  // `with_stderr`: what it writes to stderr is read too, mixed in.
  static PeerProcess command(std::vector<std::string> argv, bool with_stderr = false) {
    return PeerProcess{std::move(argv), with_stderr ? 1 : 0};
  }

  PeerProcess(PeerProcess&& other) noexcept
      : pid_{std::exchange(other.pid_, -1)}, code_{other.code_}, out_{std::exchange(other.out_, -1)},
        buffer_{std::move(other.buffer_)} {}

 private:
  static std::vector<std::string> with_peer(std::vector<std::string> args) {
    args.insert(args.begin(), SHM_PEER_PATH);
    return args;
  }

  PeerProcess(std::vector<std::string> args, int with_stderr) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error{"pipe failed"};
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
    if (with_stderr) posix_spawn_file_actions_adddup2(&actions, fds[1], STDERR_FILENO);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int failed = ::posix_spawnp(&pid_, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(fds[1]);
    out_ = fds[0];
    if (failed != 0) throw std::runtime_error{"cannot start " + args[0]};
  }

 public:
  PeerProcess(const PeerProcess&) = delete;
  PeerProcess& operator=(const PeerProcess&) = delete;
  ~PeerProcess() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (out_ >= 0) ::close(out_);
  }

  [[nodiscard]] pid_t pid() const noexcept { return pid_; }

  // Whether the peer printed `line` within `timeout`.
  bool says(const std::string& line, std::chrono::milliseconds timeout = std::chrono::seconds{30}) {
    return next_line_where([&](const std::string& got) { return got == line; }, timeout).has_value();
  }
  // The first line it prints that starts with `prefix`, within `timeout`.
  std::optional<std::string> line_starting(const std::string& prefix,
                                           std::chrono::milliseconds timeout = std::chrono::seconds{30}) {
    return next_line_where([&](const std::string& got) { return got.starts_with(prefix); }, timeout);
  }

  template <class Match>
  std::optional<std::string> next_line_where(Match match, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      if (auto nl = buffer_.find('\n'); nl != std::string::npos) {
        const auto got = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        if (match(got)) return got;
        continue;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      pollfd p{out_, POLLIN, 0};  // looks at least once, even with no time left
      if (::poll(&p, 1, static_cast<int>(std::max<long>(left.count(), 0))) <= 0) return std::nullopt;
      char chunk[256];
      const auto n = ::read(out_, chunk, sizeof chunk);
      if (n <= 0) return std::nullopt;  // it exited
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }

  // Everything it prints until it exits (within `timeout`).
  std::string all_output(std::chrono::milliseconds timeout = std::chrono::seconds{60}) {
    std::string all;
    while (auto line = next_line_where([](const std::string&) { return true; }, timeout)) all += *line + "\n";
    return all + buffer_;
  }

  void kill9() {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }

  // Its exit status once it ends (within `timeout`), or nothing.
  std::optional<int> exit_code(std::chrono::milliseconds timeout = std::chrono::seconds{60}) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      int status = 0;
      if (pid_ > 0 && ::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      if (code_ || std::chrono::steady_clock::now() >= deadline) return code_;
      ::usleep(1000);
    }
  }

 private:
  pid_t pid_ = -1;
  std::optional<int> code_;
  int out_ = -1;
  std::string buffer_;
};

}  // namespace prime::test
