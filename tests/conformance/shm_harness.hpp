#pragma once

// How the conformance suite runs on Shm: every core joins a domain of its
// own; a feed is a topic with a publisher and a subscription in this
// process, and core.source(event) is a topic too, so every source test goes
// through shared memory. A chain is a service the core serves and calls
// through shared memory (its workers answer in place); tests in tests/shm
// serve them from other processes. Chains of types that are not Shm
// messages, and copy counts, are other media's.

#include <unistd.h>

#include <atomic>
#include <memory>
#include <map>
#include <mutex>
#include <string>

#include "prime/shm.hpp"

namespace prime::test {

template <>
struct Harness<shm::Core> {
  static constexpr bool kCarriesAnyType = false;
  static constexpr bool kPassesObjectsInPlace = false;  // a chain's values cross as bytes, exceptions as Errc::block_failed
  static constexpr const char* kChainKind = "service";

  template <class In, class F>
  static auto chain(shm::Core& core, F block, std::string name) {
    return core.template serve<In>(unique(core, name), std::move(block));
  }
  // `name`, or "name#n" when the core serves one of that name already.
  static std::string unique(shm::Core& core, const std::string& name) {
    static std::mutex mutex;
    static std::map<std::string, int> served;
    std::scoped_lock lock{mutex};
    const auto n = served[core.domain() + "/" + name]++;
    return n == 0 ? name : name + "#" + std::to_string(n);
  }

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
    // Views pin slots: enough of them for the suite's syncs to wait for
    // matches and to queue the few sets a test makes in one burst (a sync
    // queues a quarter of its inputs' budget for its reader).
    const shm::TopicQos topic{
        .capacity = qos.capacity, .overflow = qos.overflow, .block_timeout = qos.block_timeout, .max_held = 32};
    auto publisher = core.publisher<T>(name, topic);
    auto source = core.subscribe<T>(name, {.spin = qos.spin}, topic);
    return {std::move(publisher), std::move(source)};
  }
};

}  // namespace prime::test
