// A robot split into three processes over shared memory, started together:
//
//   process "sensors"                 process "planner"                                   process "driver"
//   lidar 40 Hz ──loan──> sensors/lidar ─┐
//                                        ├─> sync ──> collector ──> localize | plan | control ──call──> driver/command
//   odom 100 Hz ──loan──> sensors/odom ──┘   (by stamp)  (50 Hz)                            (service)      │ motors
//        ▲                                                                                                 ▼
//        └──────────────────────────────────── driver/state (100 Hz) ────────────────────────── robot's true state
//
// It prints each process's rates and the latency from a sensor's stamp to
// the command applied at the motors. Part way through it kills the planner
// with SIGKILL and restarts it: the driver holds the robot safe meanwhile,
// and the system recovers.
//
//   robot [seconds] [--event]   (default 12 s; Ctrl-C stops it early). The planner runs
//                               its chain in a 50 Hz loop on the newest synchronised pair,
//                               or with --event on each pair as soon as it is made.
//   robot sensors|planner|driver <domain> [--event]   one process, as the launcher starts it
//
// While it runs, another terminal sees it: `prime ls`, `prime hz sensors/lidar`,
// `prime echo driver/stats`, `prime graph`.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "messages.hpp"
#include "prime/shm.hpp"
#include "processes.hpp"

extern char** environ;

namespace {

using namespace std::chrono_literals;

std::atomic<bool> stop{false};

robot::Trigger trigger = robot::Trigger::periodic;

pid_t start(const std::string& role, const std::string& domain) {
  std::string self = "/proc/self/exe";
  std::vector<std::string> args{"robot", role, domain};
  if (role == "planner" && trigger == robot::Trigger::event) args.push_back("--event");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (posix_spawn(&pid, self.c_str(), nullptr, nullptr, argv.data(), environ) != 0) {
    std::perror(("robot: cannot start the " + role).c_str());
    std::exit(1);
  }
  return pid;
}

// Figures of one phase of the run, from the driver's reports.
struct Phase {
  std::uint32_t commands = 0;
  double mean_ms = 0, p99_ms = 0, max_ms = 0;
  int seconds = 0;
  void add(const robot::DriverStats& s) {
    if (s.commands == 0) return;
    mean_ms = (mean_ms * commands + s.mean_ms * s.commands) / (commands + s.commands);
    commands += s.commands;
    p99_ms = std::max(p99_ms, s.p99_ms);
    max_ms = std::max(max_ms, s.max_ms);
    ++seconds;
  }
};

int launch(int seconds) {
  const char* env = std::getenv("PRIME_DOMAIN");
  const std::string domain = env && *env ? env : "robot";
  std::printf("[robot] domain '%s': sensors, planner (%s) and driver start; %d s; the planner is killed at %d s\n",
              domain.c_str(), trigger == robot::Trigger::event ? "on each synchronised pair" : "50 Hz loop", seconds,
              seconds / 3);
  std::fflush(stdout);
  prime::shm::Core shm{domain, {.participant = "launcher"}};
  auto stats = shm.subscribe<robot::DriverStats>("driver/stats", {.spin = 0us}, {.capacity = 8}).subscribe();
  const pid_t driver = start("driver", domain);
  const pid_t sensors = start("sensors", domain);
  pid_t planner = start("planner", domain);
  const auto t0 = prime::Clock::now();
  const auto kill_at = t0 + std::chrono::seconds{seconds / 3};
  std::optional<prime::Clock::time_point> killed, restarted;
  Phase before, after;
  int safe_reports = 0;
  bool recovered = false;
  while (!stop && prime::Clock::now() - t0 < std::chrono::seconds{seconds}) {
    if (auto s = stats.read_for(100ms)) {
      const auto& report = *s->value;
      if (!killed) before.add(report);
      else if (restarted && prime::Clock::now() - *restarted > 1500ms) after.add(report);
      if (killed && report.safe_stop) ++safe_reports;
      if (restarted && report.commands > 0 && !report.safe_stop) recovered = true;
    }
    const auto now = prime::Clock::now();
    if (!killed && now >= kill_at) {
      kill(planner, SIGKILL);
      waitpid(planner, nullptr, 0);
      killed = now;
      std::printf("[robot] killed the planner (SIGKILL) at %.1f s\n", std::chrono::duration<double>(now - t0).count());
      std::fflush(stdout);
    }
    if (killed && !restarted && now - *killed >= 1s) {
      planner = start("planner", domain);
      restarted = now;
      std::printf("[robot] restarted the planner at %.1f s\n", std::chrono::duration<double>(now - t0).count());
      std::fflush(stdout);
    }
  }
  for (pid_t p : {planner, sensors, driver}) {  // the planner first: it calls the driver
    kill(p, SIGTERM);
    waitpid(p, nullptr, 0);
  }
  std::printf("\n[robot] sensor stamp to motors, before the kill: %u commands, mean %.2f ms, p99 %.2f ms, max %.2f ms\n",
              before.commands, before.mean_ms, before.p99_ms, before.max_ms);
  std::printf("[robot] after the restart: %u commands, mean %.2f ms, p99 %.2f ms, max %.2f ms\n", after.commands,
              after.mean_ms, after.p99_ms, after.max_ms);
  std::printf("[robot] the driver held the robot safe while the planner was down (%d reports); %s\n", safe_reports,
              recovered ? "recovered: the restarted planner drives it again" : "NOT RECOVERED");
  return recovered ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  struct sigaction on_stop {};
  on_stop.sa_handler = [](int) { stop = true; };
  sigaction(SIGINT, &on_stop, nullptr);
  sigaction(SIGTERM, &on_stop, nullptr);
  std::vector<std::string> args(argv + 1, argv + argc);
  if (!args.empty() && args.back() == "--event") {
    trigger = robot::Trigger::event;
    args.pop_back();
  }
  if (args.size() == 2) {
    const std::string& role = args[0];
    try {
      if (role == "sensors") return robot::sensors(args[1], stop);
      if (role == "planner") return robot::planner(args[1], trigger, stop);
      if (role == "driver") return robot::driver(args[1], stop);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "[%s] %s\n", role.c_str(), e.what());
      return 1;
    }
  }
  if (args.size() > 1) {
    std::fprintf(stderr, "usage: robot [seconds] [--event]\n");
    return 2;
  }
  return launch(args.size() == 1 ? std::atoi(args[0].c_str()) : 12);
}
