// The other process of the real-time tests: drops its privileges (to the
// user nobody, when run as root), lowers RLIMIT_RTPRIO and RLIMIT_MEMLOCK to
// 0, then asks for what an unprivileged process may not have and prints what
// it was told, one line each:
//   fifo: <code>: <message>            every() with SCHED_FIFO
//   best effort: <ticks> ticks; <code>: <message>   the same with best_effort, and its warning
//   memlock: <code>: <message>          lock_memory()
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

#include "prime/liberty.hpp"

using namespace std::chrono_literals;

namespace {
void say(const std::string& what, const prime::Error& e) {
  std::printf("%s: %s: %s\n", what.c_str(), std::string{prime::to_string(e.code)}.c_str(), e.message.c_str());
  std::fflush(stdout);
}
}  // namespace

int main() {
  if (::geteuid() == 0 && (::setgid(65534) != 0 || ::setuid(65534) != 0)) {
    std::perror("unprivileged: dropping to nobody");
    return 2;
  }
  const rlimit none{0, 0};
  if (::setrlimit(RLIMIT_RTPRIO, &none) != 0 || ::setrlimit(RLIMIT_MEMLOCK, &none) != 0) {
    std::perror("unprivileged: lowering the limits");
    return 2;
  }
  prime::liberty::Core core;
  const prime::Realtime fifo{.policy = prime::Realtime::fifo, .priority = 50};
  try {
    auto loop = prime::every(core, 1ms, [](prime::Token) {}, {.name = "control", .realtime = fifo});
    std::printf("fifo: granted\n");
  } catch (const prime::Failure& f) {
    say("fifo", f.error());
  }

  auto errors = core.errors().subscribe();
  auto best_effort = fifo;
  best_effort.best_effort = true;
  auto loop = prime::every(core, 1ms, [](prime::Token) {}, {.name = "control", .realtime = best_effort});
  const auto warning = errors.read_for(10s);
  // Polling a counter the loop's thread raises, for 10 s at most.
  for (int i = 0; i < 10'000 && loop.stats().ticks < 3; ++i) std::this_thread::sleep_for(1ms);
  loop.stop();
  std::printf("best effort: %llu ticks; ", static_cast<unsigned long long>(loop.stats().ticks));
  if (warning) say("warning", warning->value);
  else std::printf("no warning\n");

  if (auto refused = prime::lock_memory(true)) say("memlock", *refused);
  else std::printf("memlock: granted\n");
  return 0;
}
