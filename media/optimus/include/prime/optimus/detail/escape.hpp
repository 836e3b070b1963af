#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace prime::optimus::detail {

// A name as it goes into a key: letters, digits and "-_./~" as they are,
// every other byte as %XX. No name then holds the ':' that parts a key, so
// no two names, and no name and a key built from another (its ":alive"),
// make one key; nor does a name hold a glob character, so a KEYS or SCAN
// pattern built from it matches it alone.
inline bool keeps_as_is(char c) noexcept {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '_' ||
         c == '.' || c == '/' || c == '~';
}
inline std::string escaped(std::string_view name) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  out.reserve(name.size());
  for (const char c : name) {
    if (keeps_as_is(c)) {
      out.push_back(c);
    } else {
      const auto byte = static_cast<unsigned char>(c);
      out.append({'%', kHex[byte >> 4], kHex[byte & 15]});
    }
  }
  return out;
}
// The text %XX escapes stand for (a name in a key, a user or password in a
// URL); null when an escape is cut short or not hex.
inline std::optional<std::string> unescaped(std::string_view text) {
  const auto hex = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
  };
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] != '%') {
      out.push_back(text[i]);
      continue;
    }
    if (i + 2 >= text.size()) return std::nullopt;
    const int high = hex(text[i + 1]), low = hex(text[i + 2]);
    if (high < 0 || low < 0) return std::nullopt;
    out.push_back(static_cast<char>(high * 16 + low));
    i += 2;
  }
  return out;
}

}  // namespace prime::optimus::detail
