#pragma once

#include <concepts>
#include <string>
#include <utility>

#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/qos.hpp"

namespace prime {

template <class C, class T>
struct Forked {
  C chain;                // runs the original chain and tees its output
  LocalSource<T> source;  // every output of `chain`, for whoever wants to watch
};

namespace detail {

template <class Body>
struct Tee {
  using Out = typename Body::output_type;
  Body body;
  LocalSource<Out> source;

  Out operator()(typename Body::input_type in) const {
    Out out = body(std::move(in));
    source.publish(out, Clock::now(), RuntimeState::worker_stop());  // in a worker, a stop ends a wait for room
    return out;
  }
};

}  // namespace detail

// Tees a chain's output into a source: `auto [chain, outputs] = fork(core, c);`
// Calling `chain` gives what `c` gives and publishes a copy of it to `outputs`.
template <Medium M, Chain C>
[[nodiscard]] auto fork(M& core, C chain, std::string name = "fork", Qos qos = {}) {
  using Out = typename C::output_type;
  static_assert(std::copy_constructible<Out>, "prime::fork: the output must be copyable to be teed");
  Graph graph = Graph::sequence(chain.graph(), Graph::node(name, "fork", std::string{core.medium()}));
  LocalSource<Out> source{std::move(name), qos, core.runtime(), graph};
  auto teed = core.template chain<typename C::input_type>(detail::Tee<C>{std::move(chain), source}, std::move(graph));
  return Forked<decltype(teed), Out>{std::move(teed), std::move(source)};
}

}  // namespace prime
