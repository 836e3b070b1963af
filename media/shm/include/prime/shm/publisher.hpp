#pragma once

#include <cstddef>
#include <cstring>
#include <expected>
#include <functional>
#include <memory>
#include <new>
#include <span>
#include <string>
#include <type_traits>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/ring.hpp"

namespace prime::shm {

// The message type of a raw byte topic (images, point clouds): each message
// is 0 to max_message_size bytes, sized when it is loaned.
struct Bytes {};

// A message a shared-memory topic can carry: it is its bytes.
template <class T>
concept Message = std::is_same_v<T, Bytes> ||
                  (std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T> && alignof(T) <= 64);

// A slot of the topic, loaned to the publisher: written in place, then
// published (or, if dropped unpublished, handed back). Move-only.
template <Message T>
class Loan {
 public:
  Loan(Loan&& other) noexcept
      : writer_{std::exchange(other.writer_, nullptr)}, chunk_{other.chunk_}, size_{other.size_} {}
  Loan& operator=(Loan&& other) noexcept {
    if (this != &other) {
      discard();
      writer_ = std::exchange(other.writer_, nullptr);
      chunk_ = other.chunk_;
      size_ = other.size_;
    }
    return *this;
  }
  ~Loan() { discard(); }

  [[nodiscard]] T& operator*() const noexcept requires(!std::is_same_v<T, Bytes>) { return *get(); }
  [[nodiscard]] T* operator->() const noexcept requires(!std::is_same_v<T, Bytes>) { return get(); }
  [[nodiscard]] T* get() const noexcept requires(!std::is_same_v<T, Bytes>) {
    return std::launder(reinterpret_cast<T*>(writer_->topic()->payload(chunk_)));
  }
  // The loaned bytes of a raw byte topic.
  [[nodiscard]] std::span<std::byte> bytes() const noexcept requires std::is_same_v<T, Bytes> {
    return {writer_->topic()->payload(chunk_), size_};
  }

  // Makes the sample visible to every subscriber; it is never copied.
  void publish(Clock::time_point stamp = Clock::now()) && {
    writer_->publish(chunk_, size_, stamp);
    writer_ = nullptr;
  }

 private:
  template <Message>
  friend class Publisher;
  Loan(detail::Writer* writer, std::uint32_t chunk, std::size_t size) : writer_{writer}, chunk_{chunk}, size_{size} {}

  void discard() noexcept {
    if (writer_) writer_->discard(chunk_);
    writer_ = nullptr;
  }

  detail::Writer* writer_;
  std::uint32_t chunk_;
  std::size_t size_;
};

// The one publisher of a topic in its domain. Publishing is loan → write in
// place → publish. Move-only; loans must not outlive it.
//
// Not thread-safe: one thread at a time loans and publishes.
template <Message T>
class Publisher {
 public:
  Publisher(std::shared_ptr<detail::Topic> topic, std::chrono::milliseconds block_timeout,
            std::function<void(Error)> report)
      : writer_{std::make_unique<detail::Writer>(std::move(topic), block_timeout, std::move(report))} {}

  // A slot for the next message, default-initialised (not zeroed). On a
  // `block` topic it first waits (up to the block timeout) for the slowest
  // subscriber. Fails with Errc::limit_exceeded when subscribers hold every slot.
  [[nodiscard]] std::expected<Loan<T>, Error> loan() requires(!std::is_same_v<T, Bytes>) {
    auto chunk = writer_->loan();
    if (!chunk) return std::unexpected(std::move(chunk.error()));
    ::new (writer_->topic()->payload(*chunk)) T;
    return Loan<T>{writer_.get(), *chunk, sizeof(T)};
  }

  // A slot of `size` bytes on a raw byte topic; a size over the topic's
  // maximum is Errc::limit_exceeded, naming both.
  [[nodiscard]] std::expected<Loan<T>, Error> loan(std::size_t size) requires std::is_same_v<T, Bytes> {
    const auto max = writer_->topic()->header().max_message_size;
    if (size > max)
      return std::unexpected(Error{Errc::limit_exceeded, "topic '" + name() + "': a message of " +
                                                             std::to_string(size) + " bytes exceeds its maximum of " +
                                                             std::to_string(max) + " bytes"});
    auto chunk = writer_->loan();
    if (!chunk) return std::unexpected(std::move(chunk.error()));
    return Loan<T>{writer_.get(), *chunk, size};
  }

  // Copies `value` into a loaned slot and publishes it: for small messages
  // built elsewhere.
  std::expected<void, Error> publish(const T& value, Clock::time_point stamp = Clock::now())
    requires(!std::is_same_v<T, Bytes>)
  {
    auto slot = loan();
    if (!slot) return std::unexpected(std::move(slot.error()));
    std::memcpy(static_cast<void*>(slot->get()), &value, sizeof(T));
    std::move(*slot).publish(stamp);
    return {};
  }
  std::expected<void, Error> publish(std::span<const std::byte> bytes, Clock::time_point stamp = Clock::now())
    requires std::is_same_v<T, Bytes>
  {
    auto slot = loan(bytes.size());
    if (!slot) return std::unexpected(std::move(slot.error()));
    if (!bytes.empty()) std::memcpy(slot->bytes().data(), bytes.data(), bytes.size());
    std::move(*slot).publish(stamp);
    return {};
  }

  [[nodiscard]] const std::string& name() const noexcept { return writer_->topic()->name(); }

 private:
  std::unique_ptr<detail::Writer> writer_;
};

}  // namespace prime::shm
