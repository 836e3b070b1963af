#pragma once

// The layout a type's description (prime::schema_of's text) gives: its
// fields, their offsets, kinds and sizes, for a program that never saw the
// type (the prime tool, a recorder writing it as ros2msg). A description
// is text another program wrote, in shared memory or a file: parsing it
// and checking it against a message's size refuses one that would send a
// read or a write past the message.

#include <algorithm>
#include <cstddef>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace prime {

// One type of a description.
struct TypeLayout {
  enum class Kind { number, boolean, character, text, vector, array, record, opaque };
  struct Field {
    std::string name;
    std::size_t offset;
    std::shared_ptr<const TypeLayout> type;
  };
  Kind kind = Kind::opaque;
  std::string number;  // "f64", "i32", ...: a number's kind
  std::size_t size = 0;  // an opaque value's bytes
  std::size_t capacity = 0, size_offset = 0, data_offset = 0, stride = 0;
  std::shared_ptr<const TypeLayout> element;  // of a vector or array
  std::vector<Field> fields;              // of a record
};

// How deep types may nest in a description: deeper ones are refused, so
// no description, however deep, exhausts the stack of what walks it.
inline constexpr std::size_t kMaxLayoutDepth = 64;

namespace detail::layout {

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
  std::shared_ptr<const TypeLayout> type() {
    if (++depth > kMaxLayoutDepth) fail("types nested more than " + std::to_string(kMaxLayoutDepth) + " deep");
    auto layout = std::make_shared<TypeLayout>();
    auto word = [&](std::string_view w) {
      if (text.substr(at, w.size()) != w) return false;
      at += w.size();
      return true;
    };
    if (take('{')) {
      layout->kind = TypeLayout::Kind::record;
      do {
        TypeLayout::Field f;
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
      layout->kind = TypeLayout::Kind::text;
      layout->capacity = count();
      expect('@');
      layout->size_offset = count();
      expect(',');
      layout->data_offset = count();
    } else if (word("vec")) {
      layout->kind = TypeLayout::Kind::vector;
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
      layout->kind = TypeLayout::Kind::array;
      layout->capacity = count();
      expect(',');
      layout->stride = count();
      expect('(');
      layout->element = type();
      expect(')');
    } else if (word("bool")) {
      layout->kind = TypeLayout::Kind::boolean;
    } else if (word("char")) {
      layout->kind = TypeLayout::Kind::character;
    } else {
      for (std::string_view n : {"i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64", "f32", "f64"}) {
        // longest first would be ambiguous only for i8/i16: check the full token
        if (text.substr(at, n.size()) == n &&
            (at + n.size() == text.size() || !(text[at + n.size()] >= '0' && text[at + n.size()] <= '9'))) {
          at += n.size();
          layout->kind = TypeLayout::Kind::number;
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

// a × b, or the most a size can be when that overflows.
inline std::size_t times(std::size_t a, std::size_t b) {
  std::size_t out = 0;
  return __builtin_mul_overflow(a, b, &out) ? ~std::size_t{0} : out;
}
inline std::size_t plus(std::size_t a, std::size_t b) {
  std::size_t out = 0;
  return __builtin_add_overflow(a, b, &out) ? ~std::size_t{0} : out;
}

}  // namespace detail::layout

// How many bytes of a message a value of layout `t` reaches; the most a
// size can be when its parts do not fit in one another (an element wider
// than its stride). A description is text a topic's creator wrote: one
// from a damaged or foreign program must not send a read or a write past
// the message.
inline std::size_t extent(const TypeLayout& t) {
  using detail::layout::plus;
  using detail::layout::times;
  constexpr auto kNever = ~std::size_t{0};
  switch (t.kind) {
    case TypeLayout::Kind::number: return t.number.size() == 2 ? 1 : t.number.ends_with("16") ? 2 : t.number.ends_with("32") ? 4 : 8;
    case TypeLayout::Kind::boolean:
    case TypeLayout::Kind::character: return 1;
    case TypeLayout::Kind::text: return std::max(plus(t.size_offset, 4), plus(t.data_offset, plus(t.capacity, 1)));  // and its '\0'
    case TypeLayout::Kind::vector:
      if (!t.element || extent(*t.element) > t.stride) return kNever;
      return std::max(plus(t.size_offset, 8), plus(t.data_offset, times(t.capacity, t.stride)));
    case TypeLayout::Kind::array:
      if (!t.element || extent(*t.element) > t.stride) return kNever;
      return times(t.capacity, t.stride);
    case TypeLayout::Kind::record: {
      std::size_t most = 0;
      for (const auto& f : t.fields) most = std::max(most, f.type ? plus(f.offset, extent(*f.type)) : kNever);
      return most;
    }
    case TypeLayout::Kind::opaque: return t.size;
  }
  return kNever;
}

namespace detail::layout {

// How many values a reader of `t` visits, not counting records (which
// hold them): numbers, characters, texts, opaque values and empty arrays,
// each a byte at least in any real type. The most a size can be when that
// overflows.
inline std::size_t values(const TypeLayout& t) {
  switch (t.kind) {
    case TypeLayout::Kind::vector:
    case TypeLayout::Kind::array: return t.capacity == 0 ? 1 : times(t.capacity, values(*t.element));
    case TypeLayout::Kind::record: {
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
inline void check_fits(const TypeLayout& t, std::size_t room, const std::string& path) {
  auto wrong = [&](const std::string& what) {
    throw std::runtime_error{(path.empty() ? std::string{"the message"} : "field '" + path + "'") + ": " + what};
  };
  const auto n = [](std::size_t v) { return std::to_string(v); };
  switch (t.kind) {
    case TypeLayout::Kind::vector:
    case TypeLayout::Kind::array: {
      if (t.stride == 0) wrong("a stride of 0");
      check_fits(*t.element, t.stride, path + "[]");  // an element fits in its stride
      const auto start = t.kind == TypeLayout::Kind::vector ? t.data_offset : 0;
      if (start > room || t.capacity > (room - start) / t.stride)
        wrong(n(t.capacity) + " elements of " + n(t.stride) + " bytes do not fit in " + n(start > room ? 0 : room - start));
      break;
    }
    case TypeLayout::Kind::text:
      if (t.data_offset > room || t.capacity >= room - t.data_offset)
        wrong(n(t.capacity) + " characters do not fit in " + n(t.data_offset > room ? 0 : room - t.data_offset) + " bytes");
      break;
    case TypeLayout::Kind::record:
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

}  // namespace detail::layout

// The layout `description` (prime::schema_of's text) gives, to list its
// fields; throws std::runtime_error when it is not a description.
inline std::shared_ptr<const TypeLayout> parse_layout(std::string_view description) {
  detail::layout::LayoutParser parser{description};
  auto layout = parser.type();
  if (parser.at != description.size()) parser.fail("text after the type");
  return layout;
}

// The same, to read or write messages of `size` bytes by: a description is
// text another program wrote in shared memory, so every count and extent in
// it must fit in the message, and it may name no more values than the
// message has bytes (so reading a message by it takes time in proportion to
// the message). Throws std::runtime_error naming the field that does not.
inline std::shared_ptr<const TypeLayout> parse_layout(std::string_view description, std::size_t size) {
  auto layout = parse_layout(description);
  detail::layout::check_fits(*layout, size, "");
  if (const auto n = detail::layout::values(*layout); n > size)
    throw std::runtime_error{"it names " + std::to_string(n) + " values in " + std::to_string(size) +
                             " bytes: fields laid over one another"};
  return layout;
}

}  // namespace prime
