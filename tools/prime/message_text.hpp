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

namespace prime::tool {

// One type of a description.
struct Layout {
  enum class Kind { number, boolean, character, text, vector, array, record, opaque };
  struct Field {
    std::string name;
    std::size_t offset;
    std::shared_ptr<const Layout> type;
  };
  Kind kind = Kind::opaque;
  std::string number;  // "f64", "i32", ...: a number's kind
  std::size_t size = 0;  // an opaque value's bytes
  std::size_t capacity = 0, size_offset = 0, data_offset = 0, stride = 0;
  std::shared_ptr<const Layout> element;  // of a vector or array
  std::vector<Field> fields;              // of a record
};

// How deep types may nest in a description: deeper ones are refused, so
// no description, however deep, exhausts the stack of what walks it.
inline constexpr std::size_t kMaxLayoutDepth = 64;

namespace detail {

// A description is text another program wrote (std::runtime_error: not the
// user's mistake, unlike bad input, which is std::invalid_argument).
struct LayoutParser {
  std::string_view text;
  std::size_t at = 0;
  std::size_t depth = 0;

  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error{"type description: " + what + " at character " + std::to_string(at + 1) + " of '" +
                             std::string{text} + "'"};
  }
  bool take(char c) {
    if (at < text.size() && text[at] == c) return ++at, true;
    return false;
  }
  void expect(char c) {
    if (!take(c)) fail(std::string{"expected '"} + c + "'");
  }
  std::size_t count() {
    std::size_t n = 0, digits = 0;
    for (; at < text.size() && text[at] >= '0' && text[at] <= '9'; ++at, ++digits)
      if (__builtin_mul_overflow(n, 10, &n) || __builtin_add_overflow(n, static_cast<std::size_t>(text[at] - '0'), &n))
        fail("a number too large");
    if (digits == 0) fail("expected a number");
    return n;
  }
  std::string name() {
    const auto start = at;
    while (at < text.size() && text[at] != '@') ++at;
    return std::string{text.substr(start, at - start)};
  }
  std::shared_ptr<const Layout> type() {
    if (++depth > kMaxLayoutDepth) fail("types nested more than " + std::to_string(kMaxLayoutDepth) + " deep");
    auto layout = std::make_shared<Layout>();
    auto word = [&](std::string_view w) {
      if (text.substr(at, w.size()) != w) return false;
      at += w.size();
      return true;
    };
    if (take('{')) {
      layout->kind = Layout::Kind::record;
      do {
        Layout::Field f;
        f.name = name();
        expect('@');
        f.offset = count();
        expect(':');
        f.type = type();
        layout->fields.push_back(std::move(f));
      } while (take(','));
      expect('}');
    } else if (take('?')) {
      layout->size = count();
    } else if (word("str")) {
      layout->kind = Layout::Kind::text;
      layout->capacity = count();
      expect('@');
      layout->size_offset = count();
      expect(',');
      layout->data_offset = count();
    } else if (word("vec")) {
      layout->kind = Layout::Kind::vector;
      layout->capacity = count();
      expect('@');
      layout->size_offset = count();
      expect(',');
      layout->data_offset = count();
      expect(',');
      layout->stride = count();
      expect('(');
      layout->element = type();
      expect(')');
    } else if (word("arr")) {
      layout->kind = Layout::Kind::array;
      layout->capacity = count();
      expect(',');
      layout->stride = count();
      expect('(');
      layout->element = type();
      expect(')');
    } else if (word("bool")) {
      layout->kind = Layout::Kind::boolean;
    } else if (word("char")) {
      layout->kind = Layout::Kind::character;
    } else {
      for (std::string_view n : {"i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64", "f32", "f64"}) {
        // longest first would be ambiguous only for i8/i16: check the full token
        if (text.substr(at, n.size()) == n &&
            (at + n.size() == text.size() || !(text[at + n.size()] >= '0' && text[at + n.size()] <= '9'))) {
          at += n.size();
          layout->kind = Layout::Kind::number;
          layout->number = std::string{n};
          --depth;
          return layout;
        }
      }
      fail("unknown type");
    }
    --depth;
    return layout;
  }
};

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

// a × b, or the most a size can be when that overflows.
inline std::size_t times(std::size_t a, std::size_t b) {
  std::size_t out = 0;
  return __builtin_mul_overflow(a, b, &out) ? ~std::size_t{0} : out;
}
inline std::size_t plus(std::size_t a, std::size_t b) {
  std::size_t out = 0;
  return __builtin_add_overflow(a, b, &out) ? ~std::size_t{0} : out;
}

}  // namespace detail

