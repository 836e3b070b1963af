#pragma once

#include <string>
#include <type_traits>
#include <utility>

#include "prime/logic/block.hpp"
#include "prime/topology/chain_factory.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/runtime.hpp"
#include "prime/radiant/chain.hpp"

namespace prime::radiant {

// Compile-time fusion: a chain's type is its blocks, so linked chains inline
// into one function.
class Core : public Runtime, public ChainFactory<Core> {
 public:
  Core() : Runtime{"radiant"} {}
  using ChainFactory<Core>::chain;

  // A chain of one block (or of a chain of another medium, adopted whole).
  template <class In = prime::detail::Deduce, class F>
  [[nodiscard]] auto chain(F block, Graph graph) {
    using I = chain_input_t<In, F>;
    static_assert(Block<F, I>, "prime::radiant: a block must be callable as Out(In) and return a value");
    static_assert(!std::is_member_pointer_v<F>, "prime::radiant: wrap a member function in a lambda");
    return Chain<I, F>{std::move(block), std::move(graph)};
  }
};

static_assert(Medium<Core>);

}  // namespace prime::radiant
