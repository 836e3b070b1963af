#include "child_process.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <system_error>
#include <thread>

#include "unique_fd.hpp"

namespace prime::bench::ipc {

namespace {

[[noreturn]] void fail_in_child(int report_fd) {
  const int error = errno;
  [[maybe_unused]] const auto written = ::write(report_fd, &error, sizeof error);
  ::_exit(127);
}

}  // namespace

ChildProcess::ChildProcess(std::string path, const std::vector<std::string>& argv, const Options& options) {
  // Everything the child needs is prepared here: between fork and exec only
  // async-signal-safe calls are allowed (this process may have threads).
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);

  const int output = options.output_fd;
  int report[2];
  if (::pipe2(report, O_CLOEXEC) != 0) throw std::system_error{errno, std::generic_category(), "pipe2"};
  UniqueFd report_read{report[0]};
  UniqueFd report_write{report[1]};

  const pid_t parent = ::getpid();
  pid_ = ::fork();
  if (pid_ < 0) throw std::system_error{errno, std::generic_category(), "fork"};
  if (pid_ == 0) {
    if (::prctl(PR_SET_PDEATHSIG, SIGKILL) != 0 || ::getppid() != parent) ::_exit(126);
    for (int fd : options.inherit_fds)
      if (::fcntl(fd, F_SETFD, 0) != 0) fail_in_child(report[1]);
    if (output >= 0 && (::dup2(output, STDOUT_FILENO) < 0 || ::dup2(output, STDERR_FILENO) < 0))
      fail_in_child(report[1]);
    if (options.cpus && ::sched_setaffinity(0, sizeof(cpu_set_t), &*options.cpus) != 0) fail_in_child(report[1]);
    ::execv(path.c_str(), args.data());
    fail_in_child(report[1]);
  }

  report_write = UniqueFd{};
  int error = 0;
  ssize_t n;
  do n = ::read(report_read.get(), &error, sizeof error);
  while (n < 0 && errno == EINTR);
  if (n > 0) {
    wait_for(std::chrono::seconds{1});
    throw std::system_error{error, std::generic_category(), "starting " + path};
  }
}

ChildProcess::~ChildProcess() {
  if (pid_ <= 0 || status_) return;
  ::kill(pid_, SIGKILL);
  int status = 0;
  while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
  }
}

std::optional<int> ChildProcess::poll() {
  if (status_ || pid_ <= 0) return status_;
  int status = 0;
  const pid_t r = ::waitpid(pid_, &status, WNOHANG);
  if (r == pid_) status_ = status;
  else if (r < 0 && errno != EINTR) status_ = W_EXITCODE(255, 0);  // not ours any more: treat as gone
  return status_;
}

std::optional<int> ChildProcess::wait_for(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!poll() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds{1});
  return status_;
}

void ChildProcess::signal(int sig) const {
  if (pid_ > 0 && !status_) ::kill(pid_, sig);
}

std::string ChildProcess::describe(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status))
    return "was killed by signal " + std::to_string(WTERMSIG(status)) + " (" + ::strsignal(WTERMSIG(status)) + ")";
  return "ended with wait status " + std::to_string(status);
}

}  // namespace prime::bench::ipc
