#pragma once

// `prime bench`: runs every benchmark of Prime and its peers and writes a
// report folder (figures.csv, summary.md, plots).

#include <string>

namespace prime::tool::bench {

struct Options {
  bool quick = false;   // a short run of the main figures (under two minutes on 2 cores)
  std::string out;      // the report folder
  std::string bin_dir;  // where the benchmark binaries are (empty: found beside the tool)
};

// Exit code: 0 with figures written, 1 if nothing could be measured or Ctrl-C
// cut the run short (the report then has what was measured), 2 on wrong usage.
int run(const Options& options);

}  // namespace prime::tool::bench
