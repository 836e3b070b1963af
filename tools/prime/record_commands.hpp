#pragma once

// `prime record`: topics of a shared-memory domain into an MCAP file, and
// `prime record info`: what a recording holds.

#include <cstddef>
#include <string>
#include <vector>

#include "shm_commands.hpp"

namespace prime::tool {

struct RecordOptions {
  std::vector<std::string> topics;  // none: --all
  bool all = false;
  std::string exclude;  // a regular expression of topics to leave out (with --all)
  std::string out;      // the file
  std::string compression = "zstd";
  std::size_t chunk_size = 1 << 20;
  std::uint64_t max_size = 0;  // bytes a file reaches before the next is begun (0: one file)
  double max_duration = 0;     // seconds a file spans before the next is begun (0: one file)
  double snapshot = 0;         // seconds kept in memory, written at each SIGUSR1 (0: record everything)
};

int shm_record(const Options& o, const RecordOptions& r);
// The same, of an Optimus domain's sources (--redis).
int optimus_record(const Options& o, const RecordOptions& r);
int record_info(const Options& o, const std::string& file);
// A recording whose writer died (no summary, a chunk cut short) rewritten
// whole into `out`: its complete chunks, with an index and a summary.
int record_recover(const std::string& file, const std::string& out);

}  // namespace prime::tool
