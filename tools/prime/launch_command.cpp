#include "launch_command.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <functional>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "prime/system/system_file.hpp"
#include "shm_commands.hpp"

extern char** environ;

namespace prime::tool {

namespace {

using Steady = std::chrono::steady_clock;
using namespace std::chrono_literals;

volatile std::sig_atomic_t stop_asked = 0;

// A pipe whose ends are above the standard descriptors and close on exec;
// the child's copies are made by dup2, which clears that.
std::pair<int, int> make_pipe() {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error{std::string{"cannot make a pipe: "} + std::strerror(errno)};
  for (int& fd : fds) {
    const int high = ::fcntl(fd, F_DUPFD_CLOEXEC, 10);
    ::close(fd);
    fd = high;
  }
  return {fds[0], fds[1]};
}

constexpr int kReadyFd = 3;  // where a child finds its readiness pipe (PRIME_READY_FD)

// One process of the placement, as the launcher runs it.
struct Child {
  system::ProcessSpec spec;
  std::string executable;
  pid_t pid = -1;
  int out = -1, err = -1, ready = -1;
  std::string out_buffer, err_buffer;
  bool is_ready = false;
  Steady::time_point started{};
  int restarts = 0;
  std::optional<Steady::time_point> restart_at{};
  std::optional<int> last_code{};  // of its last run: exit code, or 128 + signal
  bool done = false;               // ended, and not to be restarted
};

std::vector<std::string> arguments(const Child& c, const LaunchOptions& o, const std::string& placement) {
  std::vector<std::string> args{c.executable, "--prime-system", o.file, "--placement", placement, "--process", c.spec.name};
  for (const auto& p : o.params) args.insert(args.end(), {"--param", p});
  if (!o.domain.empty()) args.insert(args.end(), {"--domain", o.domain});
  if (!o.ns.empty()) args.insert(args.end(), {"--namespace", o.ns});
  return args;
}

pid_t spawn(const std::vector<std::string>& args, int out, int err, int ready) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, out, STDOUT_FILENO);
  posix_spawn_file_actions_adddup2(&actions, err, STDERR_FILENO);
  if (ready >= 0) posix_spawn_file_actions_adddup2(&actions, ready, kReadyFd);
  posix_spawnattr_t attributes;
  posix_spawnattr_init(&attributes);
  // Its own process group: Ctrl-C at the terminal reaches the launcher
  // only, which stops each process itself (SIGTERM, then SIGKILL).
  posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  posix_spawnattr_setpgroup(&attributes, 0);
  sigset_t none, defaults;
  sigemptyset(&none);
  posix_spawnattr_setsigmask(&attributes, &none);
  sigemptyset(&defaults);
  sigaddset(&defaults, SIGINT);
  sigaddset(&defaults, SIGTERM);
  sigaddset(&defaults, SIGPIPE);
  sigaddset(&defaults, SIGHUP);
  posix_spawnattr_setsigdefault(&attributes, &defaults);
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e)
    if (!std::string_view{*e}.starts_with("PRIME_READY_FD=")) env.emplace_back(*e);
  if (ready >= 0) env.push_back("PRIME_READY_FD=" + std::to_string(kReadyFd));
  std::vector<char*> argv, envp;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  for (const auto& e : env) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  pid_t pid = -1;
  const int failed = ::posix_spawnp(&pid, argv[0], &actions, &attributes, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attributes);
  if (failed != 0) throw std::runtime_error{"cannot start " + args[0] + ": " + std::strerror(failed)};
  return pid;
}

