#pragma once

#include <array>
#include <bit>
#include <concepts>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <expected>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>

#include <msgpack.hpp>

#include "prime/common/bounded_string.hpp"
#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/topology/sync.hpp"

// MessagePack knows bounded_string as text, so it travels inside other
// messages (a std::vector of them, say) as a std::string would.
namespace msgpack {
MSGPACK_API_VERSION_NAMESPACE(MSGPACK_DEFAULT_API_NS) {
namespace adaptor {
template <std::size_t N>
struct pack<prime::bounded_string<N>> {
  template <class Stream>
  packer<Stream>& operator()(packer<Stream>& out, const prime::bounded_string<N>& text) const {
    out.pack_str(static_cast<std::uint32_t>(text.size()));
    out.pack_str_body(text.view().data(), static_cast<std::uint32_t>(text.size()));
    return out;
  }
};
template <std::size_t N>
struct convert<prime::bounded_string<N>> {
  const msgpack::object& operator()(const msgpack::object& o, prime::bounded_string<N>& text) const {
    if (o.type != msgpack::type::STR) throw msgpack::type_error();
    text.assign(std::string_view{o.via.str.ptr, o.via.str.size});  // throws when it does not fit
    return o;
  }
};
// A synced set travels as [values, stamps]: its tuple, then each value's
// stamp in steady-clock nanoseconds (the same clock in every process on the
// machine).
template <class... Ts>
struct pack<prime::Synced<Ts...>> {
  template <class Stream>
  packer<Stream>& operator()(packer<Stream>& out, const prime::Synced<Ts...>& set) const {
    out.pack_array(2);
    out.pack(static_cast<const std::tuple<Ts...>&>(set));
    out.pack_array(sizeof...(Ts));
    for (const auto stamp : set.stamps)
      out.pack(static_cast<std::int64_t>(
          std::chrono::duration_cast<std::chrono::nanoseconds>(stamp.time_since_epoch()).count()));
    return out;
  }
};
template <class... Ts>
struct convert<prime::Synced<Ts...>> {
  const msgpack::object& operator()(const msgpack::object& o, prime::Synced<Ts...>& set) const {
    if (o.type != msgpack::type::ARRAY || o.via.array.size != 2) throw msgpack::type_error();
    o.via.array.ptr[0].convert(static_cast<std::tuple<Ts...>&>(set));
    const msgpack::object& stamps = o.via.array.ptr[1];
    if (stamps.type != msgpack::type::ARRAY || stamps.via.array.size != sizeof...(Ts)) throw msgpack::type_error();
    for (std::size_t i = 0; i < sizeof...(Ts); ++i)
      set.stamps[i] = prime::Clock::time_point{std::chrono::duration_cast<prime::Clock::duration>(
          std::chrono::nanoseconds{stamps.via.array.ptr[i].as<std::int64_t>()})};
    return o;
  }
};
}  // namespace adaptor
}  // MSGPACK_API_VERSION_NAMESPACE(MSGPACK_DEFAULT_API_NS)
}  // namespace msgpack

namespace prime::optimus {

// How a message's body is written, recorded in its header.
enum class Format : std::uint8_t { bytes = 0, msgpack = 1, custom = 2 };

// A trivially copyable type (and so a bounded_string / bounded_vector message)
// travels as its bytes: same machine architecture on both sides, which the
// header's fingerprint and byte-order flag check.
template <class T>
struct BytesCodec {
  static_assert(std::is_trivially_copyable_v<T>);
  static_assert(!std::is_pointer_v<T> && !std::is_member_pointer_v<T>,
                "prime::optimus: a pointer means nothing in another process; send what it points to");
  static constexpr Format kFormat = Format::bytes;

  static void encode(const T& value, std::string& out) {
    const auto bytes = std::bit_cast<std::array<char, sizeof(T)>>(value);
    out.append(bytes.data(), bytes.size());
  }
  static std::expected<T, std::string> decode(std::string_view body) {
    if (body.size() != sizeof(T))
      return std::unexpected("a body of " + std::to_string(body.size()) + " bytes, not " + std::to_string(sizeof(T)));
    std::array<char, sizeof(T)> bytes;
    std::memcpy(bytes.data(), body.data(), sizeof(T));
    T value = std::bit_cast<T>(bytes);
    // A bounded type (bounded_string, bounded_vector) with a count it could
    // not have written is refused. Those nested in a message are read within
    // their capacity by their own accessors, whatever count they carry.
    if constexpr (requires { value.valid(); T::capacity(); }) {
      if (!value.valid())
        return std::unexpected("a bounded value's count past the capacity " + std::to_string(T::capacity()) +
                               " (or its text not ended by a NUL)");
    }
    return value;
  }
};

// Any other type, through MessagePack (msgpack-cxx): the standard containers,
// strings, tuples and pairs as they are, a user's struct with MSGPACK_DEFINE.
template <class T>
struct MsgpackCodec {
  static constexpr Format kFormat = Format::msgpack;

