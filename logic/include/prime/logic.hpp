#pragma once

// The logic layer: what a user's algorithm is. Standard library only.
#include "prime/logic/block.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/sample.hpp"
#include "prime/logic/token.hpp"
