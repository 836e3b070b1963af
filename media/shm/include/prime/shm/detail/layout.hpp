#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>

#include "prime/common/fingerprint.hpp"
#include "prime/shm/detail/doorbell.hpp"
#include "prime/shm/detail/versions.hpp"

namespace prime::shm::detail {

// What lives in a topic's shared memory. Everything is plain data or
// lock-free atomics, addressed by offsets from the segment's start (no
// pointers), so each process may map it anywhere.
//
//   TopicHeader | ring: capacity × RingEntry word | info: capacity × SampleInfo
//               | chunks: chunk_count × (ChunkHeader block + payload)
//
// Samples live in chunks. The ring names the chunks of the last `capacity`
// sequences; a chunk is free when no one holds it. Who holds a chunk is one
// word of bits: one per subscriber slot, and one for the publisher, which
// holds the chunks its ring names, those it has loaned out and those it
// keeps for the next loans. So a subscriber reads a sample in place for as
// long as it likes, the publisher never reuses a chunk someone reads, and a
// dead subscriber's holds are cleared by clearing its bit everywhere.
//
// A chunk carries a sample for as long as a ring entry names the two: a
// subscriber holds a chunk by setting its bit, then checks that the entry
// still names it. A sample's size and stamp lie beside its ring entry
// (SampleInfo), not in its chunk. So a publish writes the payload, the
// info and the ring entry, and (below a page: see Writer::describe)
// nothing in the chunk's header, which subscribers holding it write
// (docs/performance.md: "Layout 12: a publish writes no header per
// sample", against layout 9's sequence, size and stamp in each header).

static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "shared memory needs lock-free 64-bit atomics");
static_assert(std::atomic<std::uint32_t>::is_always_lock_free, "shared memory needs lock-free 32-bit atomics");

// A participant of a domain: its slot in the registry and that slot's
// generation, so a later participant in the same slot is another one.
// Zero means nobody.
using ParticipantId = std::uint64_t;
// A slot (a topic's subscriber's, a service's client's) whose dead owner is
// being cleared names the participant clearing it, with this bit: one that
// dies clearing it leaves it to the next, which clears it again (each step
// can be done twice). Ids count up from 1 << kSlotBits (registry.hpp): they
// never reach it.
inline constexpr ParticipantId kReclaimingBit = 1ull << 63;

// Room for a message type's description (prime::schema_of), for tools.
inline constexpr std::size_t kSchemaCapacity = 2048;
// Subscriber slots a topic may offer; one more is kept for tools that observe.
inline constexpr std::size_t kMaxSubscribers = 61;
inline constexpr std::size_t kSlots = kMaxSubscribers + 1;
inline constexpr std::uint64_t kPublisherBit = 1ull << 63;
static_assert(kSlots <= 63, "a chunk's holders word has one bit per slot, plus the publisher's");
inline constexpr std::uint32_t kNoChunk = (1u << 24) - 1;
inline constexpr std::uint64_t kNoCursor = ~0ull;      // a subscriber slot not (yet) reading
inline constexpr std::size_t kPayloadAlignment = 64;
// The infos and the chunks each start a page: a reader walking the ring or
// the infos does not have the hardware prefetcher pull in the lines after
// them, which the publisher writes (docs/performance.md: "Infos and chunks
// each start a page").
inline constexpr std::size_t kPageAlignment = 4096;
// A chunk's header has a 128-byte block to itself, and its payload starts
// at the next: a reader of the payload alone (a batch of views) then does
// not have the adjacent-line prefetcher, which fetches lines in 128-byte
// pairs, pull in the header others write (docs/performance.md: "A chunk's
// header gets a 128-byte block of its own"). Chunks are whole blocks, so
// no payload shares one with the next chunk's header either.
inline constexpr std::size_t kChunkAlignment = 2 * kPayloadAlignment;
inline constexpr std::size_t kPayloadOffset = kChunkAlignment;  // from a chunk's start
inline constexpr std::uint64_t kPublisherSleeper = 1;  // the space doorbell's one sleeper

