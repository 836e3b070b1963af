#pragma once

// Messages as text, for a tool that never saw their C++ types: the layout a
// type's description (prime::schema_of) gives, values read from bytes as
// YAML-like lines or JSON, and bytes built from JSON.

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <iomanip>
#include <memory>
#include <ostream>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "json.hpp"
#include "prime/common/type_layout.hpp"

namespace prime::tool {

using prime::extent;
using prime::kMaxLayoutDepth;
using Layout = prime::TypeLayout;
using prime::parse_layout;

namespace detail {

template <class T>
T load(const std::byte* at) {
  T v;
  std::memcpy(&v, at, sizeof v);
  return v;
}
template <class T>
void store(std::byte* at, T v) {
  std::memcpy(at, &v, sizeof v);
}

inline std::string number_text(const std::string& kind, const std::byte* at) {
  std::ostringstream out;
  if (kind == "f64") out << load<double>(at);
  else if (kind == "f32") out << load<float>(at);
  else if (kind == "i8") out << int{load<std::int8_t>(at)};
  else if (kind == "i16") out << load<std::int16_t>(at);
  else if (kind == "i32") out << load<std::int32_t>(at);
  else if (kind == "i64") out << load<std::int64_t>(at);
  else if (kind == "u8") out << unsigned{load<std::uint8_t>(at)};
  else if (kind == "u16") out << load<std::uint16_t>(at);
  else if (kind == "u32") out << load<std::uint32_t>(at);
  else out << load<std::uint64_t>(at);
  return out.str();
}

inline std::size_t count_at(const Layout& t, const std::byte* data) {
  const auto n = t.kind == Layout::Kind::text ? load<std::uint32_t>(data + t.size_offset)
                                              : static_cast<std::size_t>(load<std::uint64_t>(data + t.size_offset));
  return n > t.capacity ? t.capacity : n;  // never read past the storage, whatever the bytes say
}

}  // namespace detail

// Bytes as hex, at most `most` of them.
inline std::string hex(std::span<const std::byte> bytes, std::size_t most = 32) {
  std::ostringstream out;
  for (std::size_t i = 0; i < bytes.size() && i < most; ++i)
    out << std::hex << std::setw(2) << std::setfill('0') << static_cast<unsigned>(bytes[i]) << (i + 1 < bytes.size() ? " " : "");
  if (bytes.size() > most) out << "...";
  return out.str();
}

// The value at `data` as JSON.
inline std::string to_json(const Layout& t, const std::byte* data) {
  using K = Layout::Kind;
  switch (t.kind) {
    case K::number: return detail::number_text(t.number, data);
    case K::boolean: return detail::load<bool>(data) ? "true" : "false";
    case K::character: return quote(std::string_view{reinterpret_cast<const char*>(data), 1});
    case K::text: return quote(std::string_view{reinterpret_cast<const char*>(data + t.data_offset), detail::count_at(t, data)});
    case K::vector:
    case K::array: {
      const auto n = t.kind == K::vector ? detail::count_at(t, data) : t.capacity;
      const auto* items = data + (t.kind == K::vector ? t.data_offset : 0);
      std::string out = "[";
      for (std::size_t i = 0; i < n; ++i) out += (i ? "," : "") + to_json(*t.element, items + i * t.stride);
      return out + "]";
    }
    case K::record: {
      std::string out = "{";
      for (std::size_t i = 0; i < t.fields.size(); ++i)
        out += (i ? "," : "") + quote(t.fields[i].name) + ":" + to_json(*t.fields[i].type, data + t.fields[i].offset);
      return out + "}";
    }
    case K::opaque: return quote(hex({data, t.size}, t.size));
  }
  return "null";
}

// The value at `data` as indented "name: value" lines, as `ros2 topic echo` prints.
inline void print_fields(std::ostream& out, const Layout& t, const std::byte* data, int indent = 0) {
  using K = Layout::Kind;
  const std::string pad(static_cast<std::size_t>(indent), ' ');
  if (t.kind != K::record) {
    out << pad << to_json(t, data) << '\n';
    return;
  }
  for (const auto& f : t.fields) {
    if (f.type->kind == K::record) {
      out << pad << f.name << ":\n";
      print_fields(out, *f.type, data + f.offset, indent + 2);
    } else {
      out << pad << f.name << ": " << to_json(*f.type, data + f.offset) << '\n';
    }
  }
}

// A number as a person writes it: no exponent for a whole one.
inline std::string number_words(double v) {
  std::ostringstream out;
  if (v == std::floor(v) && std::fabs(v) < 1e19) out << std::fixed << std::setprecision(0);
  out << v;
  return out.str();
}

// Writes `value` into the message at `data`, as the layout says; throws
// std::invalid_argument naming the field (`where`) that does not fit.
inline void fill(const Layout& t, std::byte* data, const Json& value, const std::string& where = "the message") {
  using K = Layout::Kind;
  auto wrong = [&](const std::string& what) { throw std::invalid_argument{where + ": " + what}; };
  auto number = [&]() -> double {
    if (auto* d = std::get_if<double>(&value.value)) return *d;
    if (auto* b = std::get_if<bool>(&value.value)) return *b ? 1 : 0;
    if (auto* s = std::get_if<std::string>(&value.value)) {  // all of it a number ("nan" too), or none
      double v = 0;
      const auto [end, error] = std::from_chars(s->data(), s->data() + s->size(), v);
      if (error == std::errc{} && end == s->data() + s->size()) return v;
      wrong("expected a number, not " + quote(*s));
    }
    wrong("expected a number");
    return 0;
  };
  switch (t.kind) {
    case K::number: {
      const auto v = number();
      const auto& n = t.number;
      if (n[0] != 'f') {  // a whole number within the type's range, or an error naming both
        const int bits = std::stoi(n.substr(1));
        const bool is_signed = n[0] == 'i';
        const double low = is_signed ? -std::ldexp(1.0, bits - 1) : 0.0;
        const double high = std::ldexp(1.0, is_signed ? bits - 1 : bits);  // the first value past the range
        if (v != std::floor(v) || v < low || v >= high)
          wrong(number_words(v) + " is not a whole number from " + number_words(low) + " to " + number_words(high - 1) +
                " (" + n + ")");
      }
      if (n == "f64") detail::store(data, v);
      else if (n == "f32") detail::store(data, static_cast<float>(v));
      else if (n == "i8") detail::store(data, static_cast<std::int8_t>(v));
      else if (n == "i16") detail::store(data, static_cast<std::int16_t>(v));
      else if (n == "i32") detail::store(data, static_cast<std::int32_t>(v));
      else if (n == "i64") detail::store(data, static_cast<std::int64_t>(v));
      else if (n == "u8") detail::store(data, static_cast<std::uint8_t>(v));
      else if (n == "u16") detail::store(data, static_cast<std::uint16_t>(v));
      else if (n == "u32") detail::store(data, static_cast<std::uint32_t>(v));
      else detail::store(data, static_cast<std::uint64_t>(v));
      return;
    }
    case K::boolean: detail::store(data, number() != 0); return;
    case K::character: {
      auto* s = std::get_if<std::string>(&value.value);
      if (!s || s->size() != 1) wrong("expected one character");
      data[0] = static_cast<std::byte>((*s)[0]);
      return;
    }
    case K::text: {
      auto* s = std::get_if<std::string>(&value.value);
      if (!s) wrong("expected text");
      if (s->size() > t.capacity) wrong("text of " + std::to_string(s->size()) + " characters does not fit in " + std::to_string(t.capacity));
      detail::store(data + t.size_offset, static_cast<std::uint32_t>(s->size()));
      std::memcpy(data + t.data_offset, s->data(), s->size());
      data[t.data_offset + s->size()] = std::byte{0};
      return;
    }
    case K::vector:
    case K::array: {
      if (!value.is_array()) wrong("expected a list");
      const auto& items = value.array();
      if (items.size() > t.capacity) wrong(std::to_string(items.size()) + " values do not fit in " + std::to_string(t.capacity));
      if (t.kind == K::array && items.size() != t.capacity) wrong("expected " + std::to_string(t.capacity) + " values");
      auto* at = data + (t.kind == K::vector ? t.data_offset : 0);
      if (t.kind == K::vector) detail::store(data + t.size_offset, static_cast<std::uint64_t>(items.size()));
      for (std::size_t i = 0; i < items.size(); ++i) fill(*t.element, at + i * t.stride, items[i], where + "[" + std::to_string(i) + "]");
      return;
    }
    case K::record: {
      if (!value.is_object()) wrong("expected {field: value, ...}");
      for (const auto& [name, v] : value.object()) {
        const Layout::Field* field = nullptr;
        for (const auto& f : t.fields)
          if (f.name == name) field = &f;
        if (!field) {
          std::string known;
          for (const auto& f : t.fields) known += (known.empty() ? "" : ", ") + f.name;
          wrong("no field '" + name + "' (it has " + known + ")");
        }
        fill(*field->type, data + field->offset, v, where == "the message" ? name : where + "." + name);
      }
      return;
    }
    case K::opaque: wrong("its type has no description (PRIME_DESCRIBE): it cannot be written from text");
  }
}

// `field=value` words ("x=1", "pose.theta=0.5", "frame=laser", "ranges=[1,2]")
// as one JSON object; a value that is not JSON is text, unless it starts
// as JSON's lists, objects and strings do: then it is meant as JSON, and
// its error is the answer.
inline Json from_assignments(const std::vector<std::string>& words) {
  auto root = std::make_shared<Json::Object>();
  for (const auto& word : words) {
    const auto eq = word.find('=');
    if (eq == std::string::npos) throw std::invalid_argument{"'" + word + "': expected field=value"};
    const auto path = word.substr(0, eq);
    const auto text = word.substr(eq + 1);
    Json v;
    try {
      v = parse_json(text);
    } catch (const std::invalid_argument& e) {
      if (!text.empty() && (text[0] == '[' || text[0] == '{' || text[0] == '"'))
        throw std::invalid_argument{path + ": " + e.what()};
      v = Json{text};
    }
    auto* object = root.get();
    std::size_t start = 0;
    while (true) {
      const auto dot = path.find('.', start);
      const auto key = path.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
      if (dot == std::string::npos) {
        (*object)[key] = v;
        break;
      }
      auto& next = (*object)[key];
      if (!next.is_object()) next = Json{std::make_shared<Json::Object>()};
      object = std::get<std::shared_ptr<Json::Object>>(next.value).get();
      start = dot + 1;
    }
  }
  return Json{root};
}

}  // namespace prime::tool
