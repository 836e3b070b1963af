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
// The floor's message is 64 bytes with its sequence inside, one cache line.
// A medium's 64-byte payload travels with a header (its sequence, size and
// stamp), so the same ring, 256 deep, also runs with the header laid out
// four ways, read in batches as Shm's batch readers read (the entries of
// up to 32 messages out, then each one): what a ring of that layout moves
// before any bookkeeping of its own.
// - SpscInline: 128-byte slots, the header on the line before the payload.
// - SpscRecords: 32-byte records (sequence, size, stamp), two to a line, in
//   an array of their own beside the 64-byte payload slots.
// - SpscRecordsHeaders: the same, and a 32-byte header (who holds it,
//   sequence, size, stamp) written for each message on a line of its own,
//   as Shm's publisher wrote one in each chunk until layout 12.
// - SpscShmLayout: Shm's own layout, from its TopicGeometry (layout.hpp): a
//   ring of entries naming chunks, the sizes and stamps beside it, and
//   chunks of a 128-byte header block and a payload block, taken in turn
//   as Shm's publisher takes them; each written as a publish writes it.
//
//   Throughput  the child writes seq = 1, 2, 3... into the ring as fast as
//               it has room; the parent takes one per iteration and checks
//               it (lossless: a full ring makes the child wait).

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <new>

#include "harness.hpp"
#include "payload.hpp"
#include "prime/shm/detail/layout.hpp"

namespace {

namespace ipc = prime::bench::ipc;
namespace layout = prime::shm::detail;

static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "atomics across processes must be lock-free");

// A layout: where message `seq` (1, 2, 3...) lies. The producer write()s it;
// the consumer polls has(seq), then read(seq) gives the sequence its payload
// carries (0 when its header does not describe a 64-byte message).
// kBatches: whether the consumer reads it in batches.
template <std::uint64_t kSlots>
struct Slots {
  static_assert(kSlots > 0 && (kSlots & (kSlots - 1)) == 0, "a power of two, to index by mask");
  static constexpr std::uint64_t kDepth = kSlots;
  static constexpr bool kBatches = false;

  // seq: 0 until the slot's first message; then the sequence it carries.
  struct alignas(64) Slot {
    std::atomic<std::uint64_t> seq;
    std::byte rest[56];
  };
  static_assert(sizeof(Slot) == 64);
  Slot slots[kSlots]{};

  void write(std::uint64_t seq) noexcept {
    Slot& slot = slots[(seq - 1) & (kSlots - 1)];
    std::memset(slot.rest, 0, sizeof slot.rest);  // a whole 64-byte message is written
    slot.seq.store(seq, std::memory_order_release);
  }
  [[nodiscard]] bool has(std::uint64_t seq) noexcept {
    return slots[(seq - 1) & (kSlots - 1)].seq.load(std::memory_order_acquire) == seq;
  }
  [[nodiscard]] std::uint64_t read(std::uint64_t seq) noexcept {
    return slots[(seq - 1) & (kSlots - 1)].seq.load(std::memory_order_relaxed);
  }
};

constexpr std::uint64_t kDepth = ipc::kStreamDepth;
constexpr std::size_t kPayload = 64;

void write_payload(std::byte* payload, std::uint64_t seq) noexcept {
  std::memset(payload, 0, kPayload);
  ipc::stamp(payload, seq);
}

struct Inline {
  static constexpr std::uint64_t kDepth = ::kDepth;
  static constexpr bool kBatches = true;
  struct alignas(64) Place {
    std::atomic<std::uint64_t> seq;
    std::uint64_t size;
    std::int64_t stamp;
    alignas(64) std::byte payload[kPayload];
  };
  static_assert(sizeof(Place) == 128);
  Place places[kDepth]{};

  void write(std::uint64_t seq) noexcept {
    Place& place = places[(seq - 1) % kDepth];
    write_payload(place.payload, seq);
    place.size = kPayload;
    place.stamp = static_cast<std::int64_t>(seq);
    place.seq.store(seq, std::memory_order_release);
  }
  [[nodiscard]] bool has(std::uint64_t seq) noexcept {
    return places[(seq - 1) % kDepth].seq.load(std::memory_order_acquire) == seq;
  }
  [[nodiscard]] std::uint64_t read(std::uint64_t seq) noexcept {
    const Place& place = places[(seq - 1) % kDepth];
    return place.size == kPayload ? ipc::seq_of(place.payload) : 0;
  }
};

