#pragma once

#include "prime/topology/erased_chain.hpp"

namespace prime::liberty {

// Every Liberty chain is an erased chain, whatever blocks it holds, so
// topologies can be assembled while the program runs.
template <class In, class Out>
using Chain = ErasedChain<In, Out>;

}  // namespace prime::liberty
