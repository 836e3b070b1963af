// An MCAP file written in one pass: records of the data section, chunked
// and indexed, then the summary and footer (mcap.dev/spec).
#include "prime/record/mcap_writer.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include "compression.hpp"
#include "wire.hpp"

namespace prime::record {

using namespace detail;

const char* compression_name(Compression c) noexcept {
  switch (c) {
    case Compression::none: return "";
    case Compression::lz4: return "lz4";
    case Compression::zstd: return "zstd";
  }
  return "";
}

namespace {

// A Schema's and a Channel's bodies: written into the data section as they
// are added, and again into the summary.
Bytes schema_body(const Schema& sc) {
  Bytes b;
  put<std::uint16_t>(b, sc.id);
  put_string(b, sc.name);
  put_string(b, sc.encoding);
  put_string(b, sc.data);  // uint32-prefixed bytes, as a string is
  return b;
}
Bytes channel_body(const Channel& ch) {
  Bytes b;
  put<std::uint16_t>(b, ch.id);
  put<std::uint16_t>(b, ch.schema_id);
  put_string(b, ch.topic);
  put_string(b, ch.message_encoding);
  put_string_map(b, ch.metadata);
  return b;
}

}  // namespace

struct McapWriter::State {
  std::string path;
  WriterOptions options;
  int fd = -1;
  bool closed = false;
  std::uint64_t offset = 0;    // bytes written to the file
  std::uint32_t data_crc = 0;  // of every byte before Data End
  std::map<std::uint16_t, Schema> schemas;
  std::map<std::uint16_t, Channel> channels;
  std::vector<std::pair<Metadata, std::pair<std::uint64_t, std::uint64_t>>> metadata;  // and where each lies
  std::vector<ChunkInfo> chunks;
  Statistics stats;
  // The chunk being collected: its records, times, and each channel's message index.
  Bytes records;
  std::uint64_t chunk_start = 0, chunk_end = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> index;

  void append(std::span<const std::byte> bytes) {
    for (std::size_t at = 0; at < bytes.size();) {
      const auto n = ::write(fd, bytes.data() + at, bytes.size() - at);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) {
        const int e = errno;
        const auto code = e == ENOSPC || e == EDQUOT || e == EFBIG ? Errc::no_space : Errc::unreachable;  // EFBIG: a file size limit
        throw Failure{{code, "recording '" + path + "': writing failed after " + std::to_string(offset + at) +
                                 " bytes: " + std::strerror(e) +
                                 " (what was written up to the last complete chunk stays readable)"}};
      }
      at += static_cast<std::size_t>(n);
    }
    offset += bytes.size();
  }
  // A record of the data section: counted in its CRC.
  void data_record(Op op, const Bytes& body) {
    Bytes out;
    put_record(out, op, body);
    data_crc = crc32(out, data_crc);
    append(out);
  }

  // The chunk record is written as its head and its payload (the records,
  // or them compressed): no copy of the payload is made to frame it, and
  // with no compression its CRC in the data section's is combined from
  // the chunk's own rather than computed over it again.
  void flush_chunk() {
    if (records.empty()) return;
    const auto records_crc = crc32(records);
    Bytes compressed;
    if (options.compression != Compression::none) compressed = compress(options.compression, records);
    const std::span<const std::byte> payload = options.compression == Compression::none ? std::span{records} : std::span{compressed};
    const std::string_view name = compression_name(options.compression);
    Bytes head;
    head.push_back(std::byte{kChunk});
    put<std::uint64_t>(head, 8 + 8 + 8 + 4 + 4 + name.size() + 8 + payload.size());
    put<std::uint64_t>(head, chunk_start);
    put<std::uint64_t>(head, chunk_end);
    put<std::uint64_t>(head, records.size());
    put<std::uint32_t>(head, records_crc);
    put_string(head, name);
    put<std::uint64_t>(head, payload.size());
    ChunkInfo info{chunk_start, chunk_end, offset, head.size() + payload.size(), {}, 0, std::string{name},
                   payload.size(), records.size()};
    data_crc = crc32(head, data_crc);
    data_crc = options.compression == Compression::none ? crc32_combine(data_crc, records_crc, records.size())
                                                         : crc32(payload, data_crc);
    append(head);
    append(payload);
    const auto indexes_start = offset;
    for (const auto& [channel, entries] : index) {
      Bytes mi;
      put<std::uint16_t>(mi, channel);
      put<std::uint32_t>(mi, static_cast<std::uint32_t>(entries.size() * 16));
      for (const auto& [time, at] : entries) {
        put<std::uint64_t>(mi, time);
        put<std::uint64_t>(mi, at);
      }
      info.message_index_offsets[channel] = offset;
      data_record(kMessageIndex, mi);
    }
    info.message_index_length = offset - indexes_start;
    chunks.push_back(std::move(info));
    ++stats.chunk_count;
    records.clear();
    index.clear();
  }
};

