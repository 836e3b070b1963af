#pragma once

// `prime play`: recordings published into a domain (shared memory, or
// Optimus with --redis), at their recorded timing or faster, as one
// timeline.

#include <string>
#include <vector>

#include "shm_commands.hpp"

namespace prime::tool {

struct PlayOptions {
  std::vector<std::string> files;
  std::string rate = "1";           // times the recorded speed, or "max": as fast as the readers take it
  bool loop = false;                // again from --start, until Ctrl-C
  double start = 0;                 // seconds into the timeline to start at (found by the chunk index)
  double duration = 0;              // seconds of it to play (0: to its end)
  std::vector<std::string> topics;  // only these recorded topics (none: all)
  std::vector<std::string> remaps;  // "recorded:=published"
  std::string stamps = "now";       // the samples' stamps: "now" (when published) or "keep" (as recorded)
};

int shm_play(const Options& o, const PlayOptions& p);      // recordings of shared-memory topics
int optimus_play(const Options& o, const PlayOptions& p);  // recordings of Optimus sources (--redis)

}  // namespace prime::tool
