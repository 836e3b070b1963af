#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "prime/common/fixed_text.hpp"

namespace prime {

// A message type may say which version of its layout it is; bump it when a
// field changes meaning without changing the size.
//   template <> inline constexpr std::uint32_t layout_version<Scan> = 2;
template <class T>
inline constexpr std::uint32_t layout_version = 1;

namespace detail {

template <class T>
constexpr std::string_view pretty_name() {
  constexpr std::string_view f = __PRETTY_FUNCTION__;  // "... pretty_name() [with T = Scan; ...]"
  constexpr std::string_view key = "T = ";
  const auto begin = f.find(key) + key.size();
  const auto end = f.find_first_of(";]", begin);
  return f.substr(begin, end - begin);
}

constexpr std::uint64_t fnv1a(std::string_view bytes, std::uint64_t h = 0xcbf29ce484222325ull) {
  for (char c : bytes) h = (h ^ static_cast<unsigned char>(c)) * 0x100000001b3ull;
  return h;
}

}  // namespace detail

// What a topic, key or service records about its message type, so that
// opening it with another type is an error and never a misread.
struct Fingerprint {
  static constexpr std::size_t kNameCapacity = 96;

  char name[kNameCapacity]{};  // the type's name as the compiler spells it (truncated)
  std::uint64_t size = 0;
  std::uint64_t alignment = 0;
  std::uint32_t layout_version = 0;
  std::uint64_t hash = 0;  // of the full name, size, alignment and layout version

  template <class T>
  static constexpr Fingerprint of() {
    return named(detail::pretty_name<T>(), sizeof(T), alignof(T), prime::layout_version<T>);
  }

  // The fingerprint of a type named `full` as the compiler spells it (for
  // bindings that know a C++ type by its name, size, alignment and layout
  // version: what of<T>() takes from T).
  static constexpr Fingerprint named(std::string_view full, std::uint64_t size, std::uint64_t alignment,
                                     std::uint32_t layout_version) {
    Fingerprint f;
    const auto n = full.size() < kNameCapacity - 1 ? full.size() : kNameCapacity - 1;
    for (std::size_t i = 0; i < n; ++i) f.name[i] = full[i];
    f.size = size;
    f.alignment = alignment;
    f.layout_version = layout_version;
    auto h = detail::fnv1a(full);
    for (auto v : {f.size, f.alignment, std::uint64_t{f.layout_version}}) {
      for (int i = 0; i < 8; ++i) h = (h ^ ((v >> (8 * i)) & 0xff)) * 0x100000001b3ull;
    }
    f.hash = h;
    return f;
  }

  [[nodiscard]] friend constexpr bool operator==(const Fingerprint& a, const Fingerprint& b) noexcept {
    return a.hash == b.hash && a.size == b.size && a.alignment == b.alignment &&
           a.layout_version == b.layout_version;
  }

  // "Scan (24 bytes, align 8, layout 1)"
  [[nodiscard]] std::string describe() const {
    // The name may come from shared memory: read within its room.
    return read_text(name) + " (" + std::to_string(size) + " bytes, align " + std::to_string(alignment) + ", layout " +
           std::to_string(layout_version) + ")";
  }
};

}  // namespace prime
