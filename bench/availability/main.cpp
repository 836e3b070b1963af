// prime_availability: how available a service stays, and how fast it answers,
// while other clients call it too — the method of the communication-
// architecture paper, for an Shm service and an Optimus (Redis) service.
//
//   main client ──post every period──▶ ┌─────────┐
//   extra client ─call, 1..20 ms gaps─▶ │ "shout" │  upper-cases the text, answers
//   ... (0 or 5 of them)              ▶ └─────────┘  its FNV-1a checksum
//
// The service. "shout" takes a request of `chars` characters of text (10,
// 1000 or 20000) after a 24-byte header (who sent it, its number, when:
// availability.hpp), upper-cases the text into a buffer and answers the
// checksum of the result: work proportional to the payload, the same code on
// both media. Shm carries the request as raw bytes (shm::Bytes), Optimus as a
// std::string.
//
// Availability: BM_Availability_<Shm|Optimus>/<period_ms>/<chars>/<extra_clients>,
// periods 1, 10, 100 ms, 0 or 5 extra clients. The main client sends
// min(200, 2 s / period) requests (PRIME_AVAILABILITY_REQUESTS=<n> lowers
// that, for a quick run) on a fixed schedule, one per period, asynchronously:
// it never waits for an answer. Each extra client, a process of its own,
// waits a uniform 1..20 ms, calls the same service with the same payload size
// and waits for the answer, again and again.
//   "executed" is counted where the service runs: the service notes the first
//   time it starts each of the main client's requests (by number) in a ledger
//   (shared memory for Shm, a variable of the serving process for Optimus). A
//   request counts whenever it runs, as long as that is no later than 1 s
//   after the last request was sent (Shm: the main client then waits up to 1
//   s for the queue to drain) or within its call's 1 s deadline (Optimus: a
//   worker does not run a request whose caller has given up). A request the
//   medium refuses (a full queue, no free call slot, a timeout) is sent but
//   not executed; nothing waits unboundedly.
//   Counters: availability = executed / sent (0..1), sent, executed, refused
//   (not even queued), on_time (started by the service before the main
//   client's next request was due), extra_calls (the extra clients' requests
//   the service ran meanwhile). The time shown is the sending phase's.
//
// Response time: BM_Response_<Shm|Optimus>/<chars>/<extra_clients>. The main
// client calls and waits, 500 times for Shm and 200 for Optimus (after 10
// untimed calls), with the extra clients calling meanwhile or not, each
// answer checked against the checksum. Counters: mean_ns, p50_ns, p99_ns,
// max_ns, outliers (calls slower than 10 × the median) and outlier_share.
// The time shown is the mean call.
//
// Processes. Shm: the service runs in a child process, the main client is
// this process, each extra client another child — no client shares the
// server's process. Optimus: the service is a worker of one Core of this
// process and the main client uses another Core; Redis is the hop either way;
// the extra clients are child processes. Children are this binary started
// again through bench/ipc's harness (harness.hpp); every wait is bounded, a
// dead or failed peer ends the benchmark with an error, and every child is
// stopped and reaped. The Optimus runs use a redis-server this binary starts
// (persistence off, a free loopback port) and stops at exit.
//   CPUs: as in prime_ipc, this process runs on the first CPU it may use and
// every child on the second (the Shm service and the extra clients share
// it; redis-server is not pinned). Unpinned (--ipc_no_pin), a client and a
// server that spin for each other may land on one CPU, where each spins out
// its 50 us before the other runs: a call then takes ~100 us instead of ~1
// us, depending on where the scheduler put them.
//
// What differs from the paper:
//  - The paper discarded 3 % of its response-time samples as outliers; here
//    no sample is dropped: the outliers are counted and shown.
//  - Optimus chains have no asynchronous call, so the main client "posts"
//    by handing each request to one of four sender threads that call and
//    drop the answer; with all four busy a request is refused, as an Shm
//    client is refused past its four calls in flight (calls_per_client).
//  - Each configuration runs once with a fixed number of requests (bounded
//    to about 2 s), not for a fixed long time; the machine's CPU count bounds
//    how many of the processes run at once (with 5 extra clients there are
//    7 processes).
//
//   prime_availability [--ipc_no_pin] [--benchmark_*...]

#include "harness.hpp"

int main(int argc, char** argv) { return prime::bench::ipc::benchmark_main(argc, argv); }
