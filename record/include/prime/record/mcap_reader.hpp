#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "prime/record/mcap.hpp"

namespace prime::record {

// Reads an MCAP file: its summary from the end (footer, summary section),
// or, for a file whose writer died before closing, by scanning its data
// section up to the last complete chunk. Everything read is checked
// against the file's own bounds and CRCs: a truncated, corrupt or foreign
// file is a prime::Failure naming what is wrong (Errc::damaged, or
// Errc::invalid_argument for a file that is not MCAP; not_found or
// unreachable when it cannot be opened).
class McapReader {
 public:
  explicit McapReader(const std::string& path);
  McapReader(const McapReader&) = delete;
  McapReader& operator=(const McapReader&) = delete;
  ~McapReader();

  // The summary; for a file without one (its writer died), the same
  // figures gathered from the complete chunks, and `complete()` false.
  [[nodiscard]] const Summary& summary() const noexcept;
  [[nodiscard]] bool complete() const noexcept;

  // Every message, chunk by chunk in the file's order, each chunk's
  // messages in the order written.
  void for_each_message(const std::function<void(const Message&)>& visit) const;
  // The messages of one chunk of the summary, in the order written: what
  // a reader that seeks by the chunk index reads, and nothing else.
  void for_each_message_in(const ChunkInfo& chunk, const std::function<void(const Message&)>& visit) const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace prime::record