// A ring entry: which chunk carries which sequence, in one word, so that a
// busy subscriber polls one cache line and learns both that its next sample
// is out and where it is. The sequence is kept modulo 2^40 (compared with
// wrap-around): a reader would take a later sample for its own only after
// falling behind by a multiple of 2^40 samples (hours, at any rate a
// machine reaches) to within a ring's length.
struct RingEntry {
  static constexpr int kChunkBits = 24;
  static constexpr int kSeqBits = 40;
  static constexpr std::uint64_t kSeqMask = (1ull << kSeqBits) - 1;

  static constexpr std::uint64_t pack(std::uint64_t seq, std::uint32_t chunk) noexcept {
    return ((seq & kSeqMask) << kChunkBits) | chunk;
  }
  static constexpr std::uint32_t chunk(std::uint64_t entry) noexcept {
    return static_cast<std::uint32_t>(entry & ((1u << kChunkBits) - 1));
  }
  // How far the entry's sequence is ahead of `seq`: 0 when it carries it,
  // negative while it still holds an older one, positive once overwritten.
  static constexpr std::int64_t ahead(std::uint64_t entry, std::uint64_t seq) noexcept {
    const auto d = ((entry >> kChunkBits) - seq) & kSeqMask;
    constexpr auto half = 1ull << (kSeqBits - 1);
    return d >= half ? static_cast<std::int64_t>(d) - static_cast<std::int64_t>(1ull << kSeqBits)
                     : static_cast<std::int64_t>(d);
  }
};
static_assert(RingEntry::kChunkBits + RingEntry::kSeqBits == 64);

// A published sample's size and stamp, beside its ring entry (info[i] goes
// with ring[i]), written before the entry: four samples to a line, which a
// reader taking several reads once. The publisher rewrites them a lap on,
// while a reader may be reading them (it may have been passed over, or hold
// the chunk past its place in the ring), so they are read as a seqlock is:
// `word` carries the sequence's low bits beside the size and is stored
// before the stamp; a reader loads it, the stamp, and it again, and takes
// the two only if the word is the same both times and names its sequence.
// A reader whose check of the ring entry follows (a hold) then has them
// from its own lap or the next, which the sequence's bits tell apart (the
// ring is shorter than 2^24). Stored with release and loaded with acquire:
// a value the publisher wrote after passing the reader over
// (SubscriberSlot::lagging) comes with that news.
struct SampleInfo {
  static constexpr int kSizeBits = 40;  // a message is smaller than 2^40 bytes (see damage)
  static constexpr std::uint64_t kSizeMask = (1ull << kSizeBits) - 1;

  std::atomic<std::uint64_t> word{0};  // (sequence mod 2^24) << 40 | size
  std::atomic<std::int64_t> stamp{0};  // steady_clock ticks (CLOCK_MONOTONIC: one clock for every process)

  static constexpr std::uint64_t pack(std::uint64_t seq, std::uint64_t size) noexcept {
    return (seq << kSizeBits) | (size & kSizeMask);
  }
  static constexpr std::uint64_t size_of(std::uint64_t word) noexcept { return word & kSizeMask; }
  static constexpr bool names(std::uint64_t word, std::uint64_t seq) noexcept {
    return (word >> kSizeBits) == ((seq << kSizeBits) >> kSizeBits);
  }
};
static_assert(sizeof(SampleInfo) == 16);

// A chunk's header: who holds it.
struct alignas(kPayloadAlignment) ChunkHeader {
  std::atomic<std::uint64_t> holders{0};
};
static_assert(sizeof(ChunkHeader) <= kPayloadOffset, "a chunk's header lies before its payload");

inline constexpr std::uint32_t kWaitedFor = 0;  // SubscriberSlot::lagging
inline constexpr std::uint32_t kPinning = 1;
inline constexpr std::uint32_t kPassedOver = 2;

