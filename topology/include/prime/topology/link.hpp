#pragma once

#include <concepts>
#include <memory>
#include <stop_token>
#include <string>
#include <utility>

#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/runtime.hpp"

namespace prime {

namespace detail {

template <class...>
inline constexpr bool always_false = false;

// The names of the nodes a graph's data leaves through: "lidar | localize".
inline std::string exit_names(const Graph& graph) {
  std::string names;
  for (const auto& node : graph.exits()) names.append(names.empty() ? "" : ", ").append(node.name);
  return names;
}

}  // namespace detail

// The generic link: any chain after any chain, whatever their media. Media
// give `link` overloads of their own for chains of their kind; this one is
// what remains when two media meet.
template <Chain A, Chain B>
class Linked {
 public:
  using input_type = typename A::input_type;
  using output_type = typename B::output_type;

  Linked(A first, B second)
      : first_{std::move(first)},
        second_{std::move(second)},
        graph_{std::make_shared<const Graph>(Graph::sequence(first_.graph(), second_.graph()))} {}

  output_type operator()(input_type in) const { return second_(first_(std::move(in))); }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }

 private:
  A first_;
  B second_;
  std::shared_ptr<const Graph> graph_;
};

template <Chain A, Chain B>
[[nodiscard]] Linked<A, B> link(A first, B second) {
  return {std::move(first), std::move(second)};
}

// chain | chain: a chain that runs one, then the other.
template <Chain A, Chain B>
[[nodiscard]] auto operator|(A first, B second) {
  if constexpr (!std::convertible_to<typename A::output_type, typename B::input_type>) {
    static_assert(detail::always_false<A, B>,
                  "prime: cannot link these chains: the first chain's output_type does not "
                  "convert to the second chain's input_type");
  } else {
    return link(std::move(first), std::move(second));
  }
}

// source | chain: a new source of the chain's outputs, computed by one worker
// of the source's core. Chains linked together before share that one worker.
// A link is a lasting part of the topology: its worker runs until the core
// stops, whether or not anyone still holds the returned source (a chain that
// drives actuators may have no reader at all).
template <Source S, Chain C>
[[nodiscard]] auto operator|(S source, C chain) {
  using In = typename S::value_type;
  if constexpr (!std::convertible_to<In, typename C::input_type>) {
    static_assert(detail::always_false<S, C>,
                  "prime: cannot link this chain to this source: the source's value_type does "
                  "not convert to the chain's input_type");
  } else {
    using Out = typename C::output_type;
    auto qos = source.qos();
    if constexpr (!std::same_as<Out, In>) qos.max_held = 0;  // new values: they pin nothing of the source's
    LocalSource<Out> out{source.name() + " | " + detail::exit_names(chain.graph()), qos, source.runtime(),
                         Graph::sequence(source.graph(), chain.graph())};
    detail::spawn_reader(source.runtime(), source.subscribe(), "worker '" + out.name() + "'",
                         [chain = std::move(chain), out](Sample<In>&& s, std::stop_token stop) {
                           out.publish(chain(std::move(s.value)), s.stamp, std::move(stop));
                         });
    return out;
  }
}

}  // namespace prime