template <bool kHeaders>
struct Records {
  static constexpr std::uint64_t kDepth = ::kDepth;
  static constexpr bool kBatches = true;
  struct Record {
    std::atomic<std::uint64_t> seq;
    std::uint64_t size;
    std::int64_t stamp;
    std::uint64_t unused;
  };
  static_assert(sizeof(Record) == 32);
  struct alignas(64) Payload {
    std::byte bytes[kPayload];
  };
  Record records[kDepth]{};
  alignas(4096) Payload payloads[kDepth]{};  // a page apart, as Shm's infos and chunks
  struct alignas(64) Header {
    std::atomic<std::uint64_t> holders;
    std::atomic<std::uint64_t> seq;
    std::uint64_t size;
    std::int64_t stamp;
  };
  alignas(4096) Header headers[kHeaders ? kDepth : 1]{};

  void write(std::uint64_t seq) noexcept {
    const auto i = (seq - 1) % kDepth;
    write_payload(payloads[i].bytes, seq);
    if constexpr (kHeaders) {
      auto& header = headers[i];
      header.size = kPayload;
      header.stamp = static_cast<std::int64_t>(seq);
      header.seq.store(seq, std::memory_order_release);
      header.holders.store(1, std::memory_order_release);
    }
    records[i].size = kPayload;
    records[i].stamp = static_cast<std::int64_t>(seq);
    records[i].seq.store(seq, std::memory_order_release);
  }
  [[nodiscard]] bool has(std::uint64_t seq) noexcept {
    return records[(seq - 1) % kDepth].seq.load(std::memory_order_acquire) == seq;
  }
  [[nodiscard]] std::uint64_t read(std::uint64_t seq) noexcept {
    const auto i = (seq - 1) % kDepth;
    const bool described = records[i].size == kPayload && records[i].stamp == static_cast<std::int64_t>(seq);
    return described ? ipc::seq_of(payloads[i].bytes) : 0;
  }
};

// Shm's segment for a `block` topic of kDepth 64-byte messages with one
// subscriber that holds up to 32 (the batch benchmarks' QoS), placed by
// Shm's own geometry; its header part goes unused.
struct ShmLayout {
  static constexpr std::uint64_t kDepth = ::kDepth;
  static constexpr bool kBatches = true;
  static constexpr layout::TopicGeometry kGeometry{kDepth, kPayload, 1, 32};
  alignas(4096) std::byte segment[kGeometry.bytes()]{};

  std::atomic<std::uint64_t>& ring(std::uint64_t seq) noexcept {
    return std::launder(reinterpret_cast<std::atomic<std::uint64_t>*>(segment + kGeometry.ring_offset()))[seq % kDepth];
  }
  layout::SampleInfo& info(std::uint64_t seq) noexcept {
    return std::launder(reinterpret_cast<layout::SampleInfo*>(segment + kGeometry.info_offset()))[seq % kDepth];
  }
  std::byte* chunk(std::uint32_t c) noexcept { return segment + kGeometry.chunks_offset() + c * kGeometry.chunk_stride(); }

  // As Writer::publish_some: the payload, the info, then the ring entry.
  // Chunks are taken in turn, as they come back to a publisher whose
  // subscriber keeps up.
  void write(std::uint64_t seq) noexcept {
    const auto c = static_cast<std::uint32_t>(seq % kGeometry.chunk_count());
    write_payload(chunk(c) + layout::kPayloadOffset, seq);
    info(seq).word.store(layout::SampleInfo::pack(seq, kPayload), std::memory_order_release);
    info(seq).stamp.store(static_cast<std::int64_t>(seq), std::memory_order_release);
    ring(seq).store(layout::RingEntry::pack(seq, c), std::memory_order_release);
  }
  [[nodiscard]] bool has(std::uint64_t seq) noexcept {
    return layout::RingEntry::ahead(ring(seq).load(std::memory_order_acquire), seq) == 0;
  }
  // As a batch of views reads it (Cursor::take_batch): the entry, the info
  // beside it, the payload.
  [[nodiscard]] std::uint64_t read(std::uint64_t seq) noexcept {
    const auto c = layout::RingEntry::chunk(ring(seq).load(std::memory_order_relaxed));
    if (c >= kGeometry.chunk_count() || info(seq).word.load(std::memory_order_acquire) != layout::SampleInfo::pack(seq, kPayload)) return 0;
    return ipc::seq_of(chunk(c) + layout::kPayloadOffset);
  }
};

