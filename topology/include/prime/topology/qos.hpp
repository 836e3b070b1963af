#pragma once

#include <chrono>
#include <cstddef>
#include <string>

#include "prime/logic/error.hpp"

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
  // How long a reader that finds its buffer empty keeps checking before it
  // sleeps. A value due within microseconds then costs no wake-up call; an
  // idle reader still sleeps and burns nothing. Zero: sleep at once. A
  // reader of an in-process source yields its core now and then as it
  // checks, so on a machine with fewer cores than busy threads it does not
  // keep the thread it waits for from running.
  std::chrono::microseconds spin{20};
  // How many of the source's values one reader may keep at once; 0: no
  // limit. Sources whose values pin scarce memory (a shared-memory topic's
  // views pin its slots) say so here, and what buffers their values (sync)
  // sizes its buffers to stay within it.
  std::size_t max_held = 0;
};

// Throws when `qos` cannot make a buffer, naming the source `name`: every
// medium's sources check their QoS here.
inline void validate(const Qos& qos, const std::string& name) {
  if (qos.capacity == 0) throw Failure{{Errc::invalid_argument, "source '" + name + "': capacity must be at least 1"}};
}

}  // namespace prime
