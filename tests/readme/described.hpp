// What the PRIME_DESCRIBE example of docs/tool.md takes as given.
#pragma once

#include "prime/common/bounded_string.hpp"
#include "prime/common/schema.hpp"
