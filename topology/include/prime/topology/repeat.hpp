#pragma once

#include <chrono>
#include <concepts>
#include <cstddef>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/graph.hpp"

namespace prime {

struct RepeatLimits {
  // A loop that never meets its condition is an error, not a hang.
  std::size_t max_iterations = 1'000'000;
  // With a source: how long one iteration waits for the source's next value.
  std::chrono::milliseconds read_timeout{1000};
};

namespace detail {

inline Failure too_many_iterations(const std::string& name, std::size_t max) {
  return Failure{{Errc::iteration_limit,
                  "repeat '" + name + "': condition not met after " + std::to_string(max) + " iterations"}};
}

// A loop allowed no iteration could not run its body even once.
inline void check(const RepeatLimits& limits, const std::string& name) {
  if (limits.max_iterations == 0)
    throw Failure{{Errc::invalid_argument, "repeat '" + name + "': max_iterations must be at least 1 (the body runs at least once)"}};
}

template <class Body, class Until>
struct Repeat {
  Body body;
  Until until;
  RepeatLimits limits;
  std::string name;

  typename Body::output_type operator()(typename Body::input_type value) const {
    for (std::size_t i = 0; i < limits.max_iterations; ++i) {
      value = body(std::move(value));
      if (std::invoke(until, std::as_const(value))) return value;
    }
    throw too_many_iterations(name, limits.max_iterations);
  }
};

template <class Body, class Until, class U>
struct RepeatReading {
  using T = typename Body::output_type;
  struct Input {
    explicit Input(Reader<U> r) : reader{std::move(r)} {}
    std::mutex mutex;  // the chain may be called from several threads
    Reader<U> reader;
  };

  Body body;
  Until until;
  RepeatLimits limits;
  std::string name;
  std::shared_ptr<Input> input;

  T operator()(T value) const {
    std::scoped_lock lock{input->mutex};
    for (std::size_t i = 0; i < limits.max_iterations; ++i) {
      auto next = input->reader.read_for(limits.read_timeout, RuntimeState::worker_stop());  // in a worker, a stop ends the wait
      if (!next) throw Failure{{next.error().code, "repeat '" + name + "': " + next.error().message}};
      value = body(typename Body::input_type{std::move(value), std::move(next->value)});
      if (std::invoke(until, std::as_const(value))) return value;
    }
    throw too_many_iterations(name, limits.max_iterations);
  }
};

}  // namespace detail

// Chain<T, T>: runs `body` (a Chain<T, T>) again and again on its own output
// until `until(value)` holds, like the paper's Repeater. The body runs at least
// once.
template <Medium M, Chain Body, class Until>
[[nodiscard]] auto repeat(M& core, Body body, Until until, RepeatLimits limits = {}, std::string name = "repeat") {
  using T = typename Body::input_type;
  static_assert(std::same_as<T, typename Body::output_type>,
                "prime::repeat: the body must give back what it takes (Chain<T, T>)");
  static_assert(std::predicate<const Until&, const T&>, "prime::repeat: `until` must be callable as bool(const T&)");
  detail::check(limits, name);
  Graph loop = Graph::node(name, "repeat", std::string{core.medium()});
  Graph graph = Graph::sequence(loop, body.graph()).looping_back_to(loop);
  return core.template chain<T>(detail::Repeat<Body, Until>{std::move(body), std::move(until), limits, std::move(name)},
                                std::move(graph));
}

// As above, reading the source's next value in each iteration (waiting up to
// `limits.read_timeout`): the body is a Chain<std::pair<T, U>, T>, where U is
// the source's value type (or what it converts to: a Shm view's message). A control loop paced by a sensor.
template <Medium M, Chain Body, class Until, Source S>
[[nodiscard]] auto repeat(M& core, Body body, Until until, const S& source, RepeatLimits limits = {},
                          std::string name = "repeat") {
  using T = typename Body::output_type;
  using U = typename S::value_type;
  static_assert(std::constructible_from<typename Body::input_type, T&&, U&&>,
                "prime::repeat: with a source, the body must be a Chain<std::pair<T, U>, T>, with U the "
                "source's value_type (or a pair U converts into)");
  static_assert(std::predicate<const Until&, const T&>, "prime::repeat: `until` must be callable as bool(const T&)");
  detail::check(limits, name);
  Graph loop = Graph::node(name, "repeat", std::string{core.medium()});
  Graph graph = Graph::sequence(Graph::parallel({&source.graph(), &loop}), body.graph()).looping_back_to(loop);
  using Loop = detail::RepeatReading<Body, Until, U>;
  auto input = std::make_shared<typename Loop::Input>(source.subscribe());
  return core.template chain<T>(Loop{std::move(body), std::move(until), limits, std::move(name), std::move(input)},
                                std::move(graph));
}

}  // namespace prime
