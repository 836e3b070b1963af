// Described types as ROS 2's ros2msg and CDR (XCDR1, little-endian).
#include "prime/record/cdr.hpp"

#include <cctype>
#include <cstdint>
#include <cstring>
#include <map>

#include "prime/logic/error.hpp"

namespace prime::record {

namespace {

using K = TypeLayout::Kind;

bool primitive(const TypeLayout& t) { return t.kind == K::number || t.kind == K::boolean || t.kind == K::character; }
std::size_t align(std::size_t at, std::size_t to) { return (at + to - 1) / to * to; }

// Whether `t`, at `base` in memory, lies where CDR puts it (the body at
// `cdr` so far, moved past it): true for the whole type means its bytes
// are its CDR body.
bool plain_at(const TypeLayout& t, std::size_t base, std::size_t& cdr) {
  switch (t.kind) {
    case K::number:
    case K::boolean:
    case K::character: {
      const auto n = extent(t);
      cdr = align(cdr, n);
      if (cdr != base) return false;
      cdr += n;
      return true;
    }
    case K::array:
      if (t.capacity == 0) return true;
      if (primitive(*t.element)) {  // consecutive elements of their own size: the first decides
        if (t.stride != extent(*t.element) || !plain_at(*t.element, base, cdr)) return false;
        cdr += (t.capacity - 1) * t.stride;
        return true;
      }
      for (std::size_t i = 0; i < t.capacity; ++i)
        if (!plain_at(*t.element, base + i * t.stride, cdr)) return false;
      return true;
    case K::record:
      for (const auto& f : t.fields)
        if (!plain_at(*f.type, base + f.offset, cdr)) return false;
      return true;
    default: return false;  // strings and sequences carry a length in CDR; opaque bytes say nothing
  }
}

bool describable(const TypeLayout& t) {
  switch (t.kind) {
    case K::opaque: return false;
    case K::vector:
    case K::array: return describable(*t.element);
    case K::record:
      for (const auto& f : t.fields)
        if (!describable(*f.type)) return false;
      return true;
    default: return true;
  }
}

template <class T>
T load(const std::byte* at) {
  T v;
  std::memcpy(&v, at, sizeof v);
  return v;
}

void encode_at(const TypeLayout& t, const std::byte* at, std::vector<std::byte>& out, std::size_t origin) {
  auto pad = [&](std::size_t to) { out.resize(origin + align(out.size() - origin, to), std::byte{0}); };
  auto put = [&](const void* p, std::size_t n) {
    const auto* b = static_cast<const std::byte*>(p);
    out.insert(out.end(), b, b + n);
  };
  switch (t.kind) {
    case K::number:
    case K::boolean:
    case K::character: {
      const auto n = extent(t);
      pad(n);
      put(at, n);
      return;
    }
    case K::text: {
      const auto n = std::min<std::size_t>(load<std::uint32_t>(at + t.size_offset), t.capacity);
      pad(4);
      const auto with_nul = static_cast<std::uint32_t>(n + 1);
      put(&with_nul, 4);
      put(at + t.data_offset, n);
      out.push_back(std::byte{0});
      return;
    }
    case K::vector: {
      const auto n = std::min<std::size_t>(load<std::uint64_t>(at + t.size_offset), t.capacity);
      pad(4);
      const auto count = static_cast<std::uint32_t>(n);
      put(&count, 4);
      for (std::size_t i = 0; i < n; ++i) encode_at(*t.element, at + t.data_offset + i * t.stride, out, origin);
      return;
    }
    case K::array:
      for (std::size_t i = 0; i < t.capacity; ++i) encode_at(*t.element, at + i * t.stride, out, origin);
      return;
    case K::record:
      for (const auto& f : t.fields) encode_at(*f.type, at + f.offset, out, origin);
      return;
    case K::opaque: return;  // never: a codec is made only for types with none
  }
}

// Reads CDR body `in` from `at` into the type's bytes at `to`.
struct Decoder {
  std::span<const std::byte> in;
  std::size_t at;
  const std::string& what;

  [[noreturn]] void damaged(const std::string& why) const {
    throw Failure{{Errc::damaged, what + ": not a CDR message of its type: " + why}};
  }
  const std::byte* take(std::size_t n, std::size_t alignment) {
    at = align(at, alignment);
    if (at > in.size() || n > in.size() - at) damaged("it ends before its fields do");
    const auto* p = in.data() + at;
    at += n;
    return p;
  }
  void read(const TypeLayout& t, std::byte* to) {
    switch (t.kind) {
      case K::number:
      case K::boolean:
      case K::character: {
        const auto n = extent(t);
        std::memcpy(to, take(n, n), n);
        return;
      }
      case K::text: {
        const auto with_nul = load<std::uint32_t>(take(4, 4));
        if (with_nul == 0) damaged("a string without its terminating zero");
        if (with_nul - 1 > t.capacity)
          damaged("a string of " + std::to_string(with_nul - 1) + " characters, in a field of at most " + std::to_string(t.capacity));
        std::memcpy(to + t.data_offset, take(with_nul, 1), with_nul - 1);
        const auto n = with_nul - 1;
        std::memcpy(to + t.size_offset, &n, sizeof n);
        return;
      }
      case K::vector: {
        const auto count = load<std::uint32_t>(take(4, 4));
        if (count > t.capacity)
          damaged("a sequence of " + std::to_string(count) + " elements, in a field of at most " + std::to_string(t.capacity));
        for (std::size_t i = 0; i < count; ++i) read(*t.element, to + t.data_offset + i * t.stride);
        const std::uint64_t n = count;
        std::memcpy(to + t.size_offset, &n, sizeof n);
        return;
      }
      case K::array:
        for (std::size_t i = 0; i < t.capacity; ++i) read(*t.element, to + i * t.stride);
        return;
      case K::record:
        for (const auto& f : t.fields) read(*f.type, to + f.offset);
        return;
      case K::opaque: return;
    }
  }
};

constexpr std::byte kHeader[4] = {std::byte{0x00}, std::byte{0x01}, std::byte{0x00}, std::byte{0x00}};  // CDR_LE

// ros2msg: a type's name for a field of it, and the nested record types it needs.
struct Definitions {
  std::string package;
  std::vector<std::pair<std::string, std::string>> nested;  // name, fields

