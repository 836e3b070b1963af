#pragma once

// The primitive encodings of MCAP records (mcap.dev/spec, "Serialization"):
// little-endian integers, strings and byte arrays behind a uint32 length,
// maps behind a uint32 length in bytes. Appended to a buffer, or read from
// one within its bounds: a length that runs past them is Errc::damaged.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "prime/logic/error.hpp"

namespace prime::record::detail {

enum Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kStatistics = 0x0b,
  kMetadata = 0x0c,
  kMetadataIndex = 0x0d,
  kSummaryOffset = 0x0e,
  kDataEnd = 0x0f,
};

inline constexpr std::byte kMagic[8] = {std::byte{0x89}, std::byte{'M'},  std::byte{'C'},  std::byte{'A'},
                                        std::byte{'P'},  std::byte{0x30}, std::byte{'\r'}, std::byte{'\n'}};

using Bytes = std::vector<std::byte>;

template <class Int>
void put(Bytes& out, Int v) {
  for (std::size_t i = 0; i < sizeof(Int); ++i) out.push_back(std::byte(static_cast<std::uint64_t>(v) >> (8 * i)));
}
inline void put_bytes(Bytes& out, std::span<const std::byte> b) { out.insert(out.end(), b.begin(), b.end()); }
inline void put_string(Bytes& out, std::string_view s) {
  put<std::uint32_t>(out, static_cast<std::uint32_t>(s.size()));
  put_bytes(out, std::as_bytes(std::span{s.data(), s.size()}));
}
inline void put_string_map(Bytes& out, const std::map<std::string, std::string>& m) {
  Bytes body;
  for (const auto& [k, v] : m) {
    put_string(body, k);
    put_string(body, v);
  }
  put<std::uint32_t>(out, static_cast<std::uint32_t>(body.size()));
  put_bytes(out, body);
}
template <class Key>
void put_offset_map(Bytes& out, const std::map<Key, std::uint64_t>& m) {
  put<std::uint32_t>(out, static_cast<std::uint32_t>(m.size() * (sizeof(Key) + 8)));
  for (const auto& [k, v] : m) {
    put<Key>(out, k);
    put<std::uint64_t>(out, v);
  }
}
// A record: opcode, uint64 length, body.
inline void put_record(Bytes& out, Op op, const Bytes& body) {
  out.push_back(std::byte{op});
  put<std::uint64_t>(out, body.size());
  put_bytes(out, body);
}

// Reads within `bytes`; `what` names the record for errors.
class Cursor {
 public:
  Cursor(std::span<const std::byte> bytes, std::string what) : bytes_{bytes}, what_{std::move(what)} {}

  [[nodiscard]] bool done() const noexcept { return at_ == bytes_.size(); }
  [[nodiscard]] std::size_t at() const noexcept { return at_; }
  [[nodiscard]] std::size_t left() const noexcept { return bytes_.size() - at_; }

  template <class Int>
  Int get() {
    need(sizeof(Int));
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < sizeof(Int); ++i) v |= static_cast<std::uint64_t>(bytes_[at_ + i]) << (8 * i);
    at_ += sizeof(Int);
    return static_cast<Int>(v);
  }
  std::span<const std::byte> take(std::uint64_t n) {
    need(n);
    auto s = bytes_.subspan(at_, static_cast<std::size_t>(n));
    at_ += static_cast<std::size_t>(n);
    return s;
  }
  std::string string() {
    const auto s = take(get<std::uint32_t>());
    return {reinterpret_cast<const char*>(s.data()), s.size()};
  }
  std::map<std::string, std::string> string_map() {
    Cursor body{take(get<std::uint32_t>()), what_};
    std::map<std::string, std::string> m;
    while (!body.done()) {
      auto k = body.string();
      m[std::move(k)] = body.string();
    }
    return m;
  }
  template <class Key>
  std::map<Key, std::uint64_t> offset_map() {
    Cursor body{take(get<std::uint32_t>()), what_};
    std::map<Key, std::uint64_t> m;
    while (!body.done()) {
      const auto k = body.get<Key>();
      m[k] = body.get<std::uint64_t>();
    }
    return m;
  }

 private:
  void need(std::uint64_t n) const {
    if (n > left())
      throw Failure{{Errc::damaged, what_ + ": a field of " + std::to_string(n) + " bytes runs past its record (" +
                                        std::to_string(left()) + " bytes left)"}};
  }
  std::span<const std::byte> bytes_;
  std::string what_;
  std::size_t at_ = 0;
};

}  // namespace prime::record::detail
