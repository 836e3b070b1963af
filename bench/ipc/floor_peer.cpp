// Floor: the physical floor of any shared-memory handoff between two
// processes. Two numbers in one cache line of a shared mapping; the parent
// writes `ping`, the child spins until it sees it and writes `pong`, the
// parent spins until it sees that. Nothing but the cache line moves between
// the cores, so the payload size is irrelevant and only 64 B is measured.

#include <atomic>
#include <cstdint>

#include "harness.hpp"

namespace {

namespace ipc = prime::bench::ipc;

struct alignas(64) Line {
  std::atomic<std::uint64_t> ping{0};
  std::atomic<std::uint64_t> pong{0};
};
static_assert(sizeof(Line) == 64, "both numbers share one cache line");
static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "atomics across processes must be lock-free");

void echo(ipc::Child& self) {
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(Line));
  auto& line = mapping.as<Line>();
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    ipc::spin_until(self, [&] { return line.ping.load(std::memory_order_acquire) == seq; });
    line.pong.store(seq, std::memory_order_release);
  }
}
const ipc::ChildEntry kEcho{"Floor.echo", echo};

void BM_Latency_Floor(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    auto mapping = ipc::SharedMapping::create("prime-ipc-floor", sizeof(Line));
    auto& line = mapping.construct<Line>();
    ipc::Link child{"Floor.echo", bytes, {mapping.fd()}};
    child.wait_ready();
    child.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      line.ping.store(seq, std::memory_order_release);
      ipc::spin_until(child, [&] { return line.pong.load(std::memory_order_acquire) == seq; });
    });
    child.stop();
  });
}
BENCHMARK(BM_Latency_Floor)->Arg(64)->UseRealTime();

}  // namespace
