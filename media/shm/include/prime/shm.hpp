#pragma once

// Shm: topics in shared memory, published in place and read in place by
// other processes of the same domain.
#include "prime/common/bounded_string.hpp"
#include "prime/common/bounded_vector.hpp"
#include "prime/common/schema.hpp"
#include "prime/shm/core.hpp"
#include "prime/shm/inspect.hpp"
#include "prime/shm/message.hpp"
#include "prime/shm/publisher.hpp"
#include "prime/shm/qos.hpp"
#include "prime/shm/registry.hpp"
#include "prime/shm/subscription.hpp"
#include "prime/shm/view.hpp"
#include "prime/shm/views.hpp"
#include "prime/topology.hpp"
