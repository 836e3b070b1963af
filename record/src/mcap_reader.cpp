// An MCAP file read back: the summary from its end, or, when its writer
// died before closing, from a scan of its data section; messages chunk by
// chunk. Every length is checked against the file, every CRC that is set.
#include "prime/record/mcap_reader.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "compression.hpp"
#include "wire.hpp"

namespace prime::record {

using namespace detail;

namespace {

constexpr std::uint64_t kRecordHead = 1 + 8;            // opcode, length
constexpr std::uint64_t kFooterSize = kRecordHead + 20;  // summary_start, summary_offset_start, summary_crc

Schema parse_schema(Cursor& c) {
  Schema s;
  s.id = c.get<std::uint16_t>();
  s.name = c.string();
  s.encoding = c.string();
  s.data = c.string();
  return s;
}
Channel parse_channel(Cursor& c) {
  Channel ch;
  ch.id = c.get<std::uint16_t>();
  ch.schema_id = c.get<std::uint16_t>();
  ch.topic = c.string();
  ch.message_encoding = c.string();
  ch.metadata = c.string_map();
  return ch;
}

}  // namespace

struct McapReader::State {
  std::string path;
  int fd = -1;
  std::uint64_t size = 0;
  Summary summary;
  bool complete = false;

  [[noreturn]] void damaged(const std::string& why) const {
    throw Failure{{Errc::damaged, "recording '" + path + "': " + why}};
  }
  Bytes read(std::uint64_t at, std::uint64_t n) const {
    if (at > size || n > size - at)
      damaged(std::to_string(n) + " bytes at offset " + std::to_string(at) + " run past its end (" +
              std::to_string(size) + " bytes)");
    Bytes out(static_cast<std::size_t>(n));
    for (std::size_t done = 0; done < out.size();) {
      const auto got = ::pread(fd, out.data() + done, out.size() - done, static_cast<off_t>(at + done));
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) damaged("reading at offset " + std::to_string(at + done) + ": " + (got < 0 ? std::strerror(errno) : "end of file"));
      done += static_cast<std::size_t>(got);
    }
    return out;
  }

  // Chunk record `body` (at `at`): its records, decompressed and checked.
  Bytes chunk_records(std::span<const std::byte> body, std::uint64_t at) const {
    const auto where = "recording '" + path + "': the chunk at offset " + std::to_string(at);
    Cursor c{body, where};
    c.get<std::uint64_t>();
    c.get<std::uint64_t>();
    const auto uncompressed = c.get<std::uint64_t>();
    const auto crc = c.get<std::uint32_t>();
    const auto compression = c.string();
    const auto records = c.take(c.get<std::uint64_t>());
    auto out = decompress(compression, records, uncompressed, where);
    if (crc != 0 && crc32(out) != crc) throw Failure{{Errc::damaged, where + ": its records fail their CRC"}};
    return out;
  }

