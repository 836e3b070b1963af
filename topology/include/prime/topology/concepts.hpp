#pragma once

#include <concepts>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>

#include "prime/logic/block.hpp"
#include "prime/logic/reader.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/qos.hpp"

namespace prime {

// A synchronous step: called with an input, returns an output, knows the graph
// it was built from. Copies share what they hold.
template <class C>
concept Chain = std::copy_constructible<C> &&
                requires(const C& c) {
                  typename C::input_type;
                  typename C::output_type;
                  { c.graph() } -> std::convertible_to<const Graph&>;
                } &&
                std::is_invocable_r_v<typename C::output_type, const C&, typename C::input_type>;

// Asynchronous values, read through a Reader of one's own. Linked chains run
// in workers of the core the source belongs to (`runtime()`).
template <class S>
concept Source = std::copy_constructible<S> && requires(const S& s) {
  typename S::value_type;
  { s.subscribe() } -> std::same_as<Reader<typename S::value_type>>;
  { s.name() } -> std::convertible_to<std::string>;
  { s.qos() } -> std::convertible_to<Qos>;
  { s.graph() } -> std::convertible_to<const Graph&>;
  { s.runtime() } -> std::convertible_to<std::weak_ptr<detail::RuntimeState>>;
};

// A way of carrying chains: it turns a block into a chain of its own kind.
// Combinators in this layer are written once against this and give each
// medium chains of its own kind (a fused type for Radiant, an erased one for
// Liberty).
template <class M>
concept Medium = requires(M& core, int (*block)(int), Graph graph) {
  { core.template chain<int>(block, std::string{"block"}) } -> Chain;
  { core.template chain<int>(block, graph) } -> Chain;
  { core.medium() } -> std::convertible_to<std::string_view>;
  { core.runtime() } -> std::convertible_to<std::weak_ptr<detail::RuntimeState>>;
};

namespace detail {

struct Deduce {};

// The input type of `F` as a chain: named explicitly, a chain's own, or the
// block's single parameter.
template <class In, class F>
struct chain_input {
  using type = In;
};
template <class F>
  requires Chain<F>
struct chain_input<Deduce, F> {
  using type = typename F::input_type;
};
template <class F>
  requires(!Chain<F>)
struct chain_input<Deduce, F> {
  static_assert(DeducibleBlock<F>,
                "prime: cannot tell this block's input type (a generic lambda or an overloaded "
                "functor?): name it, as in core.chain<Input>(block)");
  using type = block_input_t<F>;
};

}  // namespace detail

template <class In, class F>
using chain_input_t = typename detail::chain_input<In, F>::type;

}  // namespace prime
