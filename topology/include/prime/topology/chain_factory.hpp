#pragma once

#include <string>
#include <utility>

#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"

namespace prime {

// The ways every medium makes a chain, written once. A core defines the one
// that takes the chain's graph, `chain<In>(block, Graph)`, and gets these
// (with `using ChainFactory<Core>::chain;`):
//   core.chain(f)            a chain node named "chain"; a chain of another medium adopted whole
//   core.chain(f, "name")    a chain node named `name`
//
// Only the input type may be named: `int&...` takes no explicit argument, so
// a core's other `chain<A, B>(...)` (an Shm service handle) is never mistaken
// for one of these.
template <class Core>
class ChainFactory {
 public:
  template <class In = detail::Deduce, int&... ExplicitArgumentBarrier, class F>
  [[nodiscard]] auto chain(F block, std::string name) {
    auto& core = static_cast<Core&>(*this);
    Graph graph = Graph::node(std::move(name), "chain", std::string{core.medium()});
    return core.template chain<In>(std::move(block), std::move(graph));
  }
  template <class In = detail::Deduce, int&... ExplicitArgumentBarrier, class F>
  [[nodiscard]] auto chain(F block) {
    if constexpr (Chain<F>) {
      Graph graph = block.graph();
      return static_cast<Core&>(*this).template chain<In>(std::move(block), std::move(graph));
    } else {
      return chain<In>(std::move(block), std::string{"chain"});
    }
  }
};

}  // namespace prime
