// A separate process for the Optimus tests: hosts services or publishes a
// source on the server it is given, says "ready" on stdout, and exits when its
// stdin closes (so it never outlives the test that started it).
//
//   optimus_service_helper <url> <domain> serve          double, add_one, times_ten, whoami, fail
//   optimus_service_helper <url> <domain> publish <name> waits for "go <n>" lines, publishes n ints each
//   optimus_service_helper <url> <domain> block_reader <name> a block reader of 2 ints' room that reads nothing
//   optimus_service_helper <url> <domain> call <name> <ms>    says "ready", then calls the service (int -> int) once
#include <unistd.h>

#include <chrono>
#include <iostream>
#include <stdexcept>
#include <string>

#include "prime/optimus.hpp"

int main(int argc, char** argv) {
  if (argc < 4) {
    std::cerr << "usage: optimus_service_helper <url> <domain> serve|publish [name]\n";
    return 2;
  }
  const std::string role = argv[3];
  try {
    prime::optimus::Core core{prime::optimus::Options{.url = argv[1], .domain = argv[2]}};
    if (role == "serve") {
      (void)core.serve("double", [](int x) { return 2 * x; });
      (void)core.serve("add_one", [](int x) { return x + 1; });
      (void)core.serve("times_ten", [](int x) { return x * 10; });
      (void)core.serve("whoami", [](int) { return static_cast<int>(::getpid()); });
      (void)core.serve("fail", [](int x) -> int { throw std::runtime_error{"failing on " + std::to_string(x)}; });
      std::cout << "ready" << std::endl;
      std::string line;
      while (std::getline(std::cin, line)) {
      }
      return 0;
    }
    if (role == "block_reader" && argc >= 5) {
      auto reader = core.subscribe<int>(argv[4], {.capacity = 2, .overflow = prime::Overflow::block}).subscribe();
      std::cout << "ready" << std::endl;
      std::string line;
      while (std::getline(std::cin, line)) {
      }
      return 0;
    }
    if (role == "call" && argc >= 6) {
      auto service = core.service<int, int>(argv[4], {.timeout = std::chrono::milliseconds{std::stoi(argv[5])}});
      std::cout << "ready" << std::endl;
      auto answer = service.call(1);
      std::cout << (answer ? "answered " + std::to_string(*answer) : answer.error().describe()) << std::endl;
      return answer ? 0 : 1;
    }
    if (role == "publish" && argc >= 5) {
      auto publisher = core.publisher<int>(argv[4], {.capacity = 1000});
      std::cout << "ready" << std::endl;
      std::string line;
      int next = 0;
      while (std::getline(std::cin, line)) {
        if (!line.starts_with("go ")) continue;
        const int n = std::stoi(line.substr(3));
        for (int i = 0; i < n; ++i) {
          if (auto done = publisher.publish(next++); !done) {
            std::cerr << done.error().describe() << '\n';
            return 1;
          }
        }
        std::cout << "published " << next << std::endl;
      }
      return 0;
    }
  } catch (const std::exception& e) {
    std::cerr << "optimus_service_helper: " << e.what() << '\n';
    return 1;
  }
  std::cerr << "optimus_service_helper: unknown role '" << role << "'\n";
  return 2;
}
