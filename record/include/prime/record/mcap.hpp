#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "prime/logic/error.hpp"  // what goes wrong is a prime::Failure

namespace prime::record {

// What an MCAP file holds, as its summary section describes it (mcap.dev/spec):
// the writer's and the reader's common vocabulary. Times are nanoseconds
// since the Unix epoch.

enum class Compression { none, lz4, zstd };

// The name the MCAP spec gives a chunk compression ("", "lz4", "zstd").
[[nodiscard]] const char* compression_name(Compression c) noexcept;

struct Schema {
  std::uint16_t id = 0;
  std::string name;      // the type's name
  std::string encoding;  // how `data` describes it ("ros2msg", or "" for none)
  std::string data;
};

struct Channel {
  std::uint16_t id = 0;
  std::uint16_t schema_id = 0;  // 0: none
  std::string topic;
  std::string message_encoding;  // "cdr", or a name of Prime's own for raw bytes
  std::map<std::string, std::string> metadata;
};

// One chunk of messages, as the chunk index in the summary places it.
struct ChunkInfo {
  std::uint64_t message_start_time = 0;
  std::uint64_t message_end_time = 0;
  std::uint64_t offset = 0;  // of the chunk record, from the file's start
  std::uint64_t length = 0;  // of the chunk record
  std::map<std::uint16_t, std::uint64_t> message_index_offsets;  // per channel
  std::uint64_t message_index_length = 0;
  std::string compression;
  std::uint64_t compressed_size = 0;
  std::uint64_t uncompressed_size = 0;
};

struct Statistics {
  std::uint64_t message_count = 0;
  std::uint16_t schema_count = 0;
  std::uint32_t channel_count = 0;
  std::uint32_t attachment_count = 0;
  std::uint32_t metadata_count = 0;
  std::uint32_t chunk_count = 0;
  std::uint64_t message_start_time = 0;
  std::uint64_t message_end_time = 0;
  std::map<std::uint16_t, std::uint64_t> channel_message_counts;
};

struct Metadata {
  std::string name;
  std::map<std::string, std::string> values;
};

// A file's summary: what `prime record info` shows without reading the
// messages.
struct Summary {
  std::string profile;
  std::string library;
  std::map<std::uint16_t, Schema> schemas;
  std::map<std::uint16_t, Channel> channels;
  std::vector<ChunkInfo> chunks;
  Statistics statistics;
  std::vector<Metadata> metadata;
  std::uint64_t file_size = 0;
};

// One message as read back.
struct Message {
  std::uint16_t channel_id = 0;
  std::uint32_t sequence = 0;
  std::uint64_t log_time = 0;
  std::uint64_t publish_time = 0;
  std::vector<std::byte> data;
};

}  // namespace prime::record
