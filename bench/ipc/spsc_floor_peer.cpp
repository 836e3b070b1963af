// SpscFloor: the throughput floor between two processes — the most 64-byte
// messages per second this machine moves through shared memory. A plain
// single-producer/single-consumer ring of 64-byte slots in one shared
// mapping, written as well as we know how: the producer's head and the
// consumer's tail on lines of their own, each side caching the other's index
// and reading it again only when the ring looks full (producer) or empty
// (consumer), and the consumer handing slots back in batches. Nothing else: no loans, no readers' cursors, no wake-ups, so
// Shm's lossless throughput is reported as a ratio to it.
//
// SpscFloor256: the same ring, ipc::kStreamDepth (256) slots deep: as deep
// as Shm's topics and the iceoryx, Fast DDS and POSIX queue peers' queues in
// these benchmarks. A ring's rate depends on its depth (measured on the
// 2-vCPU development VM: about 20 M msgs/s at 256 slots, 25 M at 1024,
// 60-120 M at 4096), so this is the floor for a queue as deep as the ones
// measured against it; SpscFloor, 4096 deep, is the machine's.
//
//   Throughput  the child writes seq = 1, 2, 3... into the slots as fast as
//               the ring has room; the parent takes one per iteration and
//               checks it (lossless: a full ring makes the child wait).

#include <atomic>
#include <cstdint>
#include <cstring>

#include "harness.hpp"

namespace {

namespace ipc = prime::bench::ipc;

struct alignas(64) Slot {
  std::uint64_t seq;
  std::byte rest[56];
};
static_assert(sizeof(Slot) == 64);

// kSlots: a power of two, to index by mask.
template <std::uint64_t kSlots>
struct Ring {
  static_assert(kSlots > 0 && (kSlots & (kSlots - 1)) == 0);
  alignas(64) std::atomic<std::uint64_t> head{0};  // written by the producer
  alignas(64) std::atomic<std::uint64_t> tail{0};  // written by the consumer
  alignas(64) Slot slots[kSlots];
};
static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "atomics across processes must be lock-free");

template <std::uint64_t kSlots>
void produce(ipc::Child& self) {
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(Ring<kSlots>));
  auto& ring = mapping.as<Ring<kSlots>>();
  self.ready();
  std::uint64_t head = 0, tail = 0;  // tail: the consumer's, as last read
  for (std::uint64_t seq = 1;; ++seq) {
    if (head - tail == kSlots)
      ipc::spin_until(self, [&] { return head - (tail = ring.tail.load(std::memory_order_acquire)) < kSlots; });
    Slot& slot = ring.slots[head & (kSlots - 1)];
    slot.seq = seq;
    std::memset(slot.rest, 0, sizeof slot.rest);  // a whole 64-byte message is written
    ring.head.store(++head, std::memory_order_release);
  }
}
constexpr std::uint64_t kMachineDepth = 4096;
constexpr const char* kProducer = "SpscFloor.produce";
constexpr const char* kProducerAtStreamDepth = "SpscFloor256.produce";
const ipc::ChildEntry kProduce{kProducer, produce<kMachineDepth>};
const ipc::ChildEntry kProduceAtStreamDepth{kProducerAtStreamDepth, produce<ipc::kStreamDepth>};

template <std::uint64_t kSlots>
void throughput(benchmark::State& state, const char* producer) {
  ipc::run(state, [&](std::size_t bytes) {
    auto mapping = ipc::SharedMapping::create("prime-ipc-spsc", sizeof(Ring<kSlots>));
    auto& ring = mapping.construct<Ring<kSlots>>();
    ipc::Link child{producer, bytes, {mapping.fd()}};
    std::uint64_t tail = 0, head = 0;  // head: the producer's, as last read
    // The consumer hands slots back kBatch at a time (and whenever it finds
    // the ring empty), so the tail's line moves once per batch, not per message.
    constexpr std::uint64_t kBatch = 32;
    auto take = [&]() -> std::uint64_t {
      const std::uint64_t seq = ring.slots[tail & (kSlots - 1)].seq;
      if (++tail % kBatch == 0) ring.tail.store(tail, std::memory_order_release);
      return seq;
    };
    child.set_drain([&] {
      if (tail != ring.head.load(std::memory_order_acquire)) (void)take();
      ring.tail.store(tail, std::memory_order_release);
    });
    child.wait_ready();
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) {
      if (tail == head) {
        ring.tail.store(tail, std::memory_order_release);
        ipc::spin_until(child, [&] { return (head = ring.head.load(std::memory_order_acquire)) != tail; });
      }
      if (const auto got = take(); got != seq) throw ipc::out_of_sequence(seq, got);
    });
    child.stop();
  });
}
void BM_Throughput_SpscFloor(benchmark::State& state) { throughput<kMachineDepth>(state, kProducer); }
void BM_Throughput_SpscFloor256(benchmark::State& state) {
  throughput<ipc::kStreamDepth>(state, kProducerAtStreamDepth);
}
BENCHMARK(BM_Throughput_SpscFloor)->Arg(64)->UseRealTime();
BENCHMARK(BM_Throughput_SpscFloor256)->Arg(64)->UseRealTime();

}  // namespace
