#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "prime/common/type_layout.hpp"

namespace prime::record {

// A described type (PRIME_DESCRIBE) as ROS 2 says it, so that tools that
// decode ROS 2 messages (Foxglove, the MCAP readers' ros2 decoders) show a
// recording field by field: its definition in ros2msg, and its samples in
// CDR (XCDR1, little-endian, after the 4-byte encapsulation header), as a
// ROS 2 node would have published them.
//
// A type whose fields are numbers, booleans, characters, fixed arrays and
// records of those, each at the offset its CDR encoding gives it too, is
// its own CDR body: encoding it copies its bytes. Bounded strings and
// vectors are encoded field by field.
class CdrCodec {
 public:
  // The codec of a type of `size` bytes with `description` (schema_of's
  // text); nullopt for one with parts CDR cannot say (bytes of no
  // description) or a description that does not fit its size.
  static std::optional<CdrCodec> of(std::string_view description, std::size_t size);

  // The type's ros2msg definition as a recording's schema holds it: its
  // fields, then each nested type after a line of '=' and "MSG: <name>".
  [[nodiscard]] std::string definition(std::string_view ros2_name) const;

  // Sample `sample` (the type's `size` bytes) as a CDR message, into `out`.
  void encode(std::span<const std::byte> sample, std::vector<std::byte>& out) const;
  // CDR message `message` as the type's bytes in memory. Throws Failure
  // (Errc::damaged, naming `what`) when it is not one: a header other
  // than CDR little-endian, a string or sequence longer than its bound,
  // bytes cut short.
  [[nodiscard]] std::vector<std::byte> decode(std::span<const std::byte> message, const std::string& what) const;

  // Whether the type is its own CDR body (encoding is a copy).
  [[nodiscard]] bool plain() const noexcept { return plain_; }

 private:
  CdrCodec(std::shared_ptr<const TypeLayout> layout, std::size_t size, bool plain, std::size_t body)
      : layout_{std::move(layout)}, size_{size}, plain_{plain}, body_{body} {}
  std::shared_ptr<const TypeLayout> layout_;
  std::size_t size_;
  bool plain_;        // the layout is its CDR body...
  std::size_t body_;  // ...of these first bytes
};

// A C++ type's name as a ROS 2 type's: "robot::msgs::Pose" is
// "robot_msgs/msg/Pose"; a type in no namespace is in package "prime".
[[nodiscard]] std::string ros2_name(std::string_view cpp_name);

}  // namespace prime::record
