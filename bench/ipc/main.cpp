// prime_ipc: one-way latency and throughput between two processes, for
// Prime's Shm medium and its peers, in one run. `prime bench` makes the report;
// harness.hpp says how a peer plugs in.
//
//   prime_ipc [--ipc_no_pin] [--benchmark_*...]
//
// A child process is this binary again, started by the harness as
// `prime_ipc --ipc-child <entry> ...`: it is dispatched here before Google
// Benchmark sees the command line.

#include <benchmark/benchmark.h>

#include "harness.hpp"

int main(int argc, char** argv) {
  namespace ipc = prime::bench::ipc;
  if (ipc::is_child_command(argc, argv)) return ipc::child_main(argc, argv);

  ipc::configure_parent(argc, argv);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  ipc::bound_exit(std::chrono::seconds{10});
  return 0;
}
