#pragma once

#include <chrono>
#include <cstddef>
#include <string>

namespace prime::optimus {

// How a Core reaches its Redis server, and the domain its keys live in.
struct Options {
  // "tcp://host:port" or "unix:///path/to/redis.sock"; "tcp://user:password@host:port"
  // (%-escaped, ":password@" for a password alone) carries credentials, and
  // errors show it with the password as "***".
  std::string url = "tcp://127.0.0.1:6379";
  // AUTH: with a password only (requirepass), or as an ACL user. Empty: no
  // AUTH, unless the URL carries credentials (not both). A user without a
  // password is an error: Redis's AUTH always takes one.
  std::string username{};
  std::string password{};
  // Every key this core reads or writes starts with "<domain>:", so several
  // systems share one server. Nothing outside it is ever touched, and nothing
  // is ever flushed.
  std::string domain = "prime";
  // How long opening a connection may take before the server counts as unreachable.
  std::chrono::milliseconds connect_timeout{1000};
  // The deadline of a chain call made through operator() (call() takes its own).
  std::chrono::milliseconds call_timeout{5000};
};

// How a caller reaches a service: `core.service<In, Out>("planner", {.timeout = 20ms})`.
struct CallOptions {
  std::chrono::milliseconds timeout{5000};
};

// How a service is hosted.
struct ServeOptions {
  // Worker threads taking requests; more than one calls the block concurrently.
  std::size_t workers = 1;
};

}  // namespace prime::optimus
