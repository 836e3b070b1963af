#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

namespace prime::bench::ipc {

// The sequence number every message carries in its first eight bytes.
inline void stamp(void* message, std::uint64_t seq) noexcept { std::memcpy(message, &seq, sizeof seq); }
[[nodiscard]] inline std::uint64_t seq_of(const void* message) noexcept {
  std::uint64_t seq;
  std::memcpy(&seq, message, sizeof seq);
  return seq;
}

// A payload of its own, for the peers that copy: the bytes a sender hands to
// the kernel or a receiver gets back. Filled once; only the stamp changes.
class Payload {
 public:
  explicit Payload(std::size_t bytes) : bytes_(std::max(bytes, sizeof(std::uint64_t)), std::byte{0x5a}) {}

  [[nodiscard]] std::span<std::byte> bytes() noexcept { return bytes_; }
  void stamp(std::uint64_t seq) noexcept { ipc::stamp(bytes_.data(), seq); }
  [[nodiscard]] std::uint64_t seq() const noexcept { return seq_of(bytes_.data()); }

 private:
  std::vector<std::byte> bytes_;
};

}  // namespace prime::bench::ipc
