// The robot demo: three components (sensors, planner, driver) placed by
// robot.yaml, started and supervised by `prime launch`.
//
//   process "sensors"                 process "planner"                                   process "driver"
//   lidar 40 Hz ────────> sensors/lidar ─┐
//                                        ├─> sync ──> collector ──> localize | plan | control ──call──> driver/command
//   odom 100 Hz ────────> sensors/odom ──┘   (by stamp)  (50 Hz)                            (service)      │ motors
//        ▲                                                                                                 ▼
//        └──────────────────────────────────── driver/state (100 Hz) ────────────────────────── robot's true state
//
// Run with no arguments, it launches a placement (`prime launch`, found on
// the PATH), prints each process's output and the latency from a sensor's
// stamp to the command applied at the motors, and part way through kills
// the planner's process with SIGKILL: the driver holds the robot safe
// meanwhile, the launcher restarts the planner (restart: on_failure), and
// the system recovers.
//
//   robot [seconds] [--placement one|split|machines] [--event]
//       default: 12 s, split (three processes); --event runs the planner's
//       chain on each synchronised pair instead of in its 50 Hz loop
//   robot --prime-system robot.yaml --placement P --process NAME
//       one process of a placement, as `prime launch` starts it
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
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "components.hpp"
#include "messages.hpp"
#include "prime/shm.hpp"

extern char** environ;

namespace {

using namespace std::chrono_literals;

std::atomic<bool> stop{false};

// Figures of one phase of the run, from the driver's reports.
struct Phase {
  std::uint32_t commands = 0;
  double mean_ms = 0, p99_ms = 0, max_ms = 0;
  void add(const robot::DriverStats& s) {
    if (s.commands == 0) return;
    mean_ms = (mean_ms * commands + s.mean_ms * s.commands) / (commands + s.commands);
    commands += s.commands;
    p99_ms = std::max(p99_ms, s.p99_ms);
    max_ms = std::max(max_ms, s.max_ms);
  }
};

// The pid of the live process hosting the planner, as the domain lists it.
std::optional<pid_t> planner_process(prime::shm::Core& shm) {
  for (const auto& p : shm.registry().participants)
    if (p.alive && (p.name == "planner" || p.name.starts_with("planner ("))) return static_cast<pid_t>(p.pid);
  return std::nullopt;
}

int demo(int seconds, const std::string& placement, bool event) {
  const auto file = std::filesystem::read_symlink("/proc/self/exe").parent_path() / "robot.yaml";
  const char* env = std::getenv("PRIME_DOMAIN");
  const std::string domain = env && *env ? env : "robot";
  std::vector<std::string> args{"prime", "--domain", domain, "launch", file.string(), "--placement", placement};
  if (event) args.insert(args.end(), {"--param", "planner.on_each_pair=true"});
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::printf("[robot] %s, placement '%s' of %s: sensors, planner (%s) and driver; %d s%s\n", domain.c_str(), placement.c_str(),
              file.c_str(), event ? "on each synchronised pair" : "50 Hz loop", seconds,
              placement == "one" ? "" : ("; the planner is killed at " + std::to_string(seconds / 3) + " s").c_str());
  std::fflush(stdout);
  pid_t launcher = 0;
  if (const int failed = posix_spawnp(&launcher, "prime", nullptr, nullptr, argv.data(), environ); failed != 0) {
    std::fprintf(stderr, "robot: cannot start `prime launch` (%s): put the prime tool on the PATH, as tools/run demo does\n",
                 std::strerror(failed));
    return 1;
  }
  prime::shm::Core shm{domain, {.participant = "demo"}};
  auto stats = shm.subscribe<robot::DriverStats>("driver/stats", {.spin = 0us}, {.capacity = 8}).subscribe();
  const auto t0 = prime::Clock::now();
  const auto kill_at = t0 + std::chrono::seconds{seconds / 3};
  std::optional<prime::Clock::time_point> killed;
  std::optional<pid_t> killed_pid;
  Phase before, after;
  int safe_stops = 0;
  bool driving = false, recovered = false, launcher_ended = false;
  while (!stop && prime::Clock::now() - t0 < std::chrono::seconds{seconds}) {
    if (waitpid(launcher, nullptr, WNOHANG) == launcher) {
      launcher_ended = true;
      break;
    }
    if (auto s = stats.read_for(100ms)) {
      const auto& report = *s->value;
      if (report.commands > 0 && !report.safe_stop) driving = true;
      if (!killed) before.add(report);
      else if (prime::Clock::now() - *killed > 2500ms) after.add(report);
      if (killed) safe_stops += static_cast<int>(report.safe_stops);
      if (killed && prime::Clock::now() - *killed > 1s && report.commands > 0 && !report.safe_stop) recovered = true;
    }
    const auto now = prime::Clock::now();
    if (placement != "one" && !killed && now >= kill_at) {
      if (auto pid = planner_process(shm)) {
        kill(*pid, SIGKILL);
        killed = now;
        killed_pid = pid;
        std::printf("[robot] killed the planner's process %d (SIGKILL) at %.1f s; prime launch restarts it\n", *pid,
                    std::chrono::duration<double>(now - t0).count());
        std::fflush(stdout);
      }
    }
  }
  int status = 0;
  if (!launcher_ended) {
    kill(launcher, SIGINT);  // the launcher stops every process
    waitpid(launcher, &status, 0);
  }
  std::printf("\n[robot] sensor stamp to motors%s: %u commands, mean %.2f ms, p99 %.2f ms, max %.2f ms\n",
              placement == "one" ? "" : ", before the kill", before.commands, before.mean_ms, before.p99_ms, before.max_ms);
  if (placement == "one") {
    std::printf("[robot] %s\n", driving ? "driving: every link in one process" : "NOT DRIVING");
    return driving && !launcher_ended ? 0 : 1;
  }
  std::printf("[robot] after the restart: %u commands, mean %.2f ms, p99 %.2f ms, max %.2f ms\n", after.commands,
              after.mean_ms, after.p99_ms, after.max_ms);
  std::printf("[robot] %s; %s\n",
              safe_stops > 0 ? "the driver held the robot safe while the planner was down" : "THE DRIVER NEVER HELD THE ROBOT SAFE",
              recovered ? "recovered: the restarted planner drives it again" : "NOT RECOVERED");
  return recovered && safe_stops > 0 && !launcher_ended ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::string_view{argv[i]}.starts_with("--prime-")) return prime::system::run(argc, argv);
  struct sigaction on_stop {};
  on_stop.sa_handler = [](int) { stop = true; };
  sigaction(SIGINT, &on_stop, nullptr);
  sigaction(SIGTERM, &on_stop, nullptr);
  int seconds = 12;
  std::string placement = "split";
  bool event = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--event") event = true;
    else if (arg == "--placement" && i + 1 < argc) placement = argv[++i];
    else if (!arg.empty() && std::isdigit(static_cast<unsigned char>(arg[0]))) seconds = std::atoi(arg.c_str());
    else {
      std::fprintf(stderr, "usage: robot [seconds] [--placement one|split|machines] [--event]\n");
      return 2;
    }
  }
  return demo(seconds, placement, event);
}