  static void encode(const T& value, std::string& out) {
    struct Appender {
      std::string& out;
      void write(const char* data, std::size_t n) { out.append(data, n); }
    } appender{out};
    msgpack::pack(appender, value);
  }
  static std::expected<T, std::string> decode(std::string_view body) {
    try {
      // No container or string may claim more elements than there are bytes:
      // a forged length cannot make the decoder allocate gigabytes.
      const auto n = body.size();
      const msgpack::unpack_limit limit{n, n, n, n, n, 64};
      std::size_t offset = 0;
      auto handle = msgpack::unpack(body.data(), n, offset, nullptr, nullptr, limit);
      if (offset != n) return std::unexpected(std::to_string(n - offset) + " bytes after the MessagePack value");
      return handle.get().template as<T>();
    } catch (const std::exception& e) {
      return std::unexpected(std::string{"MessagePack: "} + e.what());
    }
  }
};

namespace detail {
template <class T>
struct DefaultCodec {
  using type = std::conditional_t<std::is_trivially_copyable_v<T>, BytesCodec<T>, MsgpackCodec<T>>;
};
}  // namespace detail

// The codec of a message type: bytes for trivially copyable types, MessagePack
// for the rest. Specialise it for a type of your own:
//
//   template <> struct prime::optimus::Codec<Scan> {
//     static void encode(const Scan& scan, std::string& out);                  // appends
//     static std::expected<Scan, std::string> decode(std::string_view body);  // says why not
//   };
template <class T>
struct Codec : detail::DefaultCodec<T>::type {};

template <class T>
concept Encodable = requires(const T& value, std::string& out, std::string_view body) {
  Codec<T>::encode(value, out);
  { Codec<T>::decode(body) } -> std::same_as<std::expected<T, std::string>>;
};

namespace detail {

// Every message starts with this header:
//   "PO", version, format (bit 7: written on a big-endian machine),
//   body size (u32, little-endian), fingerprint hash of the type (u64, little-endian)
inline constexpr std::size_t kHeaderSize = 16;
inline constexpr std::uint8_t kVersion = 1;
inline constexpr std::uint8_t kBigEndianFlag = 0x80;

template <class T>
constexpr std::uint8_t format_byte() {
  std::uint8_t format = static_cast<std::uint8_t>(Format::custom);
  if constexpr (requires { Codec<T>::kFormat; }) format = static_cast<std::uint8_t>(Codec<T>::kFormat);
  if constexpr (std::endian::native == std::endian::big) format |= kBigEndianFlag;
  return format;
}

inline void put_le(std::string& out, std::size_t at, std::uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out[at + i] = static_cast<char>((value >> (8 * i)) & 0xff);
}
inline std::uint64_t get_le(std::string_view in, std::size_t at, int bytes) {
  std::uint64_t value = 0;
  for (int i = 0; i < bytes; ++i) value |= std::uint64_t{static_cast<unsigned char>(in[at + i])} << (8 * i);
  return value;
}

// What is wrong with `message`'s header for a message of the type whose
// fingerprint hash is `hash` (its format byte is the caller's to check),
// as "found ..." says it; none when nothing is.
inline std::optional<std::string> header_problem(std::string_view message, std::uint64_t hash) {
  if (message.size() < kHeaderSize)
    return "only " + std::to_string(message.size()) + " bytes, less than a message header";
  if (message[0] != 'P' || message[1] != 'O') return "data that is not a Prime message (no 'PO' header)";
  if (static_cast<std::uint8_t>(message[2]) != kVersion)
    return "a message of header version " + std::to_string(static_cast<unsigned char>(message[2]));
  const auto body_size = get_le(message, 4, 4);
  if (body_size != message.size() - kHeaderSize)
    return "a header promising " + std::to_string(body_size) + " body bytes where " +
           std::to_string(message.size() - kHeaderSize) + " are present";
  if (const auto found = get_le(message, 8, 8); found != hash) {
    char hex[24];
    std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(found));
    return std::string{"a message of another type (fingerprint "} + hex + ")";
  }
  return std::nullopt;
}

}  // namespace detail

// `value` as a message: header, then the codec's body.
template <Encodable T>
void encode_message(const T& value, std::string& out) {
  static constexpr auto fingerprint = Fingerprint::of<T>();
  const auto start = out.size();
  out.resize(start + detail::kHeaderSize);
  Codec<T>::encode(value, out);
  const auto body = out.size() - start - detail::kHeaderSize;
  if (body > UINT32_MAX) throw Failure{{Errc::too_large, "optimus: a " + fingerprint.describe() + " message of " + std::to_string(body) + " bytes is over 4 GiB"}};
  out[start] = 'P';
  out[start + 1] = 'O';
  out[start + 2] = static_cast<char>(detail::kVersion);
  out[start + 3] = static_cast<char>(detail::format_byte<T>());
  detail::put_le(out, start + 4, body, 4);
  detail::put_le(out, start + 8, fingerprint.hash, 8);
}
template <Encodable T>
[[nodiscard]] std::string encode_message(const T& value) {
  std::string out;
  encode_message(value, out);
  return out;
}

// A message back as a T, or an Errc::type_mismatch error that names `where`
// (a key, a service) and what was expected. Never trusts the bytes.
template <Encodable T>
[[nodiscard]] std::expected<T, Error> decode_message(std::string_view message, std::string_view where) {
  static constexpr auto fingerprint = Fingerprint::of<T>();
  const auto fail = [&](const std::string& what) {
    return std::unexpected(Error{Errc::type_mismatch, std::string{where} + ": expected a message of " +
                                                          fingerprint.describe() + ", found " + what});
  };
  if (auto problem = detail::header_problem(message, fingerprint.hash)) return fail(*problem);
  if (static_cast<std::uint8_t>(message[3]) != detail::format_byte<T>())
    return fail("a body in another format or byte order (format byte " +
                std::to_string(static_cast<unsigned char>(message[3])) + ")");
  auto value = Codec<T>::decode(message.substr(detail::kHeaderSize));
  if (!value) return fail("a malformed body: " + value.error());
  return std::move(*value);
}

}  // namespace prime::optimus
