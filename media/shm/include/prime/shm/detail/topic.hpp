#pragma once

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <string>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/registry.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/detail/typed_segment.hpp"
#include "prime/shm/qos.hpp"

namespace prime::shm::detail {

// Where a topic's ring, infos and chunks lie in this process: addresses and
// sizes read once from its header, when it was checked, so no later write
// there sends an access out of the segment. A hot loop takes a copy, which
// stays in registers: read through the topic, every atomic stored in the
// loop would have the compiler load them from memory again.
struct Places {
  std::atomic<std::uint64_t>* rings;
  SampleInfo* infos;
  std::byte* chunks;
  std::uint64_t capacity;
  std::uint64_t mask;    // capacity - 1 where that is a power of two, else 0
  std::uint64_t stride;  // from one chunk to the next
  std::uint64_t chunk_count;
  std::uint64_t max_size;  // of a payload

  // Whether ring entry `entry` names one of the topic's chunks. One naming
  // a chunk past them (written by a foreign or broken program) is taken for
  // an entry overwritten: its sample is lost, not read out of the segment.
  [[nodiscard]] bool names_chunk(std::uint64_t entry) const noexcept { return RingEntry::chunk(entry) < chunk_count; }
  // A sample's size as shared memory records it, within its payload's room.
  [[nodiscard]] std::size_t size(std::uint64_t recorded) const noexcept {
    return static_cast<std::size_t>(std::min(recorded, max_size));
  }

  // Where `seq` lands in the ring: a mask where the capacity is a power of
  // two (a division costs more than the rest of a poll), else the remainder.
  [[nodiscard]] std::uint64_t ring_index(std::uint64_t seq) const noexcept {
    return mask != 0 ? seq & mask : seq % capacity;
  }
  [[nodiscard]] std::atomic<std::uint64_t>& ring(std::uint64_t seq) const noexcept { return rings[ring_index(seq)]; }
  // The size and stamp beside ring(seq) (SampleInfo).
  [[nodiscard]] SampleInfo& info(std::uint64_t seq) const noexcept { return infos[ring_index(seq)]; }
  [[nodiscard]] ChunkHeader& chunk(std::uint32_t i) const noexcept {
    return *std::launder(reinterpret_cast<ChunkHeader*>(chunks + i * stride));
  }
  [[nodiscard]] std::byte* payload(std::uint32_t i) const noexcept { return chunks + i * stride + kPayloadOffset; }
};

// A topic's segment mapped into this process, shared by its publisher and
// subscriptions here. Thread-safe (all shared state is atomic or fixed at
// creation).
class Topic {
 public:
  // Opens `name`, creating it with `qos` (complete: no zero left for a
  // default) when it does not exist. Throws Failure when it exists with
  // another type (Errc::type_mismatch) or the memory cannot be reserved
  // (Errc::no_space). Comparing QoS is the caller's. A new topic's first
  // sample is `first_sequence` (tests start near the ring's 2^40 wrap).
  static std::shared_ptr<Topic> open(std::shared_ptr<Registry> registry, const std::string& name,
                                     const Fingerprint& type, const TopicQos& qos, const std::string& schema = {},
                                     std::uint64_t first_sequence = 0) {
    const TopicGeometry geometry{qos.capacity, qos.max_message_size, qos.max_subscribers, qos.max_held};
    registry->add(EndpointKind::topic, name);
    auto mapped = Mapped::open(*registry, name, geometry.bytes(),
                               [&](std::byte* data) { set_up(data, type, qos, geometry, schema, first_sequence); });
    auto topic = std::shared_ptr<Topic>{new Topic{std::move(registry), name, std::move(mapped)}};
    if (!(topic->header().type == type))
      throw Failure{{Errc::type_mismatch, Mapped::what(name) + " carries " + topic->header().type.describe() + ", not " +
                                              type.describe()}};
    return topic;
  }

  // The topic `name` as it is, whatever its type, or null when it does not
  // exist (or is not set up yet): for inspection. Throws Failure
  // (Errc::damaged) when its header is damaged.
  static std::shared_ptr<Topic> inspect(std::shared_ptr<Registry> registry, const std::string& name) {
    auto mapped = Mapped::open_existing(*registry, name);
    if (!mapped) return nullptr;
    return std::shared_ptr<Topic>{new Topic{std::move(registry), name, std::move(*mapped)}};
  }

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] const Segment& segment() const noexcept { return mapped_.segment(); }
  [[nodiscard]] Registry& registry() const noexcept { return *registry_; }
  // Its shared state. What it fixed at creation is read through geometry()
  // and overflow(), never here: see TopicGeometry.
  [[nodiscard]] TopicHeader& header() const noexcept { return *header_; }
  [[nodiscard]] const TopicGeometry& geometry() const noexcept { return mapped_.geometry(); }
  [[nodiscard]] Overflow overflow() const noexcept { return overflow_; }
  [[nodiscard]] const Places& places() const noexcept { return places_; }
  [[nodiscard]] std::atomic<std::uint64_t>& ring(std::uint64_t seq) const noexcept { return places_.ring(seq); }
  [[nodiscard]] std::uint64_t ring_index(std::uint64_t seq) const noexcept { return places_.ring_index(seq); }
  [[nodiscard]] SampleInfo& info(std::uint64_t seq) const noexcept { return places_.info(seq); }
  [[nodiscard]] ChunkHeader& chunk(std::uint32_t i) const noexcept { return places_.chunk(i); }
  [[nodiscard]] std::byte* payload(std::uint32_t i) const noexcept { return places_.payload(i); }
  [[nodiscard]] TopicQos qos() const noexcept {
    const auto& h = *header_;
    return {.capacity = geometry().capacity,
            .max_message_size = geometry().max_message_size,
            .overflow = overflow_,
            .block_timeout = std::chrono::duration_cast<std::chrono::milliseconds>(
                std::chrono::nanoseconds{h.block_timeout_ns.load(std::memory_order_relaxed)}),
            .publish_fence = h.light_publisher.load(std::memory_order_relaxed) != 0 ? PublishFence::light : PublishFence::full,
            .max_subscribers = geometry().max_subscribers,
            .max_held = geometry().max_held};
  }

