#pragma once

// A small JSON reader for `prime pub` and `prime call`: objects, arrays,
// strings, numbers, true/false/null. Enough to build one message.

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
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

// Parses `text`; throws std::invalid_argument saying where it went wrong.
inline Json parse_json(std::string_view text) {
  std::size_t at = 0;
  auto fail = [&](const std::string& what) -> Json {
    throw std::invalid_argument{"JSON: " + what + " at character " + std::to_string(at + 1)};
  };
  auto skip = [&] {
    while (at < text.size() && std::isspace(static_cast<unsigned char>(text[at]))) ++at;
  };
  auto expect = [&](char c) {
    skip();
    if (at >= text.size() || text[at] != c) fail(std::string{"expected '"} + c + "'");
    ++at;
  };
  std::function<Json()> value = [&]() -> Json {
    skip();
    if (at >= text.size()) return fail("unexpected end");
    const char c = text[at];
    if (c == '{') {
      ++at;
      auto object = std::make_shared<Json::Object>();
      skip();
      if (at < text.size() && text[at] == '}') return ++at, Json{object};
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
        return Json{object};
      }
    }
    if (c == '[') {
      ++at;
      auto array = std::make_shared<Json::Array>();
      skip();
      if (at < text.size() && text[at] == ']') return ++at, Json{array};
      while (true) {
        array->push_back(value());
        skip();
        if (at < text.size() && text[at] == ',') {
          ++at;
          continue;
        }
        expect(']');
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
            unsigned code = 0;
            if (at + 4 >= text.size() || std::sscanf(std::string{text.substr(at + 1, 4)}.c_str(), "%4x", &code) != 1)
              return fail("a \\u escape without four hex digits");
            at += 4;
            unsigned low = 0;  // a pair of surrogates is one code point
            if (code >= 0xd800 && code < 0xdc00 && text.substr(at + 1, 2) == "\\u" && at + 6 < text.size() &&
                std::sscanf(std::string{text.substr(at + 3, 4)}.c_str(), "%4x", &low) == 1 && low >= 0xdc00 && low < 0xe000) {
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
    const std::string rest{text.substr(at)};
    char* end = nullptr;
    const double number = std::strtod(rest.c_str(), &end);
    if (end == rest.c_str()) return fail("unexpected '" + std::string(1, c) + "'");
    at += static_cast<std::size_t>(end - rest.c_str());
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
