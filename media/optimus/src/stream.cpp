// The untyped ends of a source's stream (stream.hpp), over the stream's
// writer and reader (detail/stream_writer.hpp, detail/stream_reader.hpp).
#include "prime/optimus/stream.hpp"

#include "prime/optimus/detail/stream_reader.hpp"
#include "prime/optimus/detail/stream_writer.hpp"

namespace prime::optimus::detail {

Stream::Stream(std::shared_ptr<StreamState> state) : state_{std::move(state)} {}

const std::string& Stream::name() const noexcept { return state_->name(); }
const std::string& Stream::key() const noexcept { return state_->key(); }
const Qos& Stream::qos() const noexcept { return state_->qos(); }
const std::weak_ptr<prime::detail::RuntimeState>& Stream::runtime() const noexcept { return state_->runtime(); }

std::expected<void, Error> Stream::publish(std::string_view message, Clock::time_point stamp) const {
  return state_->publish(message, stamp);
}
std::expected<void, Error> Stream::publish_all(std::span<const Message> messages) const {
  return state_->publish_all(messages);
}
void Stream::report(Error error) const { state_->report(std::move(error)); }
void Stream::feed_from(prime::Connection upstream) const { state_->feed_from(std::move(upstream)); }

StreamCursor::StreamCursor(const Stream& stream, const Qos& qos)
    : reader_{std::make_unique<StreamReader>(stream.state(), qos)} {}
StreamCursor::StreamCursor(StreamCursor&&) noexcept = default;
StreamCursor::~StreamCursor() = default;

std::optional<Message> StreamCursor::try_read() { return reader_->try_read(); }
std::expected<Message, Error> StreamCursor::read_until(Clock::time_point deadline, std::stop_token stop) {
  return reader_->read_until(deadline, std::move(stop));
}
std::uint64_t StreamCursor::lost() const { return reader_->lost(); }
void StreamCursor::refuse(Error why) { reader_->refuse(std::move(why)); }

BatchStream::BatchStream(Stream stream) : stream_{std::move(stream)}, in_flight_{std::make_unique<InFlight>()} {}
BatchStream::BatchStream(BatchStream&&) noexcept = default;
BatchStream::~BatchStream() {
  if (!in_flight_) return;  // moved from
  if (auto done = flush(); !done) stream_.report(std::move(done.error()));
}

std::expected<void, Error> BatchStream::publish_all(std::vector<Message> batch) {
  return stream_.state()->stream(*in_flight_, std::move(batch));
}
std::expected<void, Error> BatchStream::flush() { return stream_.state()->settle(*in_flight_); }

}  // namespace prime::optimus::detail
