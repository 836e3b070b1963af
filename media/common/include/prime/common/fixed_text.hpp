#pragma once

#include <cstddef>
#include <cstring>
#include <string>

namespace prime {

// Text held in a fixed array of characters (in shared memory, say): up to
// its first NUL, and never past its end, as a foreign or broken program may
// have left none.
template <std::size_t N>
std::string read_text(const char (&from)[N]) {
  return {from, ::strnlen(from, N)};
}

}  // namespace prime
