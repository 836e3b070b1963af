#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "prime/record/mcap.hpp"
#include "prime/record/mcap_reader.hpp"

namespace prime::record {

// One or more recordings read as one timeline: their messages in the order
// of their log times, across files and chunks. Seeking reads only the
// chunks whose span (from each file's chunk index) reaches the time asked
// for, and a few chunks are held at a time, however long the files.
// Errors are the McapReader's (prime::Failure naming the file and what is
// wrong). Not thread-safe.
class MergedReader {
 public:
  explicit MergedReader(const std::vector<std::string>& files);

  [[nodiscard]] std::size_t files() const noexcept { return files_.size(); }
  [[nodiscard]] const McapReader& file(std::size_t i) const { return *files_.at(i); }
  [[nodiscard]] const std::string& path(std::size_t i) const { return paths_.at(i); }
  // The earliest and latest log time of all the files (Unix ns); both 0
  // when they hold no message.
  [[nodiscard]] std::uint64_t start_time() const noexcept { return start_; }
  [[nodiscard]] std::uint64_t end_time() const noexcept { return end_; }

  // Which channels to read: those of file `file` with id `channel` for
  // which it is true (every channel, when empty).
  using Wanted = std::function<bool(std::size_t file, std::uint16_t channel)>;
  // From here on, the messages logged from `from` to `to` (inclusive).
  void seek(std::uint64_t from, std::uint64_t to = std::numeric_limits<std::uint64_t>::max(), Wanted wanted = {});

  struct Next {
    std::size_t file;  // which of the files, in the order given
    Message message;
  };
  // The next message in log time order (equal times: in the order of the
  // files given, then as written); nullopt after the last.
  [[nodiscard]] std::optional<Next> next();
  // Chunks decompressed since the last seek: what the seek cost.
  [[nodiscard]] std::size_t chunks_read() const noexcept { return chunks_read_; }

 private:
  struct Chunk {
    std::uint64_t start, end;
    std::size_t file;
    const ChunkInfo* info;
  };
  struct Held {
    std::uint64_t log_time;
    std::uint64_t order;  // of loading: keeps equal times as written
    std::size_t file;
    Message message;
  };
  void load(const Chunk& chunk);

  std::vector<std::string> paths_;
  std::vector<std::unique_ptr<McapReader>> files_;
  std::vector<Chunk> chunks_;  // of every file, by their first log time
  std::uint64_t start_ = 0, end_ = 0;
  std::uint64_t from_ = 0, to_ = 0;
  Wanted wanted_;
  std::size_t pending_ = 0;  // the first chunk not loaded
  std::vector<Held> heap_;   // loaded and not yet given, a min-heap by (log_time, order)
  std::uint64_t loaded_ = 0;
  std::size_t chunks_read_ = 0;
};

}  // namespace prime::record