  bool read_footer_and_summary() {
    if (size < 8 + kFooterSize + 8) return false;
    const auto tail = read(size - 8 - kFooterSize, kFooterSize + 8);
    if (!std::equal(tail.end() - 8, tail.end(), std::begin(kMagic)) || tail[0] != std::byte{kFooter}) return false;
    Cursor f{tail, "recording '" + path + "': its footer"};
    f.get<std::uint8_t>();
    if (f.get<std::uint64_t>() != 20) damaged("its footer's length is not 20");
    const auto summary_start = f.get<std::uint64_t>();
    f.get<std::uint64_t>();
    const auto summary_crc = f.get<std::uint32_t>();
    const auto footer_at = size - 8 - kFooterSize;
    if (summary_start == 0) return true;  // a closed file without a summary: nothing to show from it
    if (summary_start < 8 || summary_start > footer_at) damaged("its summary starts at " + std::to_string(summary_start) + ", outside the file");
    const auto section = read(summary_start, footer_at - summary_start);
    if (summary_crc != 0 && crc32(std::span{tail}.first(kRecordHead + 16), crc32(section)) != summary_crc)
      damaged("its summary fails its CRC");
    Cursor c{section, "recording '" + path + "': its summary"};
    while (!c.done()) {
      const auto op = c.get<std::uint8_t>();
      Cursor r{c.take(c.get<std::uint64_t>()), "recording '" + path + "': a summary record (opcode " + std::to_string(op) + ")"};
      switch (op) {
        case kSchema: {
          auto s = parse_schema(r);
          summary.schemas[s.id] = std::move(s);
          break;
        }
        case kChannel: {
          auto ch = parse_channel(r);
          summary.channels[ch.id] = std::move(ch);
          break;
        }
        case kStatistics: {
          auto& st = summary.statistics;
          st.message_count = r.get<std::uint64_t>();
          st.schema_count = r.get<std::uint16_t>();
          st.channel_count = r.get<std::uint32_t>();
          st.attachment_count = r.get<std::uint32_t>();
          st.metadata_count = r.get<std::uint32_t>();
          st.chunk_count = r.get<std::uint32_t>();
          st.message_start_time = r.get<std::uint64_t>();
          st.message_end_time = r.get<std::uint64_t>();
          st.channel_message_counts = r.offset_map<std::uint16_t>();
          break;
        }
        case kChunkIndex: {
          ChunkInfo ci;
          ci.message_start_time = r.get<std::uint64_t>();
          ci.message_end_time = r.get<std::uint64_t>();
          ci.offset = r.get<std::uint64_t>();
          ci.length = r.get<std::uint64_t>();
          ci.message_index_offsets = r.offset_map<std::uint16_t>();
          ci.message_index_length = r.get<std::uint64_t>();
          ci.compression = r.string();
          ci.compressed_size = r.get<std::uint64_t>();
          ci.uncompressed_size = r.get<std::uint64_t>();
          if (ci.offset < 8 || ci.offset > summary_start || ci.length > summary_start - ci.offset)
            damaged("a chunk index points outside the data section (offset " + std::to_string(ci.offset) + ")");
          summary.chunks.push_back(std::move(ci));
          break;
        }
        case kMetadataIndex: {
          const auto at = r.get<std::uint64_t>();
          const auto length = r.get<std::uint64_t>();
          const auto record = read(at, length);
          Cursor m{record, "recording '" + path + "': the metadata at offset " + std::to_string(at)};
          if (m.get<std::uint8_t>() != kMetadata) damaged("a metadata index points at no metadata record");
          Cursor body{m.take(m.get<std::uint64_t>()), "recording '" + path + "': a metadata record"};
          Metadata md;
          md.name = body.string();
          md.values = body.string_map();
          summary.metadata.push_back(std::move(md));
          break;
        }
        default: break;  // summary offsets, and records this reader does not use
      }
    }
    return true;
  }

  // A file whose writer died: the complete records of its data section.
  void scan() {
    auto& st = summary.statistics;
    std::uint64_t at = 8;
    bool first = true;
    while (size - at >= kRecordHead) {
      const auto head = read(at, kRecordHead);
      Cursor h{head, "recording '" + path + "'"};
      const auto op = h.get<std::uint8_t>();
      const auto length = h.get<std::uint64_t>();
      if (op == 0 || length > size - at - kRecordHead) break;  // cut short here: the rest is lost
      if (first && op != kHeader) damaged("its first record is not a header (opcode " + std::to_string(op) + ")");
      const auto body = read(at + kRecordHead, length);
      Cursor r{body, "recording '" + path + "': the record at offset " + std::to_string(at)};
      if (op == kSchema) {  // the header, first, was read on opening
        auto s = parse_schema(r);
        summary.schemas[s.id] = std::move(s);
      } else if (op == kChannel) {
        auto ch = parse_channel(r);
        summary.channels[ch.id] = std::move(ch);
      } else if (op == kChunk) {
        ChunkInfo ci;
        Cursor c{body, "recording '" + path + "': the chunk at offset " + std::to_string(at)};
        ci.message_start_time = c.get<std::uint64_t>();
        ci.message_end_time = c.get<std::uint64_t>();
        ci.uncompressed_size = c.get<std::uint64_t>();
        c.get<std::uint32_t>();
        ci.compression = c.string();
        ci.compressed_size = c.get<std::uint64_t>();
        ci.offset = at;
        ci.length = kRecordHead + length;
        for_each_in_chunk(chunk_records(body, at), [&](const Message& m) {
          if (st.message_count == 0) st.message_start_time = st.message_end_time = m.log_time;
          st.message_start_time = std::min(st.message_start_time, m.log_time);
          st.message_end_time = std::max(st.message_end_time, m.log_time);
          ++st.message_count;
          ++st.channel_message_counts[m.channel_id];
        });
        summary.chunks.push_back(std::move(ci));
      } else if (op == kMetadata) {
        Metadata md;
        md.name = r.string();
        md.values = r.string_map();
        summary.metadata.push_back(std::move(md));
      } else if (op == kDataEnd) {
        break;
      }
      first = false;
      at += kRecordHead + length;
    }
    st.schema_count = static_cast<std::uint16_t>(summary.schemas.size());
    st.channel_count = static_cast<std::uint32_t>(summary.channels.size());
    st.chunk_count = static_cast<std::uint32_t>(summary.chunks.size());
    st.metadata_count = static_cast<std::uint32_t>(summary.metadata.size());
  }