template <class Layout>
struct Ring {
  alignas(64) std::atomic<std::uint64_t> tail{0};  // written by the consumer
  Layout layout{};
};

template <class Layout>
void produce(ipc::Child& self) {
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(Ring<Layout>));
  auto& ring = mapping.as<Ring<Layout>>();
  self.ready();
  std::uint64_t head = 0, tail = 0;  // tail: the consumer's, as last read
  while (true) {
    if (head - tail == Layout::kDepth)
      ipc::spin_until(self, [&] { return head - (tail = ring.tail.load(std::memory_order_acquire)) < Layout::kDepth; });
    ring.layout.write(++head);
  }
}

template <class Layout>
void throughput(benchmark::State& state, const char* producer) {
  ipc::run(state, [&](std::size_t bytes) {
    auto mapping = ipc::SharedMapping::create("prime-ipc-spsc", sizeof(Ring<Layout>));
    auto& ring = mapping.construct<Ring<Layout>>();
    ipc::Link child{producer, bytes, {mapping.fd()}};
    std::uint64_t tail = 0;
    auto ready = [&] { return ring.layout.has(tail + 1); };
    // The consumer hands slots back kBatch at a time (and whenever it finds
    // the ring empty), so the tail's line moves once per batch, not per message.
    constexpr std::uint64_t kBatch = 32;
    child.set_drain([&] {
      if (ready()) ++tail;
      ring.tail.store(tail, std::memory_order_release);
    });
    child.wait_ready();
    child.go();
    // In batches: the messages known to be out run to `out`; once all are
    // read, the slots go back and the next batch is looked for.
    std::uint64_t out = 0;
    ipc::time_stream(state, [&](std::uint64_t seq) {
      if constexpr (Layout::kBatches) {
        if (tail == out) {
          ring.tail.store(tail, std::memory_order_release);
          if (!ready()) ipc::spin_until(child, ready);
          for (out = tail + 1; out - tail < kBatch && ring.layout.has(out + 1);) ++out;
        }
      } else if (!ready()) {
        ring.tail.store(tail, std::memory_order_release);
        ipc::spin_until(child, ready);
      }
      const auto got = ring.layout.read(++tail);
      if constexpr (!Layout::kBatches)
        if (tail % kBatch == 0) ring.tail.store(tail, std::memory_order_release);
      if (got != seq) throw ipc::out_of_sequence(seq, got);
    });
    child.stop();
  });
}

using Floor = Slots<4096>;
using Floor256 = Slots<kDepth>;
const ipc::ChildEntry kFloor{"SpscFloor.produce", produce<Floor>};
const ipc::ChildEntry kFloor256{"SpscFloor256.produce", produce<Floor256>};
const ipc::ChildEntry kInline{"SpscInline.produce", produce<Inline>};
const ipc::ChildEntry kRecords{"SpscRecords.produce", produce<Records<false>>};
const ipc::ChildEntry kRecordsHeaders{"SpscRecordsHeaders.produce", produce<Records<true>>};
const ipc::ChildEntry kShmLayout{"SpscShmLayout.produce", produce<ShmLayout>};

void BM_Throughput_SpscFloor(benchmark::State& state) { throughput<Floor>(state, "SpscFloor.produce"); }
void BM_Throughput_SpscFloor256(benchmark::State& state) { throughput<Floor256>(state, "SpscFloor256.produce"); }
void BM_Throughput_SpscInline(benchmark::State& state) { throughput<Inline>(state, "SpscInline.produce"); }
void BM_Throughput_SpscRecords(benchmark::State& state) { throughput<Records<false>>(state, "SpscRecords.produce"); }
void BM_Throughput_SpscRecordsHeaders(benchmark::State& state) {
  throughput<Records<true>>(state, "SpscRecordsHeaders.produce");
}
void BM_Throughput_SpscShmLayout(benchmark::State& state) { throughput<ShmLayout>(state, "SpscShmLayout.produce"); }
BENCHMARK(BM_Throughput_SpscFloor)->Arg(64)->UseRealTime();
BENCHMARK(BM_Throughput_SpscFloor256)->Arg(64)->UseRealTime();
BENCHMARK(BM_Throughput_SpscInline)->Arg(64)->UseRealTime();
BENCHMARK(BM_Throughput_SpscRecords)->Arg(64)->UseRealTime();
BENCHMARK(BM_Throughput_SpscRecordsHeaders)->Arg(64)->UseRealTime();
BENCHMARK(BM_Throughput_SpscShmLayout)->Arg(64)->UseRealTime();

}  // namespace
