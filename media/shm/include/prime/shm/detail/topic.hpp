#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <thread>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/shm/detail/futex.hpp"
#include "prime/shm/detail/process.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/qos.hpp"

namespace prime::shm::detail {

// The layout of one topic's segment. Everything in it is plain data or
// lock-free atomics, addressed by index from the segment's start (no
// pointers), so each process may map it anywhere.
//
//   TopicHeader | ring: capacity × chunk index | chunks: chunk_count × (ChunkHeader + payload)
//
// Samples live in chunks. The ring names the chunks of the last `capacity`
// sequences; a chunk is free when no one holds it. Who holds a chunk is one
// word of bits: one per subscriber slot, one for the ring and one for the
// publisher's loan. So a subscriber reads a sample in place for as long as
// it likes, the publisher never reuses a chunk someone reads, and a dead
// subscriber's holds are cleared by clearing its bit everywhere.

inline constexpr std::uint64_t kTopicMagic = 0x5052494d45534d31ull;  // "PRIMESM1"
inline constexpr std::uint32_t kLayoutVersion = 2;
inline constexpr std::size_t kMaxSubscribers = 62;
inline constexpr std::uint64_t kRingBit = 1ull << 63;
inline constexpr std::uint64_t kLoanBit = 1ull << 62;
inline constexpr std::uint64_t kNotPublished = ~0ull;  // a chunk's sequence when it carries none
inline constexpr std::uint32_t kNoChunk = (1u << 24) - 1;

// A ring entry: which chunk carries which sequence, in one word, so that a
// busy subscriber polls one cache line and learns both that its next sample
// is out and where it is. The sequence is kept modulo 2^40 (compared with
// wrap-around); the full one is in the chunk, which a subscriber checks.
struct RingEntry {
  static constexpr int kChunkBits = 24;
  static constexpr std::uint64_t kSeqMask = (1ull << 40) - 1;

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
    return d >= (1ull << 39) ? static_cast<std::int64_t>(d) - static_cast<std::int64_t>(1ull << 40)
                             : static_cast<std::int64_t>(d);
  }
};
inline constexpr std::uint64_t kNoCursor = ~0ull;        // a subscriber slot not (yet) reading
inline constexpr ProcessId kReclaiming = ~0ull;          // a slot whose dead owner is being cleared
inline constexpr std::size_t kPayloadAlignment = 64;

struct alignas(64) ChunkHeader {
  std::atomic<std::uint64_t> holders{0};
  std::atomic<std::uint64_t> seq{kNotPublished};
  std::uint64_t size = 0;   // bytes of payload in use
  std::int64_t stamp = 0;   // steady_clock ticks (CLOCK_MONOTONIC: one clock for every process)
};
static_assert(sizeof(ChunkHeader) == kPayloadAlignment);

struct alignas(64) SubscriberSlot {
  std::atomic<ProcessId> owner{0};
  std::atomic<std::uint64_t> cursor{kNoCursor};  // the next sequence it takes
};

struct TopicHeader {
  std::atomic<std::uint64_t> magic{0};  // kTopicMagic once the creator has set everything below
  std::uint32_t layout = kLayoutVersion;
  std::uint32_t overflow = 0;
  Fingerprint type{};
  std::uint64_t capacity = 0;
  std::uint64_t chunk_count = 0;
  std::uint64_t max_message_size = 0;
  std::uint64_t chunk_stride = 0;
  std::uint64_t max_subscribers = 0;
  std::uint64_t max_held = 0;
  std::int64_t block_timeout_ns = 0;
  std::uint64_t ring_offset = 0;
  std::uint64_t chunks_offset = 0;
  ProcessId creator = 0;

  alignas(64) std::atomic<ProcessId> publisher{0};
  alignas(64) std::atomic<std::uint64_t> head{0};  // sequences published so far
  Doorbell data;   // rung when a sample is published
  Doorbell space;  // rung when the slowest subscriber reaches `space_wanted` (a `block` publisher waits)
  alignas(64) std::atomic<std::uint64_t> space_wanted{~0ull};
  SubscriberSlot subscribers[kMaxSubscribers];
};

inline std::size_t round_up(std::size_t n, std::size_t to) { return (n + to - 1) / to * to; }

