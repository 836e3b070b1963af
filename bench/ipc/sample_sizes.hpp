#pragma once

// For the DDS peers, whose sample type is compiled for each payload size (Fast
// DDS's TopicDataType, Cyclone DDS's topic descriptor): a benchmark runs only
// at the sizes of kLatencyPayloads and kThroughputPayloads.

#include <cstddef>
#include <iterator>
#include <string>
#include <utility>

#include "harness.hpp"

namespace prime::bench::ipc {

namespace detail {

// Calls f.operator()<N>() if `bytes` is N, one of kSizes.
template <const auto& kSizes, class F, std::size_t... I>
bool dispatch(std::size_t bytes, F& f, std::index_sequence<I...>) {
  return ((bytes == static_cast<std::size_t>(kSizes[I]) &&
           (f.template operator()<static_cast<std::size_t>(kSizes[I])>(), true)) ||
          ...);
}

}  // namespace detail

// Calls f.operator()<N>() for N == bytes, if N is a payload size of the
// latency or throughput benchmarks; throws PeerError, naming `peer`, if not.
template <class F>
void with_sample_size(std::size_t bytes, const char* peer, F f) {
  constexpr auto kLatency = std::size(kLatencyPayloads);
  constexpr auto kThroughput = std::size(kThroughputPayloads);
  if (!detail::dispatch<kLatencyPayloads>(bytes, f, std::make_index_sequence<kLatency>{}) &&
      !detail::dispatch<kThroughputPayloads>(bytes, f, std::make_index_sequence<kThroughput>{}))
    throw PeerError{std::string{"no "} + peer + " sample type of " + std::to_string(bytes) + " bytes is compiled in"};
}

}  // namespace prime::bench::ipc
