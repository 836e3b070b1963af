#pragma once

#include "prime/liberty/chain.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/erased_chain.hpp"

namespace prime::liberty {

// Runtime composition: every chain is a liberty::Chain<In, Out>, whatever
// blocks it holds, so topologies can be assembled while the program runs.
class Core : public ErasedChainRuntime {
 public:
  Core() : ErasedChainRuntime{"liberty"} {}
};

static_assert(Medium<Core>);

}  // namespace prime::liberty
