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
#include "prime/optimus/stream.hpp"
#include "prime/optimus/streaming_publisher.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/qos.hpp"

namespace prime::optimus {

namespace detail {
// A reader of a source: its stream's messages, decoded. One that does not
// decode as a T is counted as lost and said on the errors source.
template <class T>
class TypedReader final : public Reader<T>::Impl {
 public:
  TypedReader(const Stream& stream, const Qos& qos)
      : cursor_{stream, qos}, where_{"source '" + stream.name() + "', key '" + stream.key() + "'"} {}

  std::optional<Sample<T>> try_read() override {
    while (auto message = cursor_.try_read())
      if (auto sample = decoded(std::move(*message))) return sample;
    return std::nullopt;
  }
  std::expected<Sample<T>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    while (true) {
      auto message = cursor_.read_until(deadline, stop);
      if (!message) return std::unexpected(std::move(message.error()));
      if (auto sample = decoded(std::move(*message))) return std::move(*sample);
    }
  }
  [[nodiscard]] std::uint64_t lost() const override { return cursor_.lost(); }

 private:
  std::optional<Sample<T>> decoded(Message message) {
    auto value = decode_message<T>(message.first, where_);
    if (!value) {
      cursor_.refuse(std::move(value.error()));
      return std::nullopt;
    }
    return Sample<T>{std::move(*value), message.second};
  }

  StreamCursor cursor_;
  const std::string where_;
};
}  // namespace detail

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

  Source(detail::Stream stream, Graph graph)
      : stream_{std::move(stream)}, graph_{std::make_shared<const Graph>(std::move(graph))} {}

  // A new reader that sees every value appended from now on. Throws when the
  // server cannot be reached.
  [[nodiscard]] Reader<T> subscribe() const { return subscribe(stream_.qos()); }
  [[nodiscard]] Reader<T> subscribe(const Qos& qos) const {
    return Reader<T>{std::make_unique<detail::TypedReader<T>>(stream_, qos)};
  }

  // Appends a value, as the source's producer would.
  std::expected<void, Error> publish(const T& value, Clock::time_point stamp = Clock::now()) const {
    return stream_.publish(encode_message(value), stamp);
  }

  [[nodiscard]] const std::string& name() const noexcept { return stream_.name(); }
  [[nodiscard]] const Qos& qos() const noexcept { return stream_.qos(); }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const std::weak_ptr<prime::detail::RuntimeState>& runtime() const noexcept { return stream_.runtime(); }
  // The Redis key of the stream, for tools that look at the server.
  [[nodiscard]] const std::string& key() const noexcept { return stream_.key(); }
  [[nodiscard]] const detail::Stream& stream() const noexcept { return stream_; }

 private:
  detail::Stream stream_;
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
  explicit Publisher(Source<T> source) : source_{std::move(source)} {}

  std::expected<void, Error> publish(const T& value, Clock::time_point stamp = Clock::now()) const {
    return source_.publish(value, stamp);
  }

  // Pipelined: the values go out in one write and are appended in order. A
  // batch never waits for readers (drop_oldest, whatever the source's policy).
  std::expected<void, Error> publish_all(std::span<const Sample<T>> samples) const {
    const auto batch = detail::encoded(samples);
    return source_.stream().publish_all(batch);
  }

  // A writer for a steady stream of batches, with one in flight while the
  // next is sent (StreamingPublisher).
  [[nodiscard]] StreamingPublisher<T> streaming() const { return StreamingPublisher<T>{source_.stream()}; }

  [[nodiscard]] const Source<T>& source() const noexcept { return source_; }

 private:
  Source<T> source_;
};

}  // namespace prime::optimus