// A topic segment mapped into this process, shared by its publisher and
// subscriptions here. Thread-safe (all state is atomic or fixed at creation).
class Topic {
 public:
  // Opens `name` in `domain`, creating it with `qos` when it does not exist.
  // Throws Failure when it exists with another type (Errc::type_mismatch).
  static std::shared_ptr<Topic> open(const std::string& domain, const std::string& name, const Fingerprint& type,
                                     const TopicQos& qos, unsigned permissions) {
    const auto segment_name = detail::segment_name(domain, "topic", name);
    validate(name, type, qos);
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds{2};
    while (true) {
      if (auto existing = Segment::open(segment_name)) {
        if (auto topic = adopt(name, std::move(*existing), type)) return topic;
      } else if (auto created = Segment::create(segment_name, layout_size(type, qos), permissions)) {
        return initialise(name, std::move(*created), type, qos);
      }
      // Another process is creating it right now: wait for its header, but
      // not forever (it may have died half-way).
      if (std::chrono::steady_clock::now() > deadline) {
        Segment::remove(segment_name);  // a creator that died before finishing left it
        deadline = std::chrono::steady_clock::now() + std::chrono::seconds{2};
      }
      std::this_thread::sleep_for(std::chrono::milliseconds{1});
    }
  }

  // The topic `name` as it is, whatever its type, or null when it does not
  // exist (or is still being created): for the registry's inspections.
  static std::shared_ptr<Topic> inspect(const std::string& domain, const std::string& name) {
    auto segment = Segment::open(detail::segment_name(domain, "topic", name));
    if (!segment || segment->size() < sizeof(TopicHeader)) return nullptr;
    auto* header = std::launder(reinterpret_cast<TopicHeader*>(segment->data()));
    if (header->magic.load(std::memory_order_acquire) != kTopicMagic || header->layout != kLayoutVersion) return nullptr;
    return finish(name, std::move(*segment));
  }

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] const Segment& segment() const noexcept { return segment_; }
  [[nodiscard]] TopicHeader& header() const noexcept { return *header_; }
  [[nodiscard]] std::atomic<std::uint64_t>& ring(std::uint64_t seq) const noexcept {
    return ring_[seq % header_->capacity];
  }
  [[nodiscard]] ChunkHeader& chunk(std::uint32_t i) const noexcept {
    return *std::launder(reinterpret_cast<ChunkHeader*>(chunks_ + i * header_->chunk_stride));
  }
  [[nodiscard]] std::byte* payload(std::uint32_t i) const noexcept {
    return chunks_ + i * header_->chunk_stride + sizeof(ChunkHeader);
  }
  [[nodiscard]] TopicQos qos() const noexcept {
    const auto& h = *header_;
    return {.capacity = h.capacity,
            .max_message_size = h.max_message_size,
            .overflow = static_cast<Overflow>(h.overflow),
            .block_timeout = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::nanoseconds{h.block_timeout_ns}),
            .max_subscribers = h.max_subscribers,
            .max_held = h.max_held};
  }

  // Clears what the dead owner of subscriber slot `i` held. Safe to race:
  // one caller wins the slot. Returns whether it cleared anything.
  bool reclaim_subscriber(std::size_t i) const {
    auto& slot = header_->subscribers[i];
    auto owner = slot.owner.load();
    if (owner == 0 || owner == kReclaiming || alive(owner)) return false;
    if (!slot.owner.compare_exchange_strong(owner, kReclaiming)) return false;
    release_subscriber_holds(i);
    slot.cursor.store(kNoCursor);
    slot.owner.store(0);
    header_->space.ring();
    return true;
  }

  void release_subscriber_holds(std::size_t i) const {
    const auto bit = 1ull << i;
    for (std::uint32_t c = 0; c < header_->chunk_count; ++c) chunk(c).holders.fetch_and(~bit);
  }

  // Reclaims every subscriber slot whose process is gone; returns how many.
  std::size_t reclaim_dead_subscribers() const {
    std::size_t n = 0;
    for (std::size_t i = 0; i < header_->max_subscribers; ++i) n += reclaim_subscriber(i) ? 1 : 0;
    return n;
  }

 private:
  Topic(std::string name, Segment segment)
      : name_{std::move(name)},
        segment_{std::move(segment)},
        header_{std::launder(reinterpret_cast<TopicHeader*>(segment_.data()))} {}

  static void validate(const std::string& name, const Fingerprint& type, const TopicQos& qos) {
    auto refuse = [&](const std::string& why) { throw Failure{{Errc::limit_exceeded, "topic '" + name + "': " + why}}; };
    if (qos.capacity == 0) refuse("capacity must be at least 1");
    if (qos.max_subscribers == 0 || qos.max_subscribers > kMaxSubscribers)
      refuse("max_subscribers must be in [1, " + std::to_string(kMaxSubscribers) + "], not " +
             std::to_string(qos.max_subscribers));
    if (chunk_count(qos) >= kNoChunk) refuse("capacity and subscribers need more than 2^24 slots");
    if (qos.max_message_size != 0 && qos.max_message_size < type.size)
      refuse("max_message_size " + std::to_string(qos.max_message_size) + " is smaller than " + type.describe());
  }

  static std::size_t message_size(const Fingerprint& type, const TopicQos& qos) {
    return qos.max_message_size != 0 ? qos.max_message_size : type.size;
  }
  static std::size_t held(const TopicQos& qos) { return qos.max_held != 0 ? qos.max_held : qos.capacity; }
  static std::size_t chunk_count(const TopicQos& qos) {
    // The ring's chunks, every subscriber's allowance, and one the publisher loans.
    return qos.capacity + qos.max_subscribers * held(qos) + 1;
  }
  static std::size_t layout_size(const Fingerprint& type, const TopicQos& qos) {
    const auto ring = round_up(sizeof(TopicHeader), kPayloadAlignment);
    const auto chunks = round_up(ring + qos.capacity * sizeof(std::uint64_t), kPayloadAlignment);
    const auto stride = round_up(sizeof(ChunkHeader) + message_size(type, qos), kPayloadAlignment);
    return chunks + chunk_count(qos) * stride;
  }

  static std::shared_ptr<Topic> initialise(const std::string& name, Segment segment, const Fingerprint& type,
                                           const TopicQos& qos) {
    auto* header = ::new (segment.data()) TopicHeader{};
    header->overflow = static_cast<std::uint32_t>(qos.overflow);
    header->type = type;
    header->capacity = qos.capacity;
    header->chunk_count = chunk_count(qos);
    header->max_message_size = message_size(type, qos);
    header->chunk_stride = round_up(sizeof(ChunkHeader) + header->max_message_size, kPayloadAlignment);
    header->max_subscribers = qos.max_subscribers;
    header->max_held = held(qos);
    header->block_timeout_ns = std::chrono::nanoseconds{qos.block_timeout}.count();
    header->ring_offset = round_up(sizeof(TopicHeader), kPayloadAlignment);
    header->chunks_offset = round_up(header->ring_offset + qos.capacity * sizeof(std::uint64_t), kPayloadAlignment);
    header->creator = this_process();
    auto* ring = reinterpret_cast<std::atomic<std::uint64_t>*>(segment.data() + header->ring_offset);
    for (std::size_t i = 0; i < qos.capacity; ++i)  // each entry "one lap behind": nothing published yet
      ::new (ring + i) std::atomic<std::uint64_t>{RingEntry::pack(i - qos.capacity, kNoChunk)};
    for (std::size_t i = 0; i < header->chunk_count; ++i)
      ::new (segment.data() + header->chunks_offset + i * header->chunk_stride) ChunkHeader{};
    header->magic.store(kTopicMagic, std::memory_order_release);
    return finish(name, std::move(segment));
  }

  // The topic an earlier opener created, once its header is complete; or
  // nothing while it is still being written.
  static std::shared_ptr<Topic> adopt(const std::string& name, Segment segment, const Fingerprint& type) {
    if (segment.size() < sizeof(TopicHeader)) return nullptr;
    auto* header = std::launder(reinterpret_cast<TopicHeader*>(segment.data()));
    if (header->magic.load(std::memory_order_acquire) != kTopicMagic) return nullptr;
    if (header->layout != kLayoutVersion)
      throw Failure{{Errc::type_mismatch, "topic '" + name + "': made by another version of Prime (layout " +
                                              std::to_string(header->layout) + ", this one reads " +
                                              std::to_string(kLayoutVersion) + ")"}};
    if (!(header->type == type))
      throw Failure{{Errc::type_mismatch, "topic '" + name + "' carries " + header->type.describe() +
                                              ", not " + type.describe()}};
    return finish(name, std::move(segment));
  }

  static std::shared_ptr<Topic> finish(const std::string& name, Segment segment) {
    auto topic = std::shared_ptr<Topic>{new Topic{name, std::move(segment)}};
    auto* base = topic->segment_.data();
    topic->ring_ = reinterpret_cast<std::atomic<std::uint64_t>*>(base + topic->header_->ring_offset);
    topic->chunks_ = base + topic->header_->chunks_offset;
    return topic;
  }

  std::string name_;
  Segment segment_;
  TopicHeader* header_;
  std::atomic<std::uint64_t>* ring_ = nullptr;
  std::byte* chunks_ = nullptr;
};

}  // namespace prime::shm::detail
