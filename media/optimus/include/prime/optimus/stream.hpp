#pragma once

#include <cstdint>
#include <expected>
#include <memory>
#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/logic/sample.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/qos.hpp"

// The untyped ends of a source's stream, compiled in libprime_optimus
// (src/stream.cpp): messages here are bytes, already encoded. The typed
// Source<T>, Publisher<T>, StreamingPublisher<T> and their readers
// (source.hpp) are templates over them that only encode and decode.
// Not for users: the typed classes are the API.

namespace prime::optimus::detail {

class StreamState;   // a source's stream and what its handles share (detail/stream_writer.hpp)
class StreamReader;  // one reader's cursor (detail/stream_reader.hpp)
struct InFlight;     // a StreamingPublisher's batch in flight

// An encoded value and its stamp.
using Message = std::pair<std::string, Clock::time_point>;

// A source's stream: where it is, its QoS, the core it reports to. Copies
// share it. Thread-safe.
class Stream {
 public:
  explicit Stream(std::shared_ptr<StreamState> state);

  [[nodiscard]] const std::string& name() const noexcept;
  // The Redis key of the stream.
  [[nodiscard]] const std::string& key() const noexcept;
  [[nodiscard]] const Qos& qos() const noexcept;
  [[nodiscard]] const std::weak_ptr<prime::detail::RuntimeState>& runtime() const noexcept;

  // Appends one message (one round trip); under `block`, waits for the readers first.
  std::expected<void, Error> publish(std::string_view message, Clock::time_point stamp) const;
  // Appends a batch in one round trip, never waiting for readers.
  std::expected<void, Error> publish_all(std::span<const Message> messages) const;

  // Says `error` on the errors source of the core the stream belongs to.
  void report(Error error) const;
  // Keeps the event listener that feeds this source for as long as the source lives.
  void feed_from(prime::Connection upstream) const;

  [[nodiscard]] const std::shared_ptr<StreamState>& state() const noexcept { return state_; }

 private:
  std::shared_ptr<StreamState> state_;
};

// One reader of a stream, with its own cursor: its messages in order, still
// encoded (see detail/stream_reader.hpp). Not thread-safe.
class StreamCursor {
 public:
  // Throws Failure when the server cannot be reached.
  StreamCursor(const Stream& stream, const Qos& qos);
  StreamCursor(StreamCursor&&) noexcept;
  StreamCursor& operator=(StreamCursor&&) = delete;
  ~StreamCursor();

  // The next unread message, without waiting.
  std::optional<Message> try_read();
  // The next unread message, waiting for it until `deadline` or a stop request.
  std::expected<Message, Error> read_until(Clock::time_point deadline, std::stop_token stop);
  // Messages lost: trimmed away, skipped for the newest, dropped by a writer.
  [[nodiscard]] std::uint64_t lost() const;
  // A message read that did not decode: counted as lost, and said.
  void refuse(Error why);

 private:
  std::unique_ptr<StreamReader> reader_;  // holds the stream's state, and so keeps the source alive
};

// Batches sent one after another with one in flight (StreamingPublisher).
// Not thread-safe. Movable; the destructor flushes and reports a failure.
class BatchStream {
 public:
  explicit BatchStream(Stream stream);
  BatchStream(BatchStream&&) noexcept;
  BatchStream& operator=(BatchStream&&) = delete;
  ~BatchStream();

  // Sends `batch`, then waits for the one before it: that one's outcome.
  std::expected<void, Error> publish_all(std::vector<Message> batch);
  // Waits for the batch in flight.
  std::expected<void, Error> flush();

 private:
  Stream stream_;
  std::unique_ptr<InFlight> in_flight_;
};

}  // namespace prime::optimus::detail
