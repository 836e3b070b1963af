#pragma once

#include <concepts>
#include <functional>
#include <string>
#include <type_traits>
#include <utility>

#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"

namespace prime {

namespace detail {

template <class Test, class Then, class Else>
struct Branch {
  Test test;
  Then then_chain;
  Else else_chain;

  typename Then::output_type operator()(typename Then::input_type in) const {
    if (std::invoke(test, std::as_const(in))) return then_chain(std::move(in));
    return else_chain(std::move(in));
  }
};

}  // namespace detail

// Runs `then_chain` where `test(input)` holds and `else_chain` where it does
// not. Both chains take the same input and give the same output.
template <Medium M, class Test, Chain Then, Chain Else>
[[nodiscard]] auto if_then_else(M& core, Test test, Then then_chain, Else else_chain,
                                std::string name = "if") {
  using In = typename Then::input_type;
  static_assert(std::same_as<In, typename Else::input_type>,
                "prime::if_then_else: both branches must take the same input_type");
  static_assert(std::same_as<typename Then::output_type, typename Else::output_type>,
                "prime::if_then_else: both branches must give the same output_type");
  static_assert(std::predicate<const Test&, const In&>,
                "prime::if_then_else: the test must be callable as bool(const Input&)");
  Graph graph = Graph::sequence(Graph::node(std::move(name), "branch", std::string{core.medium()}),
                                Graph::parallel({&then_chain.graph(), &else_chain.graph()}));
  return core.template chain<In>(
      detail::Branch<Test, Then, Else>{std::move(test), std::move(then_chain), std::move(else_chain)},
      std::move(graph));
}

}  // namespace prime
