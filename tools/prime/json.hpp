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
        if (text[at] == '\\' && at + 1 < text.size()) ++at;
        s.push_back(text[at]);
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

// Writes `s` as a JSON string.
inline std::string quote(std::string_view s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out.push_back('\\');
    if (static_cast<unsigned char>(c) < 0x20) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\u%04x", c);
      out += hex;
    } else {
      out.push_back(c);
    }
  }
  return out + "\"";
}

}  // namespace prime::tool
