#pragma once

// Radiant: chains fused at compile time.
#include "prime/radiant/chain.hpp"
#include "prime/radiant/core.hpp"
#include "prime/topology.hpp"
