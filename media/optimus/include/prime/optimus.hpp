#pragma once

// Optimus: chains and sources carried by a Redis server, for systems that span machines.
#include "prime/optimus/chain.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/core.hpp"
#include "prime/optimus/options.hpp"
#include "prime/optimus/source.hpp"
#include "prime/optimus/streaming_publisher.hpp"
#include "prime/topology.hpp"