  std::string element_name(const TypeLayout& t, const std::string& owner, const std::string& field) {
    switch (t.kind) {
      case K::number: {
        static const std::map<std::string, std::string> names{{"f64", "float64"}, {"f32", "float32"}, {"i8", "int8"},
                                                              {"u8", "uint8"},     {"i16", "int16"},   {"u16", "uint16"},
                                                              {"i32", "int32"},    {"u32", "uint32"},  {"i64", "int64"},
                                                              {"u64", "uint64"}};
        return names.at(t.number);
      }
      case K::boolean: return "bool";
      case K::character: return "char";
      case K::text: return "string<=" + std::to_string(t.capacity);
      case K::vector: return element_name(*t.element, owner, field) + "[<=" + std::to_string(t.capacity) + "]";
      case K::array: return element_name(*t.element, owner, field) + "[" + std::to_string(t.capacity) + "]";
      case K::record: {
        // A nested record has no name of its own in a description: its
        // owner's and its field's, as a ROS type's name is written.
        std::string name = owner;
        bool upper = true;
        for (const char c : field) {
          if (c == '_') {
            upper = true;
            continue;
          }
          name += upper ? static_cast<char>(std::toupper(static_cast<unsigned char>(c))) : c;
          upper = false;
        }
        nested.emplace_back(name, fields(t, name));
        return package + "/" + name;
      }
      case K::opaque: return "uint8[" + std::to_string(t.size) + "]";
    }
    return {};
  }
  std::string fields(const TypeLayout& record, const std::string& name) {
    std::string text;
    for (const auto& f : record.fields) text += element_name(*f.type, name, f.name) + " " + f.name + "\n";
    return text;
  }
};

}  // namespace

std::optional<CdrCodec> CdrCodec::of(std::string_view description, std::size_t size) {
  std::shared_ptr<const TypeLayout> layout;
  try {
    layout = parse_layout(description, size);
  } catch (const std::runtime_error&) {
    return std::nullopt;
  }
  if (layout->kind != K::record || !describable(*layout)) return std::nullopt;
  std::size_t body = 0;
  const bool plain = plain_at(*layout, 0, body);
  return CdrCodec{std::move(layout), size, plain, plain ? body : 0};
}

std::string CdrCodec::definition(std::string_view ros2) const {
  // "pkg/msg/Name": nested types are written "pkg/Name", as ROS 2 writes them.
  const std::string full{ros2};
  const auto slash = full.find('/');
  const auto last = full.rfind('/');
  Definitions d{slash == std::string::npos ? std::string{"prime"} : full.substr(0, slash), {}};
  const auto name = last == std::string::npos ? full : full.substr(last + 1);
  auto text = d.fields(*layout_, name);
  for (const auto& [nested, fields] : d.nested)
    text += std::string(80, '=') + "\nMSG: " + d.package + "/" + nested + "\n" + fields;
  return text;
}

void CdrCodec::encode(std::span<const std::byte> sample, std::vector<std::byte>& out) const {
  out.assign(std::begin(kHeader), std::end(kHeader));
  if (plain_) {
    out.insert(out.end(), sample.begin(), sample.begin() + static_cast<std::ptrdiff_t>(std::min(body_, sample.size())));
    return;
  }
  encode_at(*layout_, sample.data(), out, sizeof kHeader);
}

std::vector<std::byte> CdrCodec::decode(std::span<const std::byte> message, const std::string& what) const {
  if (message.size() < sizeof kHeader || std::memcmp(message.data(), kHeader, 2) != 0)
    throw Failure{{Errc::damaged, what + ": not a CDR little-endian message (its header is not 00 01)"}};
  const auto body = message.subspan(sizeof kHeader);
  std::vector<std::byte> out(size_, std::byte{0});
  if (plain_) {
    if (body.size() < body_ || body.size() > size_)
      throw Failure{{Errc::damaged, what + ": a CDR body of " + std::to_string(body.size()) + " bytes, not the " +
                                        std::to_string(body_) + " of its type"}};
    std::memcpy(out.data(), body.data(), body.size());
    return out;
  }
  Decoder{body, 0, what}.read(*layout_, out.data());
  return out;
}

std::string ros2_name(std::string_view cpp_name) {
  std::vector<std::string> parts;
  std::string part;
  for (std::size_t i = 0; i < cpp_name.size(); ++i) {
    if (cpp_name.substr(i, 2) == "::") {
      parts.push_back(part);
      part.clear();
      ++i;
      continue;
    }
    const char c = cpp_name[i];
    part += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  }
  std::string package;
  for (const auto& p : parts) package += (package.empty() ? "" : "_") + p;
  if (package.empty()) package = "prime";
  if (!part.empty() && !std::isupper(static_cast<unsigned char>(part[0])))
    part[0] = std::isalpha(static_cast<unsigned char>(part[0])) ? static_cast<char>(std::toupper(static_cast<unsigned char>(part[0])))
                                                                 : 'T';
  return package + "/msg/" + part;
}

}  // namespace prime::record
