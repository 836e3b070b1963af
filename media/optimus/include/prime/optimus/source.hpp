#pragma once

#include <expected>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/detail/stream_reader.hpp"
#include "prime/optimus/detail/stream_writer.hpp"
#include "prime/optimus/streaming_publisher.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/qos.hpp"

namespace prime::optimus {

// A source carried by a bounded Redis stream: trimmed to `Qos::capacity`
// entries, so it never grows. Any process of the domain can read it; each
// reader has its own cursor and gives latest / all unread like any Reader.
// Copies are handles to the same source.
//
// Thread-safe.
template <class T>
class Source {
 public:
  using value_type = T;

  Source(std::shared_ptr<detail::StreamState> state, Graph graph)
      : state_{std::move(state)}, graph_{std::make_shared<const Graph>(std::move(graph))} {}

  // A new reader that sees every value appended from now on. Throws when the
  // server cannot be reached.
  [[nodiscard]] Reader<T> subscribe() const { return subscribe(state_->qos()); }
  [[nodiscard]] Reader<T> subscribe(const Qos& qos) const {
    return Reader<T>{std::make_unique<detail::StreamReader<T>>(state_, qos)};
  }

  // Appends a value, as the source's producer would.
  std::expected<void, Error> publish(const T& value, Clock::time_point stamp = Clock::now()) const {
    return state_->publish(encode_message(value), stamp);
  }

  [[nodiscard]] const std::string& name() const noexcept { return state_->name(); }
  [[nodiscard]] const Qos& qos() const noexcept { return state_->qos(); }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const std::weak_ptr<prime::detail::RuntimeState>& runtime() const noexcept { return state_->runtime(); }
  // The Redis key of the stream, for tools that look at the server.
  [[nodiscard]] const std::string& key() const noexcept { return state_->key(); }

 private:
  std::shared_ptr<detail::StreamState> state_;
  std::shared_ptr<const Graph> graph_;
};

static_assert(prime::Source<Source<int>>);

// The writing end of a named source, for a process that produces values
// without an Event: `publish` one, `publish_all` a batch in one round trip,
// or stream batches with one in flight (`streaming`).
//
// Thread-safe.
template <class T>
class Publisher {
 public:
  explicit Publisher(Source<T> source, std::shared_ptr<detail::StreamState> state)
      : source_{std::move(source)}, state_{std::move(state)} {}

  std::expected<void, Error> publish(const T& value, Clock::time_point stamp = Clock::now()) const {
    return source_.publish(value, stamp);
  }

  // Pipelined: the values go out in one write and are appended in order. A
  // batch never waits for readers (drop_oldest, whatever the source's policy).
  std::expected<void, Error> publish_all(std::span<const Sample<T>> samples) const {
    return state_->publish_all(detail::encoded(samples));
  }

  // A writer for a steady stream of batches, with one in flight while the
  // next is sent (StreamingPublisher).
  [[nodiscard]] StreamingPublisher<T> streaming() const { return StreamingPublisher<T>{state_}; }

  [[nodiscard]] const Source<T>& source() const noexcept { return source_; }

 private:
  Source<T> source_;
  std::shared_ptr<detail::StreamState> state_;
};

}  // namespace prime::optimus
