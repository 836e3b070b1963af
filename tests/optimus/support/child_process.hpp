#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace prime::test {

// An owned file descriptor.
class UniqueFd {
 public:
  UniqueFd() = default;
  explicit UniqueFd(int fd) : fd_{fd} {}
  UniqueFd(UniqueFd&& other) noexcept : fd_{std::exchange(other.fd_, -1)} {}
  UniqueFd& operator=(UniqueFd&& other) noexcept {
    if (this != &other) {
      reset();
      fd_ = std::exchange(other.fd_, -1);
    }
    return *this;
  }
  ~UniqueFd() { reset(); }
  void reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  [[nodiscard]] int get() const noexcept { return fd_; }

 private:
  int fd_ = -1;
};

// A program started with fork and exec, its stdin and stdout on pipes. It is
// sent SIGKILL if the thread that started it ends (PR_SET_PDEATHSIG), so no server or service
// outlives a test that crashed. Destroying the handle closes stdin, sends
// SIGTERM, and after a grace period SIGKILL; it always reaps.
class ChildProcess {
 public:
  // `stderr_path`: where the child's stderr goes (empty: inherit ours).
  explicit ChildProcess(std::vector<std::string> argv, const std::string& stderr_path = {}) {
    int in[2], out[2];
    if (::pipe2(in, O_CLOEXEC) != 0 || ::pipe2(out, O_CLOEXEC) != 0) throw std::runtime_error{"pipe2 failed"};
    stdin_ = UniqueFd{in[1]};
    stdout_ = UniqueFd{out[0]};
    UniqueFd child_in{in[0]}, child_out{out[1]};
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    // fork + exec rather than posix_spawn, for PR_SET_PDEATHSIG. Between fork
    // and exec only async-signal-safe calls. The death signal comes when the
    // *thread* that forked ends, not the process: start a child on a thread
    // that outlives it.
    const int err_fd = stderr_path.empty() ? -1 : ::open(stderr_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    const pid_t parent = ::getpid();
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error{"fork failed"};
    if (pid_ == 0) {
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (::getppid() != parent) ::_exit(127);
      ::dup2(child_in.get(), 0);
      ::dup2(child_out.get(), 1);
      if (err_fd >= 0) ::dup2(err_fd, 2);
      ::execvp(args[0], args.data());
      ::_exit(127);
    }
    if (err_fd >= 0) ::close(err_fd);
    name_ = argv[0];
  }
  ChildProcess(ChildProcess&& other) noexcept
      : pid_{std::exchange(other.pid_, -1)},
        stdin_{std::move(other.stdin_)},
        stdout_{std::move(other.stdout_)},
        buffer_{std::move(other.buffer_)},
        name_{std::move(other.name_)} {}
  ChildProcess& operator=(ChildProcess&&) = delete;
  ~ChildProcess() { stop(); }

  [[nodiscard]] pid_t pid() const noexcept { return pid_; }
  [[nodiscard]] bool running() const noexcept { return pid_ > 0; }

  // The next line the child writes to stdout, waiting no longer than `timeout`.
  std::optional<std::string> read_line(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      if (const auto nl = buffer_.find('\n'); nl != std::string::npos) {
        std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        return line;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      pollfd p{stdout_.get(), POLLIN, 0};
      const int ready = ::poll(&p, 1, static_cast<int>(left.count()));
      if (ready < 0 && errno == EINTR) continue;
      if (ready <= 0) return std::nullopt;
      char chunk[512];
      const auto n = ::read(stdout_.get(), chunk, sizeof chunk);
      if (n <= 0) return std::nullopt;  // the child closed stdout (exited)
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }

  // Waits for a line equal to `expected`, skipping others.
  bool wait_for_line(const std::string& expected, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return false;
      auto line = read_line(left);
      if (!line) return false;
      if (*line == expected) return true;
    }
  }

  void send_line(const std::string& line) {
    const std::string text = line + "\n";
    (void)!::write(stdin_.get(), text.data(), text.size());
  }

  // kill -9, and reap.
  void kill() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGKILL);
    reap(std::chrono::seconds{10});
  }

  // Closes stdin and asks politely; SIGKILL if the child is still there after the grace period.
  int stop(std::chrono::milliseconds grace = std::chrono::milliseconds{5000}) {
    if (pid_ <= 0) return status_;
    stdin_.reset();
    ::kill(pid_, SIGTERM);
    if (!reap(grace)) {
      ::kill(pid_, SIGKILL);
      reap(std::chrono::seconds{10});
    }
    return status_;
  }

 private:
  bool reap(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      int status = 0;
      const pid_t r = ::waitpid(pid_, &status, WNOHANG);
      if (r == pid_ || (r < 0 && errno == ECHILD)) {
        status_ = status;
        pid_ = -1;
        return true;
      }
      if (std::chrono::steady_clock::now() >= deadline) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds{2});  // waitpid has no timeout
    }
  }

  pid_t pid_ = -1;
  int status_ = 0;
  UniqueFd stdin_;
  UniqueFd stdout_;
  std::string buffer_;
  std::string name_;
};

}  // namespace prime::test
