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
#include <array>
#include <cstdint>
#include <iostream>
#include <string>

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

}  // namespace

int main(int argc, char** argv) try {
  if (argc < 3) {
    std::cerr << "usage: peer publish|subscribe|serve DOMAIN [N]\n";
    return 2;
  }
  const std::string role = argv[1];
  shm::Core core{argv[2], {.participant = "peer-" + role}};
  const int n = argc > 3 ? std::stoi(argv[3]) : 0;
  if (role == "publish") return publish(core, n);
  if (role == "subscribe") return subscribe(core, n);
  if (role == "serve") return serve(core);
  std::cerr << "unknown role " << role << "\n";
  return 2;
} catch (const std::exception& e) {
  std::cout << "failed: " << e.what() << std::endl;
  return 1;
}