McapWriter::McapWriter(const std::string& path, WriterOptions options) : state_{std::make_unique<State>()} {
  auto& s = *state_;
  s.path = path;
  s.options = std::move(options);
  if (s.options.chunk_size == 0) throw Failure{{Errc::invalid_argument, "recording '" + path + "': a chunk size of 0"}};
  s.fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (s.fd < 0) {
    const int e = errno;
    throw Failure{{e == ENOENT ? Errc::not_found : e == ENOSPC ? Errc::no_space : Errc::unreachable,
                   "recording '" + path + "': cannot be made: " + std::strerror(e)}};
  }
  Bytes head{std::begin(kMagic), std::end(kMagic)};
  s.data_crc = crc32(head);
  s.append(head);
  Bytes header;
  put_string(header, s.options.profile);
  put_string(header, "prime");
  s.data_record(kHeader, header);
  s.records.reserve(s.options.chunk_size + 4096);
}

McapWriter::~McapWriter() {
  try {
    close();
  } catch (const Failure&) {
  }
  if (state_->fd >= 0) ::close(state_->fd);
}

const std::string& McapWriter::path() const noexcept { return state_->path; }
std::uint64_t McapWriter::bytes_written() const noexcept { return state_->offset; }

std::uint16_t McapWriter::add_schema(const std::string& name, const std::string& encoding, const std::string& data) {
  auto& s = *state_;
  if (s.closed) throw Failure{{Errc::invalid_argument, "recording '" + s.path + "': closed"}};
  const auto id = static_cast<std::uint16_t>(s.schemas.size() + 1);
  Schema schema{id, name, encoding, data};
  s.data_record(kSchema, schema_body(schema));
  s.schemas[id] = std::move(schema);
  ++s.stats.schema_count;
  return id;
}

std::uint16_t McapWriter::add_channel(std::uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                                      const std::map<std::string, std::string>& metadata) {
  auto& s = *state_;
  if (s.closed) throw Failure{{Errc::invalid_argument, "recording '" + s.path + "': closed"}};
  if (schema_id != 0 && !s.schemas.contains(schema_id))
    throw Failure{{Errc::invalid_argument, "recording '" + s.path + "': no schema " + std::to_string(schema_id)}};
  const auto id = static_cast<std::uint16_t>(s.channels.size() + 1);
  Channel channel{id, schema_id, topic, message_encoding, metadata};
  s.data_record(kChannel, channel_body(channel));
  s.channels[id] = std::move(channel);
  ++s.stats.channel_count;
  s.stats.channel_message_counts[id] = 0;
  return id;
}

void McapWriter::write(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                       std::uint64_t publish_time, std::span<const std::byte> data) {
  auto& s = *state_;
  if (s.closed) throw Failure{{Errc::invalid_argument, "recording '" + s.path + "': closed"}};
  auto counted = s.stats.channel_message_counts.find(channel_id);
  if (counted == s.stats.channel_message_counts.end())
    throw Failure{{Errc::invalid_argument, "recording '" + s.path + "': no channel " + std::to_string(channel_id)}};
  if (s.records.empty()) s.chunk_start = s.chunk_end = log_time;
  s.chunk_start = std::min(s.chunk_start, log_time);
  s.chunk_end = std::max(s.chunk_end, log_time);
  s.index[channel_id].emplace_back(log_time, s.records.size());
  s.records.push_back(std::byte{kMessage});
  put<std::uint64_t>(s.records, 2 + 4 + 8 + 8 + data.size());
  put<std::uint16_t>(s.records, channel_id);
  put<std::uint32_t>(s.records, sequence);
  put<std::uint64_t>(s.records, log_time);
  put<std::uint64_t>(s.records, publish_time);
  put_bytes(s.records, data);
  auto& st = s.stats;
  if (st.message_count == 0) st.message_start_time = st.message_end_time = log_time;
  st.message_start_time = std::min(st.message_start_time, log_time);
  st.message_end_time = std::max(st.message_end_time, log_time);
  ++st.message_count;
  ++counted->second;
  if (s.records.size() >= s.options.chunk_size) s.flush_chunk();
}

