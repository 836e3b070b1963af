// The C++ side of the Python tests (tests/python/test_shm.py), one role per
// run, in domain argv[2]:
//
//   peer publish D N    makes topic "pose", says "ready", and on "go" (a line
//                       on stdin) publishes N poses (id i, x i/2, y -i,
//                       frame "map", v {i, 2i, 3i}), says "done", and waits
//                       for stdin to close
//   peer subscribe D N  subscribes to "command" (making it), says "ready",
//                       and checks N commands come in order (value i, gain
//                       i/4, from 1): says "ok N", or what was wrong (exit 1)
//   peer serve D        serves "double" (Command -> Command, value and gain
//                       doubled) and "fail" (throws "no motors"), says
//                       "ready", and serves until stdin closes
//   peer pair D N       makes topics "scan" (Pose) and "odom" (Command),
//                       says "ready", and on each of N lines publishes the
//                       next pair: pose i stamped t0 + 10 ms i, command i
//                       1 ms later; then says "done", and waits for stdin
//                       to close
//   peer sync D N       syncs "scan" (Pose) and "odom" (Command) by exact
//                       time (making the topics if Python has not), says
//                       "ready", and for each of N sets checks pose i and
//                       command i came together and says "set i"; says
//                       what was wrong otherwise (exit 1)
//   peer call D N       calls "triple" (Command -> Command, served from
//                       Python) N times and checks each answer, then
//                       "refuse" (its failure's code must be invalid
//                       argument) and "raise" (block failed, naming the
//                       Python exception): says "ok N", or what was wrong
#include <array>
#include <cstdint>
#include <iostream>
#include <string>
#include <string_view>

#include "prime/shm.hpp"

namespace robot {
struct Pose {
  double x;
  double y;
  std::int32_t id;
  prime::bounded_string<16> frame;
  std::array<float, 3> v;
};
PRIME_DESCRIBE(Pose, x, y, id, frame, v)

struct Command {
  std::int64_t value;
  double gain;
};
PRIME_DESCRIBE(Command, value, gain)
}  // namespace robot