struct alignas(64) SubscriberSlot {
  std::atomic<ParticipantId> owner{0};
  std::atomic<std::uint64_t> cursor{kNoCursor};  // the next sequence it takes
  // On a `block` topic: kWaitedFor, or set when the publisher stopped
  // waiting for this subscriber (it read nothing for block_timeout): it is
  // then passed over like a drop_oldest reader, until it has caught up and
  // clears this. kPinning while the publisher holds chunks for it (see
  // BackPressure::give_up_on_laggards), then kPassedOver.
  std::atomic<std::uint32_t> lagging{0};
  // The end of the newest batch its cursor keeps (Cursor::take_batch): the
  // span from its cursor to here is what a publisher that stops waiting
  // for it holds for it.
  std::atomic<std::uint64_t> kept_end{0};
};
static_assert(sizeof(SubscriberSlot) == 64, "each subscriber's cursor on a line of its own");

struct TopicHeader {
  static constexpr const char* kKind = "topic";  // in its segment's name (and TypedSegment's errors)
  static constexpr std::uint64_t kMagic = kTopicMagic;
  static constexpr std::uint32_t kLayout = kTopicLayout;

  std::atomic<std::uint64_t> magic{0};  // kTopicMagic once the creator has set everything below
  std::uint32_t layout = kTopicLayout;
  std::uint32_t overflow = 0;
  Fingerprint type{};
  std::uint64_t capacity = 0;
  std::uint64_t chunk_count = 0;
  std::uint64_t max_message_size = 0;
  std::uint64_t chunk_stride = 0;
  std::uint64_t max_subscribers = 0;
  std::uint64_t max_held = 0;
  std::uint64_t ring_offset = 0;
  std::uint64_t info_offset = 0;
  std::uint64_t chunks_offset = 0;
  char schema[kSchemaCapacity]{};  // the message type's description; "?<size>" when it has none

  alignas(64) std::atomic<ParticipantId> publisher{0};
  std::atomic<std::int64_t> block_timeout_ns{0};  // the current publisher's
  // Set while the publisher fences its head stores lightly (PublishFence::
  // light, asymmetric_fence.hpp): a subscriber about to sleep must then
  // fence heavily, or ask for full fences.
  std::atomic<std::uint32_t> light_publisher{0};
  // Subscriber slots' bits: those that asked the publisher to fence every
  // head store fully (refused membarrier, or sleeping too often for it).
  std::atomic<std::uint64_t> full_fences_wanted{0};
  alignas(64) std::atomic<std::uint64_t> head{0};  // sequences published so far
  Doorbell data;   // rung when a sample is published; sleepers are subscriber slots' bits
  Doorbell space;  // rung when a subscriber acknowledges `space_wanted` (a `block` publisher waits; it checks the slowest)
  alignas(64) std::atomic<std::uint64_t> space_wanted{~0ull};
  SubscriberSlot subscribers[kSlots];
};
static_assert(offsetof(TopicHeader, publisher) % 64 == 0 && offsetof(TopicHeader, head) % 64 == 0 &&
                  offsetof(TopicHeader, space_wanted) % 64 == 0 && offsetof(TopicHeader, subscribers) % 64 == 0,
              "the lines publisher and subscribers write do not share with each other");

inline constexpr std::size_t round_up(std::size_t n, std::size_t to) { return (n + to - 1) / to * to; }

// Bounds on what a segment's geometry may multiply: a message, and a
// segment, far larger than any /dev/shm, yet small enough that no sum or
// product of them wraps around.
inline constexpr std::uint64_t kMaxMessageSize = 1ull << 40;  // exclusive
inline constexpr std::uint64_t kMaxSegmentBytes = 1ull << 46;

// Copies a type's description where it fits; one that does not is recorded
// as its size only (tools then show bytes).
template <std::size_t N>
void write_schema(char (&to)[N], const std::string& schema, std::size_t size) {
  if (schema.size() < N) {
    std::memcpy(to, schema.data(), schema.size());
    to[schema.size()] = '\0';
  } else {
    std::snprintf(to, N, "?%zu", size);
  }
}