void McapWriter::add_metadata(const std::string& name, const std::map<std::string, std::string>& values) {
  auto& s = *state_;
  if (s.closed) throw Failure{{Errc::invalid_argument, "recording '" + s.path + "': closed"}};
  Bytes body;
  put_string(body, name);
  put_string_map(body, values);
  const auto at = s.offset;
  s.data_record(kMetadata, body);
  s.metadata.push_back({Metadata{name, values}, {at, s.offset - at}});
  ++s.stats.metadata_count;
}

void McapWriter::close() {
  auto& s = *state_;
  if (s.closed) return;
  s.closed = true;
  s.flush_chunk();
  Bytes end;
  put<std::uint32_t>(end, s.data_crc);
  Bytes data_end;
  put_record(data_end, kDataEnd, end);
  s.append(data_end);

  // The summary, grouped by opcode, and where each group lies.
  const auto summary_start = s.offset;
  Bytes summary;
  std::vector<std::tuple<Op, std::uint64_t, std::uint64_t>> groups;
  auto group = [&](Op op, auto&& write_all) {
    const auto from = summary.size();
    write_all();
    if (summary.size() > from) groups.emplace_back(op, summary_start + from, summary.size() - from);
  };
  group(kSchema, [&] {
    for (const auto& [id, sc] : s.schemas) put_record(summary, kSchema, schema_body(sc));
  });
  group(kChannel, [&] {
    for (const auto& [id, ch] : s.channels) put_record(summary, kChannel, channel_body(ch));
  });
  group(kStatistics, [&] {
    const auto& st = s.stats;
    Bytes b;
    put<std::uint64_t>(b, st.message_count);
    put<std::uint16_t>(b, st.schema_count);
    put<std::uint32_t>(b, st.channel_count);
    put<std::uint32_t>(b, st.attachment_count);
    put<std::uint32_t>(b, st.metadata_count);
    put<std::uint32_t>(b, st.chunk_count);
    put<std::uint64_t>(b, st.message_start_time);
    put<std::uint64_t>(b, st.message_end_time);
    put_offset_map(b, st.channel_message_counts);
    put_record(summary, kStatistics, b);
  });
  group(kChunkIndex, [&] {
    for (const auto& c : s.chunks) {
      Bytes b;
      put<std::uint64_t>(b, c.message_start_time);
      put<std::uint64_t>(b, c.message_end_time);
      put<std::uint64_t>(b, c.offset);
      put<std::uint64_t>(b, c.length);
      put_offset_map(b, c.message_index_offsets);
      put<std::uint64_t>(b, c.message_index_length);
      put_string(b, c.compression);
      put<std::uint64_t>(b, c.compressed_size);
      put<std::uint64_t>(b, c.uncompressed_size);
      put_record(summary, kChunkIndex, b);
    }
  });
  group(kMetadataIndex, [&] {
    for (const auto& [m, where] : s.metadata) {
      Bytes b;
      put<std::uint64_t>(b, where.first);
      put<std::uint64_t>(b, where.second);
      put_string(b, m.name);
      put_record(summary, kMetadataIndex, b);
    }
  });
  const auto offsets_start = summary_start + summary.size();
  for (const auto& [op, start, length] : groups) {
    Bytes b;
    b.push_back(std::byte{op});
    put<std::uint64_t>(b, start);
    put<std::uint64_t>(b, length);
    put_record(summary, kSummaryOffset, b);
  }
  Bytes footer;
  footer.push_back(std::byte{kFooter});
  put<std::uint64_t>(footer, 8 + 8 + 4);
  put<std::uint64_t>(footer, summary_start);
  put<std::uint64_t>(footer, groups.empty() ? 0 : offsets_start);
  const auto summary_crc = crc32(footer, crc32(summary));
  put<std::uint32_t>(footer, summary_crc);
  summary.insert(summary.end(), footer.begin(), footer.end());
  summary.insert(summary.end(), std::begin(kMagic), std::end(kMagic));
  s.append(summary);
  if (::fsync(s.fd) != 0 && errno != EINVAL)
    throw Failure{{Errc::unreachable, "recording '" + s.path + "': " + std::strerror(errno)}};
}

}  // namespace prime::record