// Runs `args` to its end; its exit code, stdout and stderr.
struct Ran {
  int code;
  std::string out, err;
};
Ran run_to_end(const std::vector<std::string>& args) {
  auto [out_r, out_w] = make_pipe();
  auto [err_r, err_w] = make_pipe();
  const pid_t pid = spawn(args, out_w, err_w, -1);
  ::close(out_w);
  ::close(err_w);
  Ran ran{0, {}, {}};
  pollfd fds[2]{{out_r, POLLIN, 0}, {err_r, POLLIN, 0}};
  for (int open = 2; open > 0;) {
    if (::poll(fds, 2, -1) < 0 && errno != EINTR) break;
    for (int i = 0; i < 2; ++i) {
      if (fds[i].fd < 0 || !(fds[i].revents & (POLLIN | POLLHUP))) continue;
      char chunk[4096];
      const auto n = ::read(fds[i].fd, chunk, sizeof chunk);
      if (n > 0) (i == 0 ? ran.out : ran.err).append(chunk, static_cast<std::size_t>(n));
      else {
        ::close(fds[i].fd);
        fds[i].fd = -1;
        --open;
      }
    }
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ran.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return ran;
}

std::string describe_end(int status) {
  if (WIFEXITED(status)) return "exited with code " + std::to_string(WEXITSTATUS(status));
  return std::string{"was killed by signal "} + std::to_string(WTERMSIG(status)) + " (" + ::strsignal(WTERMSIG(status)) + ")";
}

class Launcher {
 public:
  Launcher(const LaunchOptions& o, std::string placement, std::vector<Child> children)
      : o_{o}, placement_{std::move(placement)}, children_{std::move(children)} {
    for (const auto& c : children_) width_ = std::max(width_, c.spec.name.size());
  }

  void say(const std::string& what) {
    std::printf("%-*s | %s\n", static_cast<int>(width_), "launch", what.c_str());
    std::fflush(stdout);
  }

  void start(Child& c) {
    auto [out_r, out_w] = make_pipe();
    auto [err_r, err_w] = make_pipe();
    auto [ready_r, ready_w] = make_pipe();
    try {
      c.pid = spawn(arguments(c, o_, placement_), out_w, err_w, ready_w);
    } catch (...) {
      for (int fd : {out_r, out_w, err_r, err_w, ready_r, ready_w}) ::close(fd);
      throw;
    }
    for (int fd : {out_w, err_w, ready_w}) ::close(fd);
    c.out = out_r;
    c.err = err_r;
    c.ready = ready_r;
    c.is_ready = false;
    c.started = Steady::now();
    c.restart_at.reset();
  }

  // Reads what the processes wrote, for up to `wait`; prints it line by
  // line, prefixed by the process's name.
  void pump(std::chrono::milliseconds wait) {
    std::vector<pollfd> fds;
    std::vector<std::pair<Child*, int>> whose;  // 0 out, 1 err, 2 ready
    for (auto& c : children_) {
      for (int which = 0; which < 3; ++which) {
        const int fd = which == 0 ? c.out : which == 1 ? c.err : c.ready;
        if (fd < 0) continue;
        fds.push_back({fd, POLLIN, 0});
        whose.emplace_back(&c, which);
      }
    }
    if (fds.empty()) {  // nothing to read (a restart's backoff): wait all the same, not spin
      ::poll(nullptr, 0, static_cast<int>(wait.count()));
      return;
    }
    if (::poll(fds.data(), fds.size(), static_cast<int>(wait.count())) <= 0) return;
    for (std::size_t i = 0; i < fds.size(); ++i) {
      if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      auto& [c, which] = whose[i];
      char chunk[4096];
      const auto n = ::read(fds[i].fd, chunk, sizeof chunk);
      int& fd = which == 0 ? c->out : which == 1 ? c->err : c->ready;
      if (which == 2) {
        if (n > 0 && std::string_view{chunk, static_cast<std::size_t>(n)}.starts_with("ready")) c->is_ready = true;
        ::close(fd);
        fd = -1;
        continue;
      }
      auto& buffer = which == 0 ? c->out_buffer : c->err_buffer;
      if (n > 0) buffer.append(chunk, static_cast<std::size_t>(n));
      else {
        ::close(fd);
        fd = -1;
        if (!buffer.empty()) buffer += '\n';
      }
      for (auto nl = buffer.find('\n'); nl != std::string::npos; nl = buffer.find('\n')) {
        std::fprintf(which == 0 ? stdout : stderr, "%-*s | %s\n", static_cast<int>(width_), c->spec.name.c_str(),
                     buffer.substr(0, nl).c_str());
        buffer.erase(0, nl + 1);
      }
      std::fflush(which == 0 ? stdout : stderr);
    }
  }

  // Reaps the processes that ended: true for each, with its status.
  void reap(const std::function<void(Child&, int)>& ended) {
    for (auto& c : children_) {
      if (c.pid <= 0) continue;
      int status = 0;
      if (::waitpid(c.pid, &status, WNOHANG) != c.pid) continue;
      c.pid = -1;
      c.last_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      ended(c, status);
    }
  }

  // Starts each process in `order`, the next once this one is ready.
  bool start_all(const std::vector<std::string>& order) {
    for (const auto& name : order) {
      auto& c = child(name);
      start(c);
      const auto deadline = Steady::now() + std::chrono::duration_cast<Steady::duration>(std::chrono::duration<double>{o_.ready_timeout});
      bool failed = false;
      while (!c.is_ready && !failed && !stop_asked) {
        pump(100ms);
        reap([&](Child& ended, int status) {
          say("'" + ended.spec.name + "' " + describe_end(status) + (ended.is_ready ? "" : " before it was ready"));
          failed = true;
        });
        if (Steady::now() > deadline) {
          say("'" + c.spec.name + "' was not ready within " + seconds(o_.ready_timeout));
          failed = true;
        }
      }
      if (failed || stop_asked) return false;
      say("'" + c.spec.name + "' is ready (pid " + std::to_string(c.pid) + ", machine " + c.spec.machine + ")");
    }
    return true;
  }

  // Supervises until Ctrl-C or until every process has ended for good.
  // Whether one failed.
  bool supervise() {
    bool failed = false;
    while (!stop_asked) {
      pump(100ms);
      reap([&](Child& c, int status) {
        const bool clean = c.last_code == 0;
        const bool again = c.spec.restart == system::Restart::always || (c.spec.restart == system::Restart::on_failure && !clean);
        if (!again) {
          c.done = true;
          if (!clean) failed = true;
          say("'" + c.spec.name + "' " + describe_end(status) + "; its restart policy is " + policy(c.spec.restart));
          return;
        }
        if (Steady::now() - c.started > 10s) c.restarts = 0;  // it ran long enough: the backoff starts over
        const auto backoff = std::chrono::milliseconds{500} * (1 << std::min(c.restarts, 4));
        ++c.restarts;
        c.restart_at = Steady::now() + backoff;
        say("'" + c.spec.name + "' " + describe_end(status) + "; restarting it in " + std::to_string(backoff.count()) + " ms (" +
            policy(c.spec.restart) + ")");
      });
      for (auto& c : children_) {
        if (c.pid > 0 || !c.restart_at || Steady::now() < *c.restart_at) continue;
        try {
          start(c);
          say("'" + c.spec.name + "' restarted (pid " + std::to_string(c.pid) + ")");
        } catch (const std::exception& e) {
          say("'" + c.spec.name + "': " + e.what());
          c.restart_at = Steady::now() + 5s;
        }
      }
      if (std::all_of(children_.begin(), children_.end(), [](const Child& c) { return c.done; })) {
        say("every process has ended");
        return failed;
      }
    }
    return failed;
  }

  // SIGTERM to each live process, SIGKILL to those still alive after the
  // grace time. Whether each ended by itself, with 0.
  bool stop_all() {
    bool clean = true;
    for (auto& c : children_)
      if (c.pid > 0) ::kill(c.pid, SIGTERM);
    const auto deadline = Steady::now() + std::chrono::duration_cast<Steady::duration>(std::chrono::duration<double>{o_.grace});
    const auto live = [&] { return std::any_of(children_.begin(), children_.end(), [](const Child& c) { return c.pid > 0; }); };
    while (live() && Steady::now() < deadline) {
      pump(50ms);
      reap([&](Child& c, int status) {
        if (c.last_code != 0) {
          clean = false;
          say("'" + c.spec.name + "' " + describe_end(status));
        }
      });
    }
    for (auto& c : children_) {
      if (c.pid <= 0) continue;
      ::kill(c.pid, SIGKILL);
      ::waitpid(c.pid, nullptr, 0);
      c.pid = -1;
      clean = false;
      say("'" + c.spec.name + "' did not stop within " + seconds(o_.grace) + " of SIGTERM: killed");
    }
    pump(0ms);
    return clean;
  }

  Child& child(const std::string& name) {
    return *std::find_if(children_.begin(), children_.end(), [&](const Child& c) { return c.spec.name == name; });
  }

 private:
  static std::string seconds(double s) {
    char text[32];
    std::snprintf(text, sizeof text, "%g s", s);
    return text;
  }
  static std::string policy(system::Restart r) {
    return r == system::Restart::never ? "never" : r == system::Restart::on_failure ? "on_failure" : "always";
  }

  const LaunchOptions& o_;
  std::string placement_;
  std::vector<Child> children_;
  std::size_t width_ = 6;
};

}  // namespace