  void for_each_in_chunk(const Bytes& records, const std::function<void(const Message&)>& visit) const {
    Cursor c{records, "recording '" + path + "': a chunk's records"};
    Message m;
    while (!c.done()) {
      const auto op = c.get<std::uint8_t>();
      Cursor r{c.take(c.get<std::uint64_t>()), "recording '" + path + "': a record in a chunk"};
      if (op != kMessage) continue;
      m.channel_id = r.get<std::uint16_t>();
      m.sequence = r.get<std::uint32_t>();
      m.log_time = r.get<std::uint64_t>();
      m.publish_time = r.get<std::uint64_t>();
      const auto data = r.take(r.left());
      m.data.assign(data.begin(), data.end());
      visit(m);
    }
  }
};

McapReader::McapReader(const std::string& path) : state_{std::make_unique<State>()} {
  auto& s = *state_;
  s.path = path;
  s.fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (s.fd < 0) {
    const int e = errno;
    throw Failure{{e == ENOENT ? Errc::not_found : Errc::unreachable, "recording '" + path + "': " + std::strerror(e)}};
  }
  struct stat st{};
  if (::fstat(s.fd, &st) != 0) throw Failure{{Errc::unreachable, "recording '" + path + "': " + std::strerror(errno)}};
  s.size = static_cast<std::uint64_t>(st.st_size);
  s.summary.file_size = s.size;
  if (s.size < 8 || s.read(0, 8) != Bytes(std::begin(kMagic), std::end(kMagic)))
    throw Failure{{Errc::invalid_argument, "'" + path + "' is not an MCAP file (it does not start with MCAP's magic)"}};
  // The header, for its profile and library.
  if (s.size >= 8 + kRecordHead) {
    const auto head = s.read(8, kRecordHead);
    Cursor h{head, "recording '" + path + "': its header"};
    if (h.get<std::uint8_t>() != kHeader) s.damaged("its first record is not a header");
    const auto length = h.get<std::uint64_t>();
    const auto body = s.read(8 + kRecordHead, length);
    Cursor b{body, "recording '" + path + "': its header"};
    s.summary.profile = b.string();
    s.summary.library = b.string();
  }
  s.complete = s.read_footer_and_summary();
  if (!s.complete) s.scan();
}

McapReader::~McapReader() {
  if (state_->fd >= 0) ::close(state_->fd);
}

const Summary& McapReader::summary() const noexcept { return state_->summary; }
bool McapReader::complete() const noexcept { return state_->complete; }

void McapReader::for_each_message(const std::function<void(const Message&)>& visit) const {
  for (const auto& chunk : state_->summary.chunks) for_each_message_in(chunk, visit);
}

void McapReader::for_each_message_in(const ChunkInfo& chunk, const std::function<void(const Message&)>& visit) const {
  const auto& s = *state_;
  const auto record = s.read(chunk.offset, chunk.length);
  Cursor c{record, "recording '" + s.path + "': the chunk at offset " + std::to_string(chunk.offset)};
  if (c.get<std::uint8_t>() != kChunk) s.damaged("the chunk index points at offset " + std::to_string(chunk.offset) + ", where no chunk is");
  const auto body = c.take(c.get<std::uint64_t>());
  s.for_each_in_chunk(s.chunk_records(body, chunk.offset), visit);
}

}  // namespace prime::record