// How many bytes of a message a value of layout `t` reaches; the most a
// size can be when its parts do not fit in one another (an element wider
// than its stride). A description is text a topic's creator wrote: one
// from a damaged or foreign program must not send a read or a write past
// the message.
inline std::size_t extent(const Layout& t) {
  using detail::plus;
  using detail::times;
  constexpr auto kNever = ~std::size_t{0};
  switch (t.kind) {
    case Layout::Kind::number: return t.number.size() == 2 ? 1 : t.number.ends_with("16") ? 2 : t.number.ends_with("32") ? 4 : 8;
    case Layout::Kind::boolean:
    case Layout::Kind::character: return 1;
    case Layout::Kind::text: return std::max(plus(t.size_offset, 4), plus(t.data_offset, plus(t.capacity, 1)));  // and its '\0'
    case Layout::Kind::vector:
      if (!t.element || extent(*t.element) > t.stride) return kNever;
      return std::max(plus(t.size_offset, 8), plus(t.data_offset, times(t.capacity, t.stride)));
    case Layout::Kind::array:
      if (!t.element || extent(*t.element) > t.stride) return kNever;
      return times(t.capacity, t.stride);
    case Layout::Kind::record: {
      std::size_t most = 0;
      for (const auto& f : t.fields) most = std::max(most, f.type ? plus(f.offset, extent(*f.type)) : kNever);
      return most;
    }
    case Layout::Kind::opaque: return t.size;
  }
  return kNever;
}

namespace detail {

// How many values a reader of `t` visits, not counting records (which
// hold them): numbers, characters, texts, opaque values and empty arrays,
// each a byte at least in any real type. The most a size can be when that
// overflows.
inline std::size_t values(const Layout& t) {
  switch (t.kind) {
    case Layout::Kind::vector:
    case Layout::Kind::array: return t.capacity == 0 ? 1 : times(t.capacity, values(*t.element));
    case Layout::Kind::record: {
      std::size_t n = 0;
      for (const auto& f : t.fields) n = plus(n, values(*f.type));
      return n;
    }
    default: return 1;
  }
}

// Throws std::runtime_error naming the field (`path`) of `t` that does not
// fit in the `room` bytes it has: every count and extent is held against
// the message before anything reads or writes by them.
inline void check_fits(const Layout& t, std::size_t room, const std::string& path) {
  auto wrong = [&](const std::string& what) {
    throw std::runtime_error{(path.empty() ? std::string{"the message"} : "field '" + path + "'") + ": " + what};
  };
  const auto n = [](std::size_t v) { return std::to_string(v); };
  switch (t.kind) {
    case Layout::Kind::vector:
    case Layout::Kind::array: {
      if (t.stride == 0) wrong("a stride of 0");
      check_fits(*t.element, t.stride, path + "[]");  // an element fits in its stride
      const auto start = t.kind == Layout::Kind::vector ? t.data_offset : 0;
      if (start > room || t.capacity > (room - start) / t.stride)
        wrong(n(t.capacity) + " elements of " + n(t.stride) + " bytes do not fit in " + n(start > room ? 0 : room - start));
      break;
    }
    case Layout::Kind::text:
      if (t.data_offset > room || t.capacity >= room - t.data_offset)
        wrong(n(t.capacity) + " characters do not fit in " + n(t.data_offset > room ? 0 : room - t.data_offset) + " bytes");
      break;
    case Layout::Kind::record:
      for (const auto& f : t.fields) {
        const auto name = path.empty() ? f.name : path + "." + f.name;
        if (f.offset > room)
          throw std::runtime_error{"field '" + name + "': offset " + n(f.offset) + " is past the " + n(room) + " bytes of its record"};
        check_fits(*f.type, room - f.offset, name);
      }
      break;
    default: break;
  }
  if (const auto reach = extent(t); reach > room) wrong(n(reach) + " bytes do not fit in " + n(room));
}

}  // namespace detail

// The layout `description` (prime::schema_of's text) gives, to list its
// fields; throws std::runtime_error when it is not a description.
inline std::shared_ptr<const Layout> parse_layout(std::string_view description) {
  detail::LayoutParser parser{description};
  auto layout = parser.type();
  if (parser.at != description.size()) parser.fail("text after the type");
  return layout;
}

// The same, to read or write messages of `size` bytes by: a description is
// text another program wrote in shared memory, so every count and extent in
// it must fit in the message, and it may name no more values than the
// message has bytes (so reading a message by it takes time in proportion to
// the message). Throws std::runtime_error naming the field that does not.
inline std::shared_ptr<const Layout> parse_layout(std::string_view description, std::size_t size) {
  auto layout = parse_layout(description);
  detail::check_fits(*layout, size, "");
  if (const auto n = detail::values(*layout); n > size)
    throw std::runtime_error{"it names " + std::to_string(n) + " values in " + std::to_string(size) +
                             " bytes: fields laid over one another"};
  return layout;
}

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
