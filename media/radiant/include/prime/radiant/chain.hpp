#pragma once

#include <functional>
#include <memory>
#include <utility>

#include "prime/logic/block.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"

namespace prime::radiant {

namespace detail {

// `second` after `first`, as one type the compiler sees through: a chain of a
// hundred blocks inlines into the hand-written sequence of calls.
template <class First, class Second>
struct Fused {
  First first;
  Second second;

  // Called directly, not through std::invoke: every level of a deep chain
  // must inline, and only what is marked always_inline surely does.
  template <class X>
  [[gnu::always_inline]] constexpr decltype(auto) operator()(X&& x) const {
    return second(first(std::forward<X>(x)));
  }
};

}  // namespace detail

// A chain whose type carries its blocks. Linking radiant chains yields a new
// type; nothing is erased, nothing allocated on the call path. Lambdas and
// functors fuse completely; a plain function is held as a pointer, so pass
// `prime::fn<&f>` for a function to be inlined too.
//
// Thread-safe to call from several threads when the blocks are.
template <class In, class F>
class Chain {
 public:
  using input_type = In;
  using output_type = block_output_t<F, In>;

  Chain(F block, Graph graph) : block_{std::move(block)}, graph_{std::make_shared<const Graph>(std::move(graph))} {}

  [[gnu::always_inline]] inline output_type operator()(In in) const { return block_(std::move(in)); }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const F& block() const noexcept { return block_; }

 private:
  F block_;
  std::shared_ptr<const Graph> graph_;
};

static_assert(prime::Chain<Chain<int, int (*)(int)>>);

template <class In, class F, class Mid, class G>
  requires std::same_as<block_output_t<F, In>, Mid>
[[nodiscard]] auto link(const Chain<In, F>& first, const Chain<Mid, G>& second) {
  return Chain<In, detail::Fused<F, G>>{{first.block(), second.block()}, Graph::sequence(first.graph(), second.graph())};
}

using prime::operator|;

}  // namespace prime::radiant
