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
                                     std::uint64_t first_sequence = 0);

  // The topic `name` as it is, whatever its type, or null when it does not
  // exist (or is not set up yet): for inspection. Throws Failure
  // (Errc::damaged) when its header is damaged.
  static std::shared_ptr<Topic> inspect(std::shared_ptr<Registry> registry, const std::string& name);

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
  [[nodiscard]] TopicQos qos() const noexcept;

  // Clears what the dead owner of subscriber slot `i` held. Safe to race:
  // one caller wins the slot. Returns whether it cleared anything.
  bool reclaim_subscriber(std::size_t i) const;
  // Takes subscriber slot `i`'s bit from every chunk.
  void release_subscriber_holds(std::size_t i) const;
  // Reclaims every subscriber slot whose participant is gone; returns how many.
  std::size_t reclaim_dead_subscribers() const;

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

  Topic(std::shared_ptr<Registry> registry, std::string name, Mapped mapped);

  std::shared_ptr<Registry> registry_;  // the participant lives as long as its topics
  std::string name_;
  Mapped mapped_;
  TopicHeader* header_;  // mapped_'s, at hand
  Overflow overflow_;
  Places places_;
};

}  // namespace prime::shm::detail
