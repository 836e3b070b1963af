// The compiled side of a Publisher: its port's loans and publishes, which
// the typed Publisher, Loan and Batch of publisher.hpp call. The engine
// itself is the Writer (detail/writer.hpp), inlined here.
#include "prime/shm/publisher.hpp"

#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/topic.hpp"
#include "prime/shm/detail/writer.hpp"

namespace prime::shm::detail {

PublisherPort::PublisherPort(std::shared_ptr<Topic> topic, std::chrono::nanoseconds block_timeout, bool light,
                             std::function<void(Error)> report)
    : writer_{std::make_unique<Writer>(std::move(topic), block_timeout, light, std::move(report))},
      payloads_{writer_->topic()->places().chunks + kPayloadOffset, writer_->topic()->places().stride},
      max_size_{writer_->topic()->geometry().max_message_size} {}

PublisherPort::~PublisherPort() = default;

const std::string& PublisherPort::name() const noexcept { return writer_->topic()->name(); }

std::expected<std::uint32_t, Error> PublisherPort::loan() { return writer_->loan(); }

std::expected<void, Error> PublisherPort::loan_some(std::size_t max, std::vector<std::uint32_t>& out) {
  return writer_->loan_some(max, out);
}

void PublisherPort::discard(std::uint32_t chunk) noexcept { writer_->discard(chunk); }

void PublisherPort::publish(std::uint32_t chunk, std::size_t size, Clock::time_point stamp) noexcept {
  writer_->publish(chunk, size, stamp);
}

void PublisherPort::publish_some(std::span<const std::uint32_t> chunks, std::size_t size, Clock::time_point stamp) noexcept {
  writer_->publish_some(chunks, size, [&](std::size_t) { return stamp; });
}

void PublisherPort::publish_some(std::span<const std::uint32_t> chunks, std::size_t size,
                                 std::span<const Clock::time_point> stamps) noexcept {
  writer_->publish_some(chunks, size, [&](std::size_t i) { return stamps[i]; });
}

}  // namespace prime::shm::detail