int launch(const LaunchOptions& o) {
  const auto system = system::load_system(o.file, o.params);
  if (system.placements.empty()) throw std::invalid_argument{o.file + " has no placements"};
  const auto placement_name = o.placement.empty() ? system.placements.front().name : o.placement;
  const auto* placement = system.placement(placement_name);
  if (!placement) {
    std::string names;
    for (const auto& p : system.placements) names += (names.empty() ? "" : ", ") + p.name;
    throw std::invalid_argument{o.file + " has no placement '" + placement_name + "' (it has " + names + ")"};
  }
  const auto dir = std::filesystem::path{o.file}.parent_path();
  std::vector<Child> children;
  for (const auto& p : placement->processes) {
    Child c;
    c.spec = p;
    c.executable = !o.executable.empty() ? o.executable : !p.executable.empty() ? p.executable : system.executable;
    if (c.executable.empty())
      throw std::invalid_argument{o.file + ":" + std::to_string(p.line) + ": process '" + p.name +
                                  "' has no executable (give one in the file, or --executable)"};
    if (o.executable.empty() && c.executable.find('/') != std::string::npos && std::filesystem::path{c.executable}.is_relative())
      c.executable = std::filesystem::absolute(dir / c.executable).lexically_normal().string();  // beside the system file
    children.push_back(std::move(c));
  }

  // Checked before anything starts, by each program against the components
  // it has; the first gives the order.
  std::vector<std::string> order;
  std::set<std::string> checked;
  for (const auto& c : children) {
    if (!checked.insert(c.executable).second) continue;
    std::vector<std::string> args{c.executable, "--prime-check", o.file, "--placement", placement_name};
    for (const auto& p : o.params) args.insert(args.end(), {"--param", p});
    const auto ran = run_to_end(args);
    if (ran.code != 0) {
      std::fprintf(stderr, "%s", ran.err.c_str());
      std::fprintf(stderr, "prime: %s refused placement '%s' of %s (exit code %d): nothing was started\n", c.executable.c_str(),
                   placement_name.c_str(), o.file.c_str(), ran.code);
      return kUsage;
    }
    if (order.empty() && ran.out.starts_with("order:")) {
      std::string word;
      for (char ch : ran.out.substr(6)) {
        if (ch == ' ' || ch == '\n') {
          if (!word.empty()) order.push_back(std::exchange(word, {}));
        } else {
          word += ch;
        }
      }
    }
  }
  if (order.size() != children.size()) {
    order.clear();
    for (const auto& c : children) order.push_back(c.spec.name);
  }

  stop_asked = 0;
  struct sigaction on_stop {};
  on_stop.sa_handler = [](int) { stop_asked = 1; };
  sigemptyset(&on_stop.sa_mask);
  ::sigaction(SIGINT, &on_stop, nullptr);
  ::sigaction(SIGTERM, &on_stop, nullptr);
  ::sigaction(SIGHUP, &on_stop, nullptr);  // the terminal closed: stop them, do not leave them unsupervised
  ::signal(SIGPIPE, SIG_IGN);              // output piped into a reader that left: a failed write, not death

  Launcher launcher{o, placement_name, std::move(children)};
  std::string listed;
  for (const auto& name : order) listed += (listed.empty() ? "" : ", ") + name;
  launcher.say("placement '" + placement_name + "' of " + o.file + ": starting " + listed);
  bool failed = false;
  try {
    failed = !launcher.start_all(order) && !stop_asked;
    if (!failed && !stop_asked) {
      launcher.say("every process is ready; Ctrl-C stops them");
      failed = launcher.supervise();
    }
  } catch (const std::exception& e) {  // out of pipes or processes, say: stop what runs, then say so
    launcher.say(std::string{"failed: "} + e.what());
    failed = true;
  }
  const bool clean = launcher.stop_all();
  launcher.say(failed ? "stopped, after a failure" : clean ? "stopped" : "stopped, not every process cleanly");
  return failed || !clean ? kFailed : kOk;
}

}  // namespace prime::tool
