#pragma once

#include <memory>
#include <string>
#include <utility>

#include "prime/logic/block.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/runtime.hpp"
#include "prime/liberty/chain.hpp"

namespace prime::liberty {

// Runtime composition: every chain is a liberty::Chain<In, Out>, whatever
// blocks it holds, so topologies can be assembled while the program runs.
class Core : public Runtime {
 public:
  Core() : Runtime{"liberty"} {}

  // A chain of one block (or of a chain of another medium, adopted whole).
  template <class In = prime::detail::Deduce, class F>
  [[nodiscard]] auto chain(F block, Graph graph) {
    using I = chain_input_t<In, F>;
    static_assert(Block<F, I>, "prime::liberty: a block must be callable as Out(In) and return a value");
    using Out = block_output_t<F, I>;
    return Chain<I, Out>{std::make_shared<const detail::BlockStep<I, Out, F>>(std::move(block)), std::move(graph)};
  }
  template <class In = prime::detail::Deduce, class F>
  [[nodiscard]] auto chain(F block, std::string name) {
    return chain<In>(std::move(block), Graph::node(std::move(name), "chain", "liberty"));
  }
  template <class In = prime::detail::Deduce, class F>
  [[nodiscard]] auto chain(F block) {
    if constexpr (prime::Chain<F>) {
      Graph graph = block.graph();
      return chain<In>(std::move(block), std::move(graph));
    } else {
      return chain<In>(std::move(block), std::string{"chain"});
    }
  }
};

static_assert(Medium<Core>);

}  // namespace prime::liberty
