#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>

#include "prime/record/mcap.hpp"

namespace prime::record {

struct WriterOptions {
  Compression compression = Compression::zstd;
  std::size_t chunk_size = 1 << 20;  // uncompressed bytes of records a chunk collects before it is written
  std::string profile;               // the Header's profile ("" : Prime's own encodings)
};

// Writes an MCAP file (mcap.dev/spec) in one pass: messages collected into
// chunks, compressed with lz4 (frame format) or zstd, each chunk followed
// by its message indexes; closing writes the summary (schemas, channels,
// chunk indexes, statistics, metadata indexes), its offsets and the footer.
// Every CRC the format has is filled in.
//
// A file whose writer died before closing holds every chunk written so
// far, readable up to the last complete one.
//
// Errors are prime::Failure: Errc::not_found or unreachable (the file
// cannot be made, naming why), no_space (the disk is full: what was
// written before stays readable), invalid_argument (an unknown id, a
// closed writer). Not thread-safe.
class McapWriter {
 public:
  McapWriter(const std::string& path, WriterOptions options = {});
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;
  ~McapWriter();  // closes, if close() was not called; an error then is lost

  // A schema or channel, written before the messages that use it; ids from 1.
  std::uint16_t add_schema(const std::string& name, const std::string& encoding, const std::string& data);
  std::uint16_t add_channel(std::uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                            const std::map<std::string, std::string>& metadata = {});
  void write(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time, std::uint64_t publish_time,
             std::span<const std::byte> data);
  // A Metadata record (with its index in the summary).
  void add_metadata(const std::string& name, const std::map<std::string, std::string>& values);

  // Writes what is collected, then the summary and footer. Once only.
  void close();

  [[nodiscard]] const std::string& path() const noexcept;
  [[nodiscard]] std::uint64_t bytes_written() const noexcept;  // to the file so far

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace prime::record
