#pragma once

// The machine a report was measured on: figures mean little without it.

#include <sched.h>
#include <sys/utsname.h>

#include <chrono>
#include <ctime>
#include <fstream>
#include <string>

namespace prime::tool::bench {

struct Machine {
  std::string cpu;     // the model, from /proc/cpuinfo
  int cpus = 0;        // CPUs this process may run on
  std::string kernel;  // uname: release and machine
  std::string memory;  // MemTotal, from /proc/meminfo
  std::string date;    // UTC, when the run started
};

inline Machine this_machine() {
  Machine m;
  std::ifstream cpuinfo{"/proc/cpuinfo"};
  for (std::string line; std::getline(cpuinfo, line);)
    if (line.starts_with("model name")) {
      m.cpu = line.substr(line.find(':') + 2);
      break;
    }
  cpu_set_t set;
  if (::sched_getaffinity(0, sizeof set, &set) == 0) m.cpus = CPU_COUNT(&set);
  utsname u{};
  if (::uname(&u) == 0) m.kernel = std::string{u.sysname} + " " + u.release + " " + u.machine;
  std::ifstream meminfo{"/proc/meminfo"};
  for (std::string line; std::getline(meminfo, line);)
    if (line.starts_with("MemTotal:")) {
      const auto kib = std::stoull(line.substr(9));
      m.memory = std::to_string(kib / (1024 * 1024)) + " GiB";
      break;
    }
  const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  m.date = text;
  return m;
}

}  // namespace prime::tool::bench
