#pragma once

// How the conformance suite runs on Optimus: one redis-server for the whole
// test binary (started on first use, stopped at exit), and a domain of its own
// for every core. A feed is an Event feeding core.source(), whose values go
// through a Redis stream. Values travel serialised and each block is a
// service with its own worker, which two capability flags say.

#include <unistd.h>

#include <atomic>
#include <memory>
#include <string>

#include "optimus/support/redis_server.hpp"
#include "prime/optimus.hpp"

namespace prime::test {

template <>
struct Harness<optimus::Core> {
  static constexpr bool kPassesObjectsInPlace = false;
  static constexpr bool kRunsLinkedBlocksInOneWorker = false;

  static std::unique_ptr<optimus::Core> make_core() {
    static RedisServer server;
    static std::atomic<int> made = 0;
    return std::make_unique<optimus::Core>(optimus::Options{
        .url = server.url(), .domain = "conformance-" + std::to_string(::getpid()) + "-" + std::to_string(made++)});
  }

  template <class T>
  struct Feed {
    std::unique_ptr<Event<T>> event;
    optimus::Source<T> source;

    void emit(T value) { event->emit(std::move(value)); }
    void emit(T value, Clock::time_point stamp) { event->emit(std::move(value), stamp); }
  };

  template <class T>
  static Feed<T> feed(optimus::Core& core, std::string name, Qos qos = {}) {
    auto event = std::make_unique<Event<T>>();
    auto source = core.source(*event, std::move(name), qos);
    return {std::move(event), std::move(source)};
  }
};

}  // namespace prime::test
