#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>

#include "prime/common/bounded_string.hpp"
#include "prime/common/schema.hpp"
#include "prime/shm/qos.hpp"

namespace prime::test {

// A payload whose every word derives from its sequence number, with a
// checksum: a sample read while being overwritten cannot pass check().
struct Checked {
  std::uint64_t seq;
  std::uint64_t words[510];
  std::uint64_t sum;
};

inline void fill(Checked& c, std::uint64_t seq) {
  c.seq = seq;
  std::uint64_t sum = seq;
  for (std::uint64_t i = 0; i < 510; ++i) {
    c.words[i] = seq * 0x9e3779b97f4a7c15ull + i;
    sum += c.words[i];
  }
  c.sum = sum;
}

inline bool check(const Checked& c) {
  std::uint64_t sum = c.seq;
  for (std::uint64_t i = 0; i < 510; ++i) {
    if (c.words[i] != c.seq * 0x9e3779b97f4a7c15ull + i) return false;
    sum += c.words[i];
  }
  return sum == c.sum;
}

// A request that says who asks, and its answer: a caller can tell its own.
struct Ask {
  std::uint64_t who;
  std::uint64_t n;
};
struct Answer {
  std::uint64_t who;
  std::uint64_t n;
};
PRIME_DESCRIBE(Ask, who, n)
PRIME_DESCRIBE(Answer, who, n)

// Asks the emitter peer to publish `value` on its topic number `topic`
// (0: lidar, 1: odom, 2: odom_x as a double), stamped `stamp_ns` on the
// steady clock every process on the machine shares.
struct Emit {
  std::int32_t topic;
  std::int32_t value;
  std::int64_t stamp_ns;
};
PRIME_DESCRIBE(Emit, topic, value, stamp_ns)
// The emitter's topics: max_held leaves a sync room to wait for matches.
inline constexpr shm::TopicQos kEmitterTopics{.capacity = 64, .max_held = 32};

// A described message with text and numbers, for the command-line tool.
struct Tick {
  std::uint64_t n;
  double x;
  bounded_string<8> tag;
};
PRIME_DESCRIBE(Tick, n, x, tag)

// A message with no description: tools show its bytes.
struct Raw {
  std::uint64_t a, b;
};

// A megabyte image: a topic of these with default QoS takes 130 MiB.
struct Image {
  std::byte pixels[1 << 20];
};

// Small ring, so the publisher laps slow readers all the time.
inline constexpr shm::TopicQos kCheckedQos{.capacity = 4, .max_subscribers = 4, .max_held = 2};
// The same under block, waiting 1 ms for a reader before passing it over: a
// reader that stops for longer is lapped as under drop_oldest.
inline constexpr shm::TopicQos kCheckedBlockQos{.capacity = 4, .overflow = Overflow::block,
                                                .block_timeout = std::chrono::milliseconds{1}, .max_subscribers = 4,
                                                .max_held = 2};
inline constexpr shm::TopicQos kSequenceQos{.capacity = 256, .overflow = Overflow::block,
                                            .block_timeout = std::chrono::milliseconds{5000}};

}  // namespace prime::test
