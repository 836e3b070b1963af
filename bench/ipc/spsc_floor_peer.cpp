// SpscFloor: the throughput floor between two processes — the most 64-byte
// messages per second this machine moves through shared memory. A plain
// single-producer/single-consumer ring of 64-byte slots in one shared
// mapping, written as well as we know how:
// - each slot carries its message's sequence, stored last (release): the
//   consumer polls the slot it reads next, not a head index, so no line but
//   the slots themselves goes back and forth per message;
// - the producer caches the consumer's tail and reads it again only when
//   the ring looks full; the consumer hands slots back 32 at a time (and
//   whenever it finds the ring empty), on a line of its own.
// Nothing else: no loans, no readers' cursors, no wake-ups, so Shm's
// lossless throughput is reported as a ratio to it.
//
// An earlier floor published a head index after every message, which the
// consumer polled when it had caught up. On the 2-vCPU development VM it
// ran in two modes, round by round (34-155 M msgs/s at 4096 slots), and at
// 256 slots at 17-27 M, below Shm's batches of views. This ring measured
// 168-228 M at 4096 slots and 95-128 M at 256.
//
// SpscFloor256: the same ring, ipc::kStreamDepth (256) slots deep: as deep
// as Shm's topics and the iceoryx, Fast DDS and POSIX queue peers' queues in
// these benchmarks. A ring's rate depends on its depth, so this is the floor
// for a queue as deep as the ones measured against it; SpscFloor, 4096 deep,
// is the machine's.
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

// seq: 0 until the slot's first message; then the sequence it carries.
struct alignas(64) Slot {
  std::atomic<std::uint64_t> seq;
  std::byte rest[56];
};
static_assert(sizeof(Slot) == 64);
static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "atomics across processes must be lock-free");

// kSlots: a power of two, to index by mask.
template <std::uint64_t kSlots>
struct Ring {
  static_assert(kSlots > 0 && (kSlots & (kSlots - 1)) == 0);
  alignas(64) std::atomic<std::uint64_t> tail{0};  // written by the consumer
  alignas(64) Slot slots[kSlots]{};
};

template <std::uint64_t kSlots>
void produce(ipc::Child& self) {
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(Ring<kSlots>));
  auto& ring = mapping.as<Ring<kSlots>>();
  self.ready();
  std::uint64_t head = 0, tail = 0;  // tail: the consumer's, as last read
  while (true) {
    if (head - tail == kSlots)
      ipc::spin_until(self, [&] { return head - (tail = ring.tail.load(std::memory_order_acquire)) < kSlots; });
    Slot& slot = ring.slots[head & (kSlots - 1)];
    std::memset(slot.rest, 0, sizeof slot.rest);  // a whole 64-byte message is written
    slot.seq.store(++head, std::memory_order_release);
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
    std::uint64_t tail = 0;
    // The next message is in its slot: the slot carries the sequence after it.
    auto ready = [&] { return ring.slots[tail & (kSlots - 1)].seq.load(std::memory_order_acquire) == tail + 1; };
    // The consumer hands slots back kBatch at a time (and whenever it finds
    // the ring empty), so the tail's line moves once per batch, not per message.
    constexpr std::uint64_t kBatch = 32;
    child.set_drain([&] {
      if (ready()) ++tail;
      ring.tail.store(tail, std::memory_order_release);
    });
    child.wait_ready();
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) {
      if (!ready()) {
        ring.tail.store(tail, std::memory_order_release);
        ipc::spin_until(child, ready);
      }
      const auto got = ring.slots[tail & (kSlots - 1)].seq.load(std::memory_order_relaxed);
      if (++tail % kBatch == 0) ring.tail.store(tail, std::memory_order_release);
      if (got != seq) throw ipc::out_of_sequence(seq, got);
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
