#pragma once

#include <chrono>
#include <cstdint>
#include <expected>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <msgpack.hpp>

#include "prime/logic/error.hpp"

namespace prime::optimus::detail {

// What travels to a service: who asked (correlation id, reply key), where the
// result goes next (the route: the request keys of the services still to run,
// so linked services pass data on without the caller), until when the caller
// waits, and the message. MessagePack on the wire.
struct Request {
  std::uint64_t id = 0;
  std::string reply_key;
  std::vector<std::string> route;   // services still to run after this one
  std::int64_t deadline_ms = 0;     // the server's clock (Pool::server_ms); the caller gives up then; 0: never
  std::string payload;              // an encoded message (codec.hpp)
};

// What comes back: the correlation id, Ok or the Errc of a failure, its
// message, and the encoded result.
struct Response {
  std::uint64_t id = 0;
  std::optional<Errc> error;
  std::string message;
  std::string payload;
};

// How an envelope goes onto a list (a service's requests, a caller's reply
// key): appended, and the list made to live at least `ms` more (the
// request's deadline and kUntakenFor), so what nobody takes (its caller was
// killed, its service's process died) goes away by itself, and never cuts
// short a request queued before with a later deadline. One step on the
// server: the expiry is set only if the append succeeded (a script stops at
// an error), and the append never stays without one.
inline constexpr std::string_view kPushFunction = R"lua(
local function push(key, value, ms)
  redis.call('RPUSH', key, value)
  if redis.call('PTTL', key) < tonumber(ms) then redis.call('PEXPIRE', key, ms) end
end
)lua";
// KEYS[1] the list, ARGV[1] the envelope, ARGV[2] ms.
inline const std::string kPushScript = std::string{kPushFunction} + "push(KEYS[1], ARGV[1], ARGV[2])\nreturn 1\n";

struct StringAppender {
  std::string& out;
  void write(const char* data, std::size_t n) { out.append(data, n); }
};

inline void encode_request(std::uint64_t id, std::string_view reply_key, std::span<const std::string> route,
                           std::int64_t deadline_ms, std::string_view payload, std::string& out) {
  StringAppender appender{out};
  msgpack::packer packer{appender};
  packer.pack_array(5);
  packer.pack(id);
  packer.pack_str(static_cast<std::uint32_t>(reply_key.size())).pack_str_body(reply_key.data(), static_cast<std::uint32_t>(reply_key.size()));
  packer.pack_array(static_cast<std::uint32_t>(route.size()));
  for (const auto& hop : route) packer.pack(hop);
  packer.pack(deadline_ms);
  packer.pack_bin(static_cast<std::uint32_t>(payload.size())).pack_bin_body(payload.data(), static_cast<std::uint32_t>(payload.size()));
}

inline void encode_response(std::uint64_t id, const std::optional<Errc>& error, std::string_view message,
                            std::string_view payload, std::string& out) {
  StringAppender appender{out};
  msgpack::packer packer{appender};
  packer.pack_array(4);
  packer.pack(id);
  packer.pack(error ? static_cast<int>(*error) + 1 : 0);
  packer.pack_str(static_cast<std::uint32_t>(message.size())).pack_str_body(message.data(), static_cast<std::uint32_t>(message.size()));
  packer.pack_bin(static_cast<std::uint32_t>(payload.size())).pack_bin_body(payload.data(), static_cast<std::uint32_t>(payload.size()));
}

inline std::string_view bytes_of(const msgpack::object& o) {
  if (o.type == msgpack::type::BIN) return {o.via.bin.ptr, o.via.bin.size};
  if (o.type == msgpack::type::STR) return {o.via.str.ptr, o.via.str.size};
  throw msgpack::type_error{};
}

inline msgpack::object_handle unpack_bounded(std::string_view data) {
  const auto n = data.size();
  std::size_t offset = 0;
  auto handle = msgpack::unpack(data.data(), n, offset, nullptr, nullptr, msgpack::unpack_limit{n, n, n, n, n, 8});
  if (offset != n) throw msgpack::unpack_error{"trailing bytes"};
  return handle;
}

// A request read back, or why it is not one (a foreign value in the key).
inline std::expected<Request, std::string> decode_request(std::string_view data) {
  try {
    auto handle = unpack_bounded(data);
    const auto& o = handle.get();
    if (o.type != msgpack::type::ARRAY || o.via.array.size != 5) return std::unexpected(std::string{"not a request envelope"});
    const auto* f = o.via.array.ptr;
    Request r;
    r.id = f[0].as<std::uint64_t>();
    r.reply_key = std::string{bytes_of(f[1])};
    if (f[2].type != msgpack::type::ARRAY) return std::unexpected(std::string{"a request without a route"});
    for (std::uint32_t i = 0; i < f[2].via.array.size; ++i) r.route.emplace_back(bytes_of(f[2].via.array.ptr[i]));
    r.deadline_ms = f[3].as<std::int64_t>();
    r.payload = std::string{bytes_of(f[4])};
    if (r.reply_key.empty()) return std::unexpected(std::string{"a request without a reply key"});
    return r;
  } catch (const std::exception& e) {
    return std::unexpected(std::string{"not a request envelope: "} + e.what());
  }
}

inline std::expected<Response, std::string> decode_response(std::string_view data) {
  try {
    auto handle = unpack_bounded(data);
    const auto& o = handle.get();
    if (o.type != msgpack::type::ARRAY || o.via.array.size != 4) return std::unexpected(std::string{"not a reply envelope"});
    const auto* f = o.via.array.ptr;
    Response r;
    r.id = f[0].as<std::uint64_t>();
    const int code = f[1].as<int>();
    if (code > 0) {
      r.error = errc_from(code - 1);
      if (!r.error) return std::unexpected(std::string{"an unknown status"});
    } else if (code < 0) {
      return std::unexpected(std::string{"an unknown status"});
    }
    r.message = std::string{bytes_of(f[2])};
    r.payload = std::string{bytes_of(f[3])};
    return r;
  } catch (const std::exception& e) {
    return std::unexpected(std::string{"not a reply envelope: "} + e.what());
  }
}

}  // namespace prime::optimus::detail