  // Clears what the dead owner of subscriber slot `i` held. Safe to race:
  // one caller wins the slot. Returns whether it cleared anything.
  bool reclaim_subscriber(std::size_t i) const {
    auto& slot = header_->subscribers[i];
    if (!registry_->take_to_clear(slot.owner)) return false;
    release_subscriber_holds(i);
    slot.cursor.store(kNoCursor);
    slot.lagging.store(0);
    slot.kept_end.store(0);
    header_->data.forget(1ull << i);  // it may have died asleep
    header_->full_fences_wanted.fetch_and(~(1ull << i));
    slot.owner.store(0);
    wake_publisher();
    return true;
  }

  void release_subscriber_holds(std::size_t i) const {
    const auto bit = 1ull << i;
    for (std::uint32_t c = 0; c < places_.chunk_count; ++c) chunk(c).holders.fetch_and(~bit);
  }

  // Reclaims every subscriber slot whose participant is gone; returns how many.
  std::size_t reclaim_dead_subscribers() const {
    std::size_t n = 0;
    for (std::size_t i = 0; i < kSlots; ++i) n += reclaim_subscriber(i) ? 1 : 0;
    return n;
  }

  // Wakes a `block` publisher waiting for room. When a publisher that slept
  // died, its flag would make every later ring a system call: a ring that
  // wakes nobody checks whether the publisher lives, and forgets it if not.
  void wake_publisher() const {
    if (header_->space.ring() != 0) return;
    const auto publisher = header_->publisher.load();
    if (!registry_->alive(publisher)) {
      header_->space_wanted.store(~0ull);
      header_->space.forget(kPublisherSleeper);
    }
  }

 private:
  using Mapped = TypedSegment<TopicHeader, TopicGeometry>;

  Topic(std::shared_ptr<Registry> registry, std::string name, Mapped mapped)
      : registry_{std::move(registry)},
        name_{std::move(name)},
        mapped_{std::move(mapped)},
        header_{&mapped_.header()},
        // Read once more after the check: whatever it reads now, one of the two.
        overflow_{header_->overflow == static_cast<std::uint32_t>(Overflow::block) ? Overflow::block : Overflow::drop_oldest},
        places_{.rings = reinterpret_cast<std::atomic<std::uint64_t>*>(mapped_.data() + geometry().ring_offset()),
                .infos = std::launder(reinterpret_cast<SampleInfo*>(mapped_.data() + geometry().info_offset())),
                .chunks = mapped_.data() + geometry().chunks_offset(),
                .capacity = geometry().capacity,
                .mask = std::has_single_bit(geometry().capacity) ? geometry().capacity - 1 : 0,
                .stride = geometry().chunk_stride(),
                .chunk_count = geometry().chunk_count(),
                .max_size = geometry().max_message_size} {}

  static void set_up(std::byte* data, const Fingerprint& type, const TopicQos& qos, const TopicGeometry& geometry,
                     const std::string& schema, std::uint64_t first) {
    auto* header = ::new (data) TopicHeader{};
    write_schema(header->schema, schema, type.size);
    header->overflow = static_cast<std::uint32_t>(qos.overflow);
    header->type = type;
    header->capacity = qos.capacity;
    header->chunk_count = geometry.chunk_count();
    header->max_message_size = qos.max_message_size;
    header->chunk_stride = geometry.chunk_stride();
    header->max_subscribers = qos.max_subscribers;
    header->max_held = qos.max_held;
    header->block_timeout_ns.store(saturating_cast<std::chrono::nanoseconds>(qos.block_timeout).count());
    header->ring_offset = geometry.ring_offset();
    header->info_offset = geometry.info_offset();
    header->chunks_offset = geometry.chunks_offset();
    header->head.store(first);
    // Each entry one lap behind the first sequence that will land in it: nothing published yet.
    auto* ring = reinterpret_cast<std::atomic<std::uint64_t>*>(data + header->ring_offset);
    const auto cap = qos.capacity;
    for (std::size_t k = 0; k < cap; ++k) {
      const auto lands = first + (k + cap - first % cap) % cap;
      ::new (ring + k) std::atomic<std::uint64_t>{RingEntry::pack(lands - cap, kNoChunk)};
      ::new (data + header->info_offset + k * sizeof(SampleInfo)) SampleInfo{};
    }
    for (std::size_t i = 0; i < header->chunk_count; ++i)
      ::new (data + header->chunks_offset + i * header->chunk_stride) ChunkHeader{};
    header->magic.store(kTopicMagic, std::memory_order_release);
  }

  std::shared_ptr<Registry> registry_;  // the participant lives as long as its topics
  std::string name_;
  Mapped mapped_;
  TopicHeader* header_;  // mapped_'s, at hand
  Overflow overflow_;
  Places places_;
};

}  // namespace prime::shm::detail
