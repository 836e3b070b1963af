#pragma once

// Liberty: chains composed at run time from type-erased blocks.
#include "prime/liberty/chain.hpp"
#include "prime/liberty/core.hpp"
#include "prime/topology.hpp"
