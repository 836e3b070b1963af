#pragma once

// A small JSON reader for `prime pub` and `prime call`: objects, arrays,
// strings, numbers, true/false/null. Enough to build one message.

#include <cctype>
#include <charconv>
#include <cstdio>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <variant>
#include <vector>

namespace prime::tool {

struct Json {
  using Object = std::map<std::string, Json>;
  using Array = std::vector<Json>;
  std::variant<std::nullptr_t, bool, double, std::string, std::shared_ptr<Array>, std::shared_ptr<Object>> value;

  [[nodiscard]] bool is_object() const { return std::holds_alternative<std::shared_ptr<Object>>(value); }
  [[nodiscard]] bool is_array() const { return std::holds_alternative<std::shared_ptr<Array>>(value); }
  [[nodiscard]] const Object& object() const { return *std::get<std::shared_ptr<Object>>(value); }
  [[nodiscard]] const Array& array() const { return *std::get<std::shared_ptr<Array>>(value); }
};

// Code point `code` as UTF-8.
inline void append_utf8(std::string& out, unsigned code) {
  if (code < 0x80) {
    out.push_back(static_cast<char>(code));
  } else if (code < 0x800) {
    out.push_back(static_cast<char>(0xc0 | (code >> 6)));
    out.push_back(static_cast<char>(0x80 | (code & 0x3f)));
  } else if (code < 0x10000) {
    out.push_back(static_cast<char>(0xe0 | (code >> 12)));
    out.push_back(static_cast<char>(0x80 | ((code >> 6) & 0x3f)));
    out.push_back(static_cast<char>(0x80 | (code & 0x3f)));
  } else {
    out.push_back(static_cast<char>(0xf0 | (code >> 18)));
    out.push_back(static_cast<char>(0x80 | ((code >> 12) & 0x3f)));
    out.push_back(static_cast<char>(0x80 | ((code >> 6) & 0x3f)));
    out.push_back(static_cast<char>(0x80 | (code & 0x3f)));
  }
}

// How deep arrays and objects may nest: deeper input is refused, so no
// input, however deep, exhausts the stack of the reader (or of what walks
// the value after it).
inline constexpr std::size_t kMaxJsonDepth = 64;

// How many characters the JSON number `text` starts with takes; 0 when it
// starts with none (JSON writes no hex, '+', leading zero, bare point,
// infinity or NaN).
inline std::size_t json_number_length(std::string_view text) {
  std::size_t at = 0;
  const auto digits = [&] {
    const auto start = at;
    while (at < text.size() && text[at] >= '0' && text[at] <= '9') ++at;
    return at > start;
  };
  if (at < text.size() && text[at] == '-') ++at;
  if (at < text.size() && text[at] == '0') ++at;
  else if (!digits()) return 0;
  if (at < text.size() && text[at] == '.' && (++at, !digits())) return 0;
  if (at < text.size() && (text[at] == 'e' || text[at] == 'E')) {
    ++at;
    if (at < text.size() && (text[at] == '+' || text[at] == '-')) ++at;
    if (!digits()) return 0;
  }
  return at;
}

// Parses `text`; throws std::invalid_argument saying what went wrong and where.
inline Json parse_json(std::string_view text) {
  std::size_t at = 0;
  std::size_t depth = 0;
  auto fail_at = [&](const std::string& what, std::size_t where) -> Json {
    throw std::invalid_argument{"JSON: " + what + " at character " + std::to_string(where + 1)};
  };
  auto fail = [&](const std::string& what) { return fail_at(what, at); };
  auto skip = [&] {
    while (at < text.size() && std::isspace(static_cast<unsigned char>(text[at]))) ++at;
  };
  auto expect = [&](char c) {
    skip();
    if (at >= text.size() || text[at] != c) fail(std::string{"expected '"} + c + "'");
    ++at;
  };
  // The four hex digits of the \u escape whose 'u' is at `u`.
  auto hex4 = [&](std::size_t u) {
    unsigned code = 0;
    for (std::size_t i = u + 1; i < u + 5; ++i) {
      const char c = i < text.size() ? text[i] : '\0';
      const int digit = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : c >= 'A' && c <= 'F' ? c - 'A' + 10 : -1;
      if (digit < 0) fail_at("a \\u escape without four hex digits", u - 1);
      code = code * 16 + static_cast<unsigned>(digit);
    }
    return code;
  };
  std::function<Json()> value = [&]() -> Json {
    skip();
    if (at >= text.size()) return fail("unexpected end");
    const char c = text[at];
    if ((c == '{' || c == '[') && ++depth > kMaxJsonDepth)
      return fail("arrays and objects nested more than " + std::to_string(kMaxJsonDepth) + " deep");
    if (c == '{') {
      ++at;
      auto object = std::make_shared<Json::Object>();
      skip();
      if (at < text.size() && text[at] == '}') return ++at, --depth, Json{object};
      while (true) {
        skip();
        auto key = value();
        if (!std::holds_alternative<std::string>(key.value)) return fail("expected a field name");
        expect(':');
        (*object)[std::get<std::string>(key.value)] = value();
        skip();
        if (at < text.size() && text[at] == ',') {
          ++at;
          continue;
        }
        expect('}');
        --depth;
        return Json{object};
      }
    }
    if (c == '[') {
      ++at;
      auto array = std::make_shared<Json::Array>();
      skip();
      if (at < text.size() && text[at] == ']') return ++at, --depth, Json{array};
      while (true) {
        array->push_back(value());
        skip();
        if (at < text.size() && text[at] == ',') {
          ++at;
          continue;
        }
        expect(']');
        --depth;
        return Json{array};
      }
    }
    if (c == '"') {
      std::string s;
      for (++at; at < text.size() && text[at] != '"'; ++at) {
        if (text[at] != '\\') {
          s.push_back(text[at]);
          continue;
        }
        if (++at >= text.size()) break;
        switch (text[at]) {
          case 'n': s.push_back('\n'); break;
          case 't': s.push_back('\t'); break;
          case 'r': s.push_back('\r'); break;
          case 'b': s.push_back('\b'); break;
          case 'f': s.push_back('\f'); break;
          case 'u': {
            const auto escape = at - 1;
            auto code = hex4(at);
            at += 4;
            // A code point past U+FFFF is a pair of surrogates: a high one, then a low one.
            if (code >= 0xdc00 && code < 0xe000) return fail_at("a low surrogate without a high one", escape);
            if (code >= 0xd800 && code < 0xdc00) {
              const bool low_follows = text.substr(at + 1, 2) == "\\u";
              const auto low = low_follows ? hex4(at + 2) : 0;
              if (low < 0xdc00 || low >= 0xe000) return fail_at("a high surrogate without its low one", escape);
              code = 0x10000 + ((code - 0xd800) << 10) + (low - 0xdc00);
              at += 6;
            }
            append_utf8(s, code);
            break;
          }
          default: s.push_back(text[at]);  // \" \\ \/
        }
      }
      if (at >= text.size()) return fail("unterminated string");
      ++at;
      return Json{s};
    }
    if (text.substr(at, 4) == "true") return at += 4, Json{true};
    if (text.substr(at, 5) == "false") return at += 5, Json{false};
    if (text.substr(at, 4) == "null") return at += 4, Json{nullptr};
    const auto length = json_number_length(text.substr(at));
    if (length == 0) return fail(c == '-' || (c >= '0' && c <= '9') ? "a malformed number" : "unexpected '" + std::string(1, c) + "'");
    double number = 0;
    if (std::from_chars(text.data() + at, text.data() + at + length, number).ec != std::errc{})
      return fail("a number out of range");
    at += length;
    return Json{number};
  };
  auto result = value();
  skip();
  if (at != text.size()) fail("text after the value");
  return result;
}

// How many bytes of well-formed UTF-8 start `s` (one character), or 0 when
// they are not: a stray continuation byte, a truncated or overlong
// sequence, a surrogate, or a code point past U+10FFFF.
inline std::size_t utf8_length(std::string_view s) {
  const auto byte = [&](std::size_t i) { return static_cast<unsigned char>(s[i]); };
  const auto lead = byte(0);
  if (lead < 0x80) return 1;
  const std::size_t n = lead >= 0xc2 && lead <= 0xdf ? 2 : lead >= 0xe0 && lead <= 0xef ? 3 : lead >= 0xf0 && lead <= 0xf4 ? 4 : 0;
  if (n == 0 || s.size() < n) return 0;
  for (std::size_t i = 1; i < n; ++i)
    if ((byte(i) & 0xc0) != 0x80) return 0;
  // The second byte's range where the lead alone does not rule out an
  // overlong form, a surrogate (U+D800..DFFF) or a code point past U+10FFFF.
  if ((lead == 0xe0 && byte(1) < 0xa0) || (lead == 0xed && byte(1) > 0x9f) || (lead == 0xf0 && byte(1) < 0x90) ||
      (lead == 0xf4 && byte(1) > 0x8f))
    return 0;
  return n;
}

// `s` as a JSON string. Text that is not UTF-8 (a message's characters in
// another encoding, or bytes that are not text) would make the whole output
// something no JSON reader takes: each byte that is not part of a UTF-8
// character becomes U+FFFD, the replacement character.
inline std::string quote(std::string_view s) {
  std::string out = "\"";
  for (std::size_t at = 0; at < s.size();) {
    const char c = s[at];
    const auto length = utf8_length(s.substr(at));
    if (length == 0) {
      out += "\\ufffd";
      ++at;
      continue;
    }
    if (length > 1) {
      out.append(s.substr(at, length));
      at += length;
      continue;
    }
    if (c == '"' || c == '\\') out.push_back('\\');
    if (static_cast<unsigned char>(c) < 0x20) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\u%04x", c);
      out += hex;
    } else {
      out.push_back(c);
    }
    ++at;
  }
  return out + "\"";
}

}  // namespace prime::tool
