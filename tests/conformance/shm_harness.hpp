#pragma once

// How the conformance suite runs on Shm: every core joins a domain of its
// own; a feed is a topic with a publisher and a subscription in this
// process, and core.source(event) is a topic too, so every source test goes
// through shared memory (the cross-process behaviour has tests of its own
// in tests/shm). An Shm core's own chains are Liberty's erased chains, run
// in its process: the chain suite says so and skips it.

#include <unistd.h>

#include <atomic>
#include <memory>
#include <string>

#include "prime/shm.hpp"

namespace prime::test {

template <>
struct Harness<shm::Core> {
  static constexpr bool kCarriesAnyType = false;
  static constexpr const char* kChainsAreAnotherMediums =
      "an shm::Core's own chains are Liberty's erased chains, run in its process (tested on Liberty)";

  static std::unique_ptr<shm::Core> make_core() {
    static std::atomic<int> made = 0;
    return std::make_unique<shm::Core>("conformance-" + std::to_string(::getpid()) + "-" + std::to_string(made++));
  }

  template <class T>
  struct Feed {
    shm::Publisher<T> publisher;
    shm::Subscription<T> source;

    void emit(T value, Clock::time_point stamp = Clock::now()) {
      if (auto sent = publisher.publish(value, stamp); !sent) throw Failure{sent.error()};
    }
  };

  template <class T>
  static Feed<T> feed(shm::Core& core, std::string name, Qos qos = {}) {
    // Views pin slots: enough of them for the suite's syncs to wait for matches.
    const shm::TopicQos topic{
        .capacity = qos.capacity, .overflow = qos.overflow, .block_timeout = qos.block_timeout, .max_held = 16};
    auto publisher = core.publisher<T>(name, topic);
    auto source = core.subscribe<T>(name, {.spin = qos.spin}, topic);
    return {std::move(publisher), std::move(source)};
  }
};

}  // namespace prime::test
