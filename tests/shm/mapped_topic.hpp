#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/segment.hpp"
#include "support/within.hpp"

namespace prime::test {

// A topic's shared memory, mapped by the test to look at what the processes
// using it do (who sleeps, where cursors stand): observable conditions to
// wait for, instead of sleeping and hoping.
class MappedTopic {
 public:
  MappedTopic(const std::string& domain, const std::string& topic)
      : segment_{shm::detail::Segment::open_existing(shm::detail::segment_name(domain, "topic", topic))} {
    if (!segment_) throw std::runtime_error{"no topic '" + topic + "' in domain '" + domain + "'"};
  }

  [[nodiscard]] shm::detail::TopicHeader& header() const {
    return *std::launder(reinterpret_cast<shm::detail::TopicHeader*>(segment_->data()));
  }

  // Whether someone sleeps on the topic's data doorbell (a subscriber with
  // nothing to read) within `timeout`.
  bool a_subscriber_sleeps(std::chrono::milliseconds timeout = std::chrono::seconds{10}) const {
    return within(timeout, [&] { return header().data.sleepers.load() != 0; });
  }
  // Whether the publisher sleeps waiting for room within `timeout`.
  bool the_publisher_sleeps(std::chrono::milliseconds timeout = std::chrono::seconds{10}) const {
    return within(timeout, [&] { return header().space.sleepers.load() != 0; });
  }

  // Chunk `i`, ring entry and info of sequence `seq`, found by the header
  // as it is now.
  [[nodiscard]] shm::detail::ChunkHeader& chunk(std::size_t i) const {
    const auto& h = header();
    return *std::launder(reinterpret_cast<shm::detail::ChunkHeader*>(segment_->data() + h.chunks_offset + i * h.chunk_stride));
  }
  [[nodiscard]] std::atomic<std::uint64_t>& ring(std::uint64_t seq) const {
    const auto& h = header();
    return reinterpret_cast<std::atomic<std::uint64_t>*>(segment_->data() + h.ring_offset)[seq % h.capacity];
  }
  [[nodiscard]] shm::detail::SampleInfo& info(std::uint64_t seq) const {
    const auto& h = header();
    return std::launder(reinterpret_cast<shm::detail::SampleInfo*>(segment_->data() + h.info_offset))[seq % h.capacity];
  }

  // Who holds chunk `i` (its holders word: a bit per subscriber slot, and
  // the publisher's).
  [[nodiscard]] std::uint64_t holders(std::size_t i) const { return chunk(i).holders.load(); }
  // How many chunks the ring names and the publisher alone holds, and how
  // many are held otherwise: by the publisher outside the ring (its loans,
  // its spares, chunks on their way out of the ring), or by a subscriber.
  struct Census {
    std::size_t ring_only = 0;
    std::size_t other = 0;
  };
  [[nodiscard]] Census census() const {
    const auto& h = header();
    std::vector<bool> named(h.chunk_count, false);
    for (std::uint64_t i = 0; i < h.capacity; ++i)
      if (const auto c = shm::detail::RingEntry::chunk(ring(i).load()); c < h.chunk_count) named[c] = true;
    Census c;
    for (std::size_t i = 0; i < h.chunk_count; ++i) {
      const auto held = holders(i);
      if (held == shm::detail::kPublisherBit && named[i]) ++c.ring_only;
      else if (held != 0) ++c.other;
    }
    return c;
  }

  template <class Condition>
  static bool within(std::chrono::milliseconds timeout, Condition condition) {
    return test::within(timeout, std::move(condition));
  }

 private:
  std::optional<shm::detail::Segment> segment_;
};

}  // namespace prime::test
