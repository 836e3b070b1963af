#pragma once

// Chunk compression: lz4 (its frame format, as MCAP readers expect) and zstd.

#include <cstdint>
#include <span>
#include <string>

#include "wire.hpp"
#include "prime/record/mcap.hpp"

namespace prime::record::detail {

Bytes compress(Compression c, std::span<const std::byte> in);
// `in` decompressed to `size` bytes, as the chunk named `where` says it
// holds; Errc::damaged when it does not, or `name` is no compression known.
Bytes decompress(const std::string& name, std::span<const std::byte> in, std::uint64_t size, const std::string& where);

std::uint32_t crc32(std::span<const std::byte> bytes, std::uint32_t crc = 0) noexcept;
// The CRC-32 of A then B, from A's, B's and B's length.
std::uint32_t crc32_combine(std::uint32_t a, std::uint32_t b, std::uint64_t b_length) noexcept;

}  // namespace prime::record::detail
