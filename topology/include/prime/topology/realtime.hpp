#pragma once

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>

#include <cerrno>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "prime/logic/error.hpp"

namespace prime {

// How a loop's thread is scheduled: `{.policy = Realtime::fifo, .priority = 80, .cpus = {3}}`.
// What the system refuses (a priority over RLIMIT_RTPRIO, a CPU the process
// may not use) is an error naming the limit and how to raise it, or, with
// `best_effort`, one warning on the core's errors, the loop running without it.
struct Realtime {
  enum Policy { other, fifo, rr };
  Policy policy = other;  // other: the default time-sharing scheduler
  int priority = 0;       // fifo and rr: 1 (lowest) to 99
  std::vector<int> cpus{};  // the CPUs the thread may run on; empty: any the process may
  bool best_effort = false;
};

namespace detail {

inline std::string rlimit_text(int resource) {
  rlimit limit{};
  if (::getrlimit(resource, &limit) != 0) return "unknown";
  return limit.rlim_cur == RLIM_INFINITY ? std::string{"unlimited"} : std::to_string(limit.rlim_cur);
}

// Why `realtime` cannot be asked for at all (a priority out of range, a
// CPU number out of bounds), before any thread runs.
inline std::optional<std::string> realtime_invalid(const Realtime& realtime) {
  if (realtime.policy != Realtime::other) {
    const int policy = realtime.policy == Realtime::fifo ? SCHED_FIFO : SCHED_RR;
    const int low = ::sched_get_priority_min(policy), high = ::sched_get_priority_max(policy);
    if (realtime.priority < low || realtime.priority > high)
      return "priority " + std::to_string(realtime.priority) + " is outside " + std::to_string(low) + ".." +
             std::to_string(high);
  } else if (realtime.priority != 0) {
    return "a priority needs the fifo or rr policy";
  }
  for (const int cpu : realtime.cpus)
    if (cpu < 0 || cpu >= CPU_SETSIZE) return "CPU " + std::to_string(cpu) + " is not a CPU number";
  return std::nullopt;
}

// Applies `realtime` to the calling thread: the error, naming `who` and
// what to change, when the system refuses.
inline std::optional<Error> apply_realtime(const Realtime& realtime, const std::string& who) {
  if (!realtime.cpus.empty()) {
    cpu_set_t set;
    CPU_ZERO(&set);
    for (const int cpu : realtime.cpus) CPU_SET(cpu, &set);
    if (const int e = ::pthread_setaffinity_np(::pthread_self(), sizeof set, &set); e != 0) {
      cpu_set_t allowed;
      CPU_ZERO(&allowed);
      std::string usable;
      if (::sched_getaffinity(0, sizeof allowed, &allowed) == 0)
        for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu)
          if (CPU_ISSET(cpu, &allowed)) usable.append(usable.empty() ? "" : ",").append(std::to_string(cpu));
      std::string asked;
      for (const int cpu : realtime.cpus) asked.append(asked.empty() ? "" : ",").append(std::to_string(cpu));
      return Error{Errc::refused, who + ": CPU affinity {" + asked + "} was refused (" + std::strerror(e) +
                                      "); this process may run on {" + usable + "} (see taskset, cgroup cpusets)"};
    }
  }
  if (realtime.policy != Realtime::other) {
    const int policy = realtime.policy == Realtime::fifo ? SCHED_FIFO : SCHED_RR;
    const sched_param param{.sched_priority = realtime.priority};
    if (const int e = ::pthread_setschedparam(::pthread_self(), policy, &param); e != 0) {
      const std::string name = realtime.policy == Realtime::fifo ? "SCHED_FIFO" : "SCHED_RR";
      std::string why = who + ": " + name + " priority " + std::to_string(realtime.priority) + " was refused (" +
                        std::strerror(e) + ")";
      if (e == EPERM)
        why += ": without CAP_SYS_NICE a process may not go above RLIMIT_RTPRIO, here " + rlimit_text(RLIMIT_RTPRIO) +
               " (ulimit -r); raise it with an 'rtprio' line in /etc/security/limits.conf, "
               "LimitRTPRIO= in a systemd unit, or grant CAP_SYS_NICE";
      return Error{Errc::refused, std::move(why)};
    }
  }
  return std::nullopt;
}

}  // namespace detail

// Locks the process's memory, present and future (mlockall), so that no
// page it touches is ever paged out: after setup, a control loop takes no
// page fault for memory it has used. Throws Errc::refused naming
// RLIMIT_MEMLOCK and how to raise it, unless `best_effort`, which gives the
// reason back instead.
inline std::optional<Error> lock_memory(bool best_effort = false) {
  if (::mlockall(MCL_CURRENT | MCL_FUTURE) == 0) return std::nullopt;
  const int e = errno;
  Error error{Errc::refused, std::string{"locking the process's memory (mlockall) was refused ("} + std::strerror(e) +
                                 "): without CAP_IPC_LOCK a process may lock at most RLIMIT_MEMLOCK, here " +
                                 detail::rlimit_text(RLIMIT_MEMLOCK) +
                                 " bytes (ulimit -l); raise it with a 'memlock' line in "
                                 "/etc/security/limits.conf, LimitMEMLOCK= in a systemd unit, or grant CAP_IPC_LOCK"};
  if (!best_effort) throw Failure{std::move(error)};
  return error;
}

}  // namespace prime
