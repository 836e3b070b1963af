// Chunk compression with Debian's liblz4 (frame format) and libzstd, and
// CRC-32 with zlib.
#include "compression.hpp"

#include <lz4frame.h>
#include <zlib.h>
#include <zstd.h>

namespace prime::record::detail {


Bytes compress(Compression c, std::span<const std::byte> in) {
  Bytes out;
  switch (c) {
    case Compression::none: return Bytes(in.begin(), in.end());
    case Compression::lz4: {
      LZ4F_preferences_t prefs{};
      prefs.frameInfo.contentSize = in.size();
      out.resize(LZ4F_compressFrameBound(in.size(), &prefs));
      const auto n = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), &prefs);
      if (LZ4F_isError(n)) throw Failure{{Errc::invalid_argument, std::string{"lz4: "} + LZ4F_getErrorName(n)}};
      out.resize(n);
      return out;
    }
    case Compression::zstd: {
      out.resize(ZSTD_compressBound(in.size()));
      const auto n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 1);
      if (ZSTD_isError(n)) throw Failure{{Errc::invalid_argument, std::string{"zstd: "} + ZSTD_getErrorName(n)}};
      out.resize(n);
      return out;
    }
  }
  return out;
}

Bytes decompress(const std::string& name, std::span<const std::byte> in, std::uint64_t size, const std::string& where) {
  auto damaged = [&](const std::string& why) { return Failure{{Errc::damaged, where + ": " + why}}; };
  if (size > (std::uint64_t{1} << 34)) throw damaged("it says it holds " + std::to_string(size) + " bytes uncompressed");
  if (name.empty()) {
    if (in.size() != size) throw damaged("its records are " + std::to_string(in.size()) + " bytes, not the " + std::to_string(size) + " it says");
    return Bytes(in.begin(), in.end());
  }
  Bytes out(static_cast<std::size_t>(size));
  if (name == "zstd") {
    const auto n = ZSTD_decompress(out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(n) || n != size) throw damaged(std::string{"zstd: "} + (ZSTD_isError(n) ? ZSTD_getErrorName(n) : "a size other than it says"));
    return out;
  }
  if (name == "lz4") {
    LZ4F_dctx* ctx = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION))) throw damaged("lz4: no context");
    std::size_t produced = 0, consumed = 0, ret = 1;
    while (consumed < in.size() && ret != 0) {
      std::size_t dst = out.size() - produced, src = in.size() - consumed;
      ret = LZ4F_decompress(ctx, out.data() + produced, &dst, in.data() + consumed, &src, nullptr);
      if (LZ4F_isError(ret)) {
        LZ4F_freeDecompressionContext(ctx);
        throw damaged(std::string{"lz4: "} + LZ4F_getErrorName(ret));
      }
      produced += dst;
      consumed += src;
      if (dst == 0 && src == 0) break;
    }
    LZ4F_freeDecompressionContext(ctx);
    if (produced != size) throw damaged("lz4: " + std::to_string(produced) + " bytes, not the " + std::to_string(size) + " it says");
    return out;
  }
  throw damaged("compression '" + name + "' is none this reader knows (lz4, zstd)");
}

std::uint32_t crc32(std::span<const std::byte> bytes, std::uint32_t crc) noexcept {
  // zlib's CRC-32 (IEEE): MCAP's. Fed in pieces of at most 1 GiB (uInt).
  uLong c = crc;
  for (std::size_t at = 0; at < bytes.size();) {
    const auto n = std::min<std::size_t>(bytes.size() - at, 1u << 30);
    c = ::crc32(c, reinterpret_cast<const Bytef*>(bytes.data() + at), static_cast<uInt>(n));
    at += n;
  }
  return static_cast<std::uint32_t>(c);
}

std::uint32_t crc32_combine(std::uint32_t a, std::uint32_t b, std::uint64_t b_length) noexcept {
  return static_cast<std::uint32_t>(::crc32_combine64(a, b, static_cast<z_off64_t>(b_length)));
}

}  // namespace prime::record::detail
