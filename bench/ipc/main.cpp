// prime_ipc: one-way latency and throughput between two processes, for
// Prime's Shm medium and its peers, in one run. `prime bench` makes the report;
// harness.hpp says how a peer plugs in.
//
//   prime_ipc [--ipc_no_pin] [--benchmark_*...]
//
// A child process is this binary again, started by the harness as
// `prime_ipc --ipc-child <entry> ...`: it is dispatched here before Google
// Benchmark sees the command line.

#include "harness.hpp"

int main(int argc, char** argv) { return prime::bench::ipc::benchmark_main(argc, argv); }
