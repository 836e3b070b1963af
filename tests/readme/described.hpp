// What the README's PRIME_DESCRIBE example takes as given.
#pragma once

#include "prime/common/bounded_string.hpp"
#include "prime/common/schema.hpp"
