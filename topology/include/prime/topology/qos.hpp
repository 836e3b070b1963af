#pragma once

#include <chrono>
#include <cstddef>

namespace prime {

// What a bounded buffer does when a writer finds it full.
enum class Overflow {
  drop_oldest,  // sensor data: the writer never waits; the reader is told how many it lost
  block,        // lossless: the writer waits for room, up to `Qos::block_timeout`
};

// Quality of service of one source, chosen at run time. Every reader of the
// source gets its own buffer of `capacity` values.
struct Qos {
  std::size_t capacity = 64;
  Overflow overflow = Overflow::drop_oldest;
  // How long a `block` writer waits for a reader to make room before it gives
  // up on that reader for this value (counted as lost and reported): a dead or
  // wedged reader must not stall a producer forever.
  std::chrono::milliseconds block_timeout{1000};
};

}  // namespace prime
