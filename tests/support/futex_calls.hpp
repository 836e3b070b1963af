#pragma once

#include <atomic>
#include <cstdint>

namespace prime::test {

// Futex system calls this test binary's own code made (Prime's doorbells
// among them), for tests that prove a path makes none. Counted by a wrapper
// of syscall(2) that the linker puts in front of it for the binaries that
// link futex_calls.cpp with -Wl,--wrap=syscall (tests/shm/CMakeLists.txt):
// production code carries no counter.
std::uint64_t futex_calls() noexcept;

}  // namespace prime::test