// Where the parts of a topic's segment lie, from its QoS and message size.
// A process that maps a topic reads these four from its header once, checks
// them (damage) and goes by that copy from then on, never by the header: a
// later write there (a foreign or broken program) then sends no access out
// of the segment.
struct TopicGeometry {
  std::size_t capacity;
  std::size_t max_message_size;
  std::size_t max_subscribers;
  std::size_t max_held;

  // What `h` records, read once.
  [[nodiscard]] static TopicGeometry of(const TopicHeader& h) noexcept {
    return {h.capacity, h.max_message_size, h.max_subscribers, h.max_held};
  }

  // The ring's chunks; every subscriber's allowance of held samples that the
  // ring no longer names; one that an observing tool may hold; one the
  // publisher loans.
  [[nodiscard]] constexpr std::size_t chunk_count() const { return capacity + max_subscribers * max_held + 2; }
  [[nodiscard]] constexpr std::size_t ring_offset() const { return round_up(sizeof(TopicHeader), kPayloadAlignment); }
  [[nodiscard]] constexpr std::size_t info_offset() const {
    return round_up(ring_offset() + capacity * sizeof(std::uint64_t), kPageAlignment);
  }
  [[nodiscard]] constexpr std::size_t chunks_offset() const {
    return round_up(info_offset() + capacity * sizeof(SampleInfo), kPageAlignment);
  }
  [[nodiscard]] constexpr std::size_t chunk_stride() const {
    return round_up(kPayloadOffset + max_message_size, kChunkAlignment);
  }
  [[nodiscard]] constexpr std::size_t bytes() const { return chunks_offset() + chunk_count() * chunk_stride(); }

  // Which of its values is out of bounds, when one is; empty when none is.
  // Each is bounded before any is multiplied, so no size computed from
  // them wraps around: both when a topic is made (QoS) and when a segment
  // is mapped (whatever its header says).
  [[nodiscard]] std::string out_of_bounds() const {
    if (capacity == 0) return "a capacity of 0";
    if (max_subscribers == 0 || max_subscribers > kMaxSubscribers)
      return std::to_string(max_subscribers) + " subscriber slots, not in [1, " + std::to_string(kMaxSubscribers) + "]";
    if (max_held == 0) return "max_held 0";
    if (capacity >= kNoChunk || max_held >= kNoChunk || max_message_size >= kMaxMessageSize)
      return "a capacity of " + std::to_string(capacity) + ", messages of " + std::to_string(max_message_size) +
             " bytes and max_held " + std::to_string(max_held) + " (each below 2^24, messages below 2^40 bytes)";
    if (chunk_count() >= kNoChunk) return std::to_string(chunk_count()) + " chunks, more than a ring entry can name";
    if (chunk_count() > kMaxSegmentBytes / chunk_stride())
      return std::to_string(chunk_count()) + " chunks of " + std::to_string(chunk_stride()) +
             " bytes, more than a segment may be (2^46 bytes)";
    return {};
  }
};

// What is wrong with geometry `g`, read from header `h`, against the segment
// `h` heads, which is `size` bytes long; empty when nothing is. A process
// addresses the segment by `g`: one written by a foreign or broken program
// must not send it out of the segment (or divide by zero), nor have it
// size its own state past what the segment holds. What else `h` records of
// its layout must follow from `g`.
inline std::string damage(const TopicHeader& h, const TopicGeometry& g, std::size_t size) {
  if (auto what = g.out_of_bounds(); !what.empty()) return what;
  if (h.chunk_count != g.chunk_count() || h.chunk_stride != g.chunk_stride() || h.ring_offset != g.ring_offset() ||
      h.info_offset != g.info_offset() || h.chunks_offset != g.chunks_offset())
    return "a layout that does not follow from its capacity, message size and subscriber slots";
  if (g.bytes() > size)
    return std::to_string(g.bytes()) + " bytes of layout in a segment of " + std::to_string(size);
  if (h.overflow > 1) return "overflow " + std::to_string(h.overflow) + ", neither drop_oldest (0) nor block (1)";
  return {};
}

}  // namespace prime::shm::detail
