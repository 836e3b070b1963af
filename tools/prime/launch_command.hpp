#pragma once

// `prime launch`: starts the processes of one placement of a system file,
// in order of readiness, prefixes and collects their output, restarts them
// by their policy, and stops them all on Ctrl-C.

#include <string>
#include <vector>

namespace prime::tool {

struct LaunchOptions {
  std::string file;                 // the system file
  std::string placement;            // empty: the file's first
  std::vector<std::string> params;  // component.name=value, given to every process
  std::string executable;           // what every process runs, instead of the file's
  std::string domain;               // the domain, instead of the file's `system` (empty: the file's)
  std::string ns;                   // the namespace of every name, instead of the file's (empty: the file's)
  double grace = 5;                 // seconds from SIGTERM to SIGKILL when stopping
  double ready_timeout = 20;        // seconds a process may take to be ready
};

// Exit codes: 0 stopped by Ctrl-C (or SIGTERM) with every process ending
// cleanly, or every process ended with 0 by itself; 1 a process failed (to
// start, or later with no restart), or had to be killed; 2 the system file
// or the placement is wrong (nothing was started).
int launch(const LaunchOptions& options);

}  // namespace prime::tool
