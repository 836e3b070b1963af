#pragma once

// The topology layer: what chains and sources are, and the combinators that
// work the same over every medium.
#include "prime/topology/chain_factory.hpp"
#include "prime/topology/collector.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/erased_chain.hpp"
#include "prime/topology/foreach.hpp"
#include "prime/topology/fork.hpp"
#include "prime/topology/forward.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/if_then_else.hpp"
#include "prime/topology/interpolate.hpp"
#include "prime/topology/link.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/loop.hpp"
#include "prime/topology/qos.hpp"
#include "prime/topology/realtime.hpp"
#include "prime/topology/repeat.hpp"
#include "prime/topology/runtime.hpp"
#include "prime/topology/sync.hpp"
#include "prime/topology/watchdog.hpp"
