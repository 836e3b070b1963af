#pragma once

#include <cstdint>

namespace prime::shm::detail {

// Which processes can share a segment, and which programs can link the
// library, in one place. Each kind of segment
// starts with a magic number, stored last by its creator once everything
// else is set; topics and services also carry a layout version. A process
// whose numbers differ refuses the segment by name ("made by another
// version of Prime", Errc::type_mismatch) instead of misreading it.
// Change a kind's number whenever its layout or protocol changes; the
// registry has no version word, so its magic's last character counts.
// (Error codes also cross processes: their numbers are kept in
// prime/logic/error.hpp.)
inline constexpr std::uint64_t kRegistryMagic = 0x5052494d45524734ull;  // "PRIMERG4"
inline constexpr std::uint64_t kTopicMagic = 0x5052494d45534d34ull;     // "PRIMESM4"
inline constexpr std::uint32_t kTopicLayout = 12;
inline constexpr std::uint64_t kServiceMagic = 0x5052494d45535633ull;  // "PRIMESV3"
inline constexpr std::uint32_t kServiceLayout = 5;

// libprime_shm's ABI version (its SOVERSION, read from here by
// media/shm/CMakeLists.txt): raise it whenever a compiled function's
// signature or a type its callers lay out changes.
inline constexpr int kAbi = 2;

}  // namespace prime::shm::detail
