#pragma once

#include <bit>
#include <cstdint>
#include <expected>
#include <string>
#include <string_view>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/stream.hpp"

namespace prime::optimus {

// For tools (prime play): the writing end of a source whose messages come
// whole, header and body, as a recorder read them from a stream, for a
// type it does not know at compile time. Made by Core::raw_publisher.
// Each message's header is checked against the source's type before it is
// sent: one that is not a Prime message of that type and this machine's
// byte order (a damaged recording, or one of another type) is refused by
// name, never appended. Its body is the readers' to check.
//
// Thread-safe.
class RawPublisher {
 public:
  RawPublisher(detail::Stream stream, std::uint64_t hash) : stream_{std::move(stream)}, hash_{hash} {}

  std::expected<void, Error> publish(std::string_view message, Clock::time_point stamp = Clock::now()) const {
    if (auto problem = detail::header_problem(message, hash_))
      return std::unexpected(Error{Errc::type_mismatch, "source '" + stream_.name() + "': not one of its messages, but " + *problem});
    // Its body is the type's bytes or MessagePack, in this machine's byte
    // order (readers here refuse another): the format byte's flag says so.
    constexpr std::uint8_t native = std::endian::native == std::endian::big ? detail::kBigEndianFlag : 0;
    if ((static_cast<std::uint8_t>(message[3]) & detail::kBigEndianFlag) != native)
      return std::unexpected(Error{Errc::type_mismatch, "source '" + stream_.name() +
                                                            "': not one of its messages, but one written on a machine of the other byte order"});
    return stream_.publish(message, stamp);
  }

 private:
  detail::Stream stream_;
  std::uint64_t hash_;
};

}  // namespace prime::optimus