namespace {

using namespace std::chrono_literals;
namespace shm = prime::shm;

void wait_for_stdin_to_close() {
  std::string line;
  while (std::getline(std::cin, line)) {
  }
}

int publish(shm::Core& core, int n) {
  auto pub = core.publisher<robot::Pose>("pose", {.capacity = 64});
  std::cout << "ready" << std::endl;
  std::string line;
  if (!std::getline(std::cin, line)) return 1;
  for (int i = 1; i <= n; ++i) {
    robot::Pose pose{.x = i / 2.0, .y = -1.0 * i, .id = i, .frame = {}, .v = {1.0f * i, 2.0f * i, 3.0f * i}};
    pose.frame = "map";
    if (auto sent = pub.publish(pose); !sent) {
      std::cout << "publish failed: " << sent.error().describe() << std::endl;
      return 1;
    }
  }
  std::cout << "done" << std::endl;
  wait_for_stdin_to_close();
  return 0;
}

int subscribe(shm::Core& core, int n) {
  auto reader = core.subscribe<robot::Command>("command", {}, {.capacity = 64}).subscribe();
  std::cout << "ready" << std::endl;
  for (int i = 1; i <= n; ++i) {
    auto got = reader.read_for(10s);
    if (!got) {
      std::cout << "command " << i << ": " << got.error().describe() << std::endl;
      return 1;
    }
    const auto& c = *got->value;
    if (c.value != i || c.gain != i / 4.0) {
      std::cout << "command " << i << " came as value " << c.value << ", gain " << c.gain << std::endl;
      return 1;
    }
  }
  std::cout << "ok " << n << std::endl;
  return 0;
}

int serve(shm::Core& core) {
  auto twice = core.serve("double", [](const robot::Command& c) { return robot::Command{c.value * 2, c.gain * 2}; });
  auto fail = core.serve("fail", [](const robot::Command&) -> robot::Command { throw std::runtime_error{"no motors"}; });
  std::cout << "ready" << std::endl;
  wait_for_stdin_to_close();
  return 0;
}

int pair(shm::Core& core, int n) {
  auto scans = core.publisher<robot::Pose>("scan", {.capacity = 64});
  auto odoms = core.publisher<robot::Command>("odom", {.capacity = 64});
  std::cout << "ready" << std::endl;
  const auto t0 = prime::Clock::now();
  std::string line;
  for (int i = 1; i <= n; ++i) {
    if (!std::getline(std::cin, line)) return 1;
    const auto at = t0 + i * 10ms;
    robot::Pose pose{.x = 0, .y = 0, .id = i, .frame = {}, .v = {}};
    if (!scans.publish(pose, at) || !odoms.publish(robot::Command{i, 0.0}, at + 1ms)) {
      std::cout << "publish failed" << std::endl;
      return 1;
    }
  }
  std::cout << "done" << std::endl;
  wait_for_stdin_to_close();
  return 0;
}

int sync_pairs(shm::Core& core, int n) {
  auto scans = core.subscribe<robot::Pose>("scan", {}, {.capacity = 64});
  auto odoms = core.subscribe<robot::Command>("odom", {}, {.capacity = 64});
  auto sets = prime::sync(prime::exact_time, scans, odoms).subscribe();
  std::cout << "ready" << std::endl;
  for (int i = 1; i <= n; ++i) {
    auto got = sets.read_for(10s);
    if (!got) {
      std::cout << "set " << i << ": " << got.error().describe() << std::endl;
      return 1;
    }
    const auto& [scan, odom] = got->value;
    if ((*scan).id != i || (*odom).value != i || got->value.skew() != prime::Clock::duration::zero() ||
        std::string_view{(*scan).frame} != "py") {
      std::cout << "set " << i << " came as pose " << (*scan).id << " and command " << (*odom).value << std::endl;
      return 1;
    }
    std::cout << "set " << i << std::endl;
  }
  return 0;
}

// Whether a call to `service` fails with `code` and a message naming
// `text`; says what came otherwise.
bool fails_with(shm::Core& core, const std::string& service, prime::Errc code, const std::string& text) {
  const auto got = core.chain<robot::Command, robot::Command>(service, {.timeout = 5s}).call(robot::Command{1, 1.0});
  if (!got && got.error().code == code && got.error().message.find(text) != std::string::npos) return true;
  std::cout << service << ": " << (got ? "answered" : got.error().describe()) << std::endl;
  return false;
}

int call(shm::Core& core, int n) {
  std::cout << "ready" << std::endl;
  auto triple = core.chain<robot::Command, robot::Command>("triple", {.timeout = 5s});
  for (int i = 1; i <= n; ++i) {
    const auto got = triple.call(robot::Command{i, i / 8.0});
    if (!got || got->value != 3 * i || got->gain != 3 * i / 8.0) {
      std::cout << "call " << i << ": " << (got ? "value " + std::to_string(got->value) : got.error().describe()) << std::endl;
      return 1;
    }
  }
  if (!fails_with(core, "refuse", prime::Errc::invalid_argument, "gain out of range") ||
      !fails_with(core, "raise", prime::Errc::block_failed, "ZeroDivisionError"))
    return 1;
  std::cout << "ok " << n << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) try {
  if (argc < 3) {
    std::cerr << "usage: peer publish|subscribe|serve|call|pair|sync DOMAIN [N]\n";
    return 2;
  }
  const std::string role = argv[1];
  shm::Core core{argv[2], {.participant = "peer-" + role}};
  const int n = argc > 3 ? std::stoi(argv[3]) : 0;
  if (role == "publish") return publish(core, n);
  if (role == "subscribe") return subscribe(core, n);
  if (role == "serve") return serve(core);
  if (role == "call") return call(core, n);
  if (role == "pair") return pair(core, n);
  if (role == "sync") return sync_pairs(core, n);
  std::cerr << "unknown role " << role << "\n";
  return 2;
} catch (const std::exception& e) {
  std::cout << "failed: " << e.what() << std::endl;
  return 1;
}
