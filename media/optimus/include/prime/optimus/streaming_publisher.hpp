#pragma once

#include <expected>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/stream.hpp"

namespace prime::optimus {

namespace detail {
// A batch's values encoded, each with its stamp, as a stream's writer sends them.
template <class T>
std::vector<Message> encoded(std::span<const Sample<T>> samples) {
  std::vector<Message> batch;
  batch.reserve(samples.size());
  for (const auto& s : samples) batch.emplace_back(encode_message(s.value), s.stamp);
  return batch;
}
}  // namespace detail

// The writing end of a source for a steady stream of batches (a high-rate
// sensor, a log replayed): one batch is in flight while the next is encoded
// and sent, so the server appends without waiting out the writer's round
// trips. `Publisher::publish_all` waits for each batch's replies instead.
//
// `publish_all` sends its batch and returns once the batch before it is
// appended, with that one's outcome. Appends the server refused (the stream
// was deleted, or went on in a later epoch) go again, in order, as with
// `Publisher::publish_all`. A server error is the next call's error; so is
// a dead connection, naming how many values may not have been appended.
// After an error nothing is in flight, but for a batch refused before it
// was sent (a message longer than the server takes: Errc::too_large),
// which leaves the one before in flight. `flush` waits for the batch in
// flight; the destructor flushes, and reports an error to the core's
// errors. A batch never waits for readers (drop_oldest, whatever the
// source's policy).
//
// Not thread-safe: one thread streams. Movable.
template <class T>
class StreamingPublisher {
 public:
  explicit StreamingPublisher(detail::Stream stream) : batches_{std::move(stream)} {}

  std::expected<void, Error> publish_all(std::span<const Sample<T>> samples) {
    return batches_.publish_all(detail::encoded(samples));
  }

  std::expected<void, Error> flush() { return batches_.flush(); }

 private:
  detail::BatchStream batches_;
};

}  // namespace prime::optimus
