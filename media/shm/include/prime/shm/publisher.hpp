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
#include "prime/shm/detail/writer.hpp"
#include "prime/shm/message.hpp"

namespace prime::shm {

namespace detail {

// A Writer with the loans it has out: a Publisher destroyed while a loan
// lives leaves the writer to that loan, which ends it. One thread at a time
// uses a publisher and its loans, so the count needs no atomics (the hot
// path pays nothing for this).
struct LoaningWriter {
  template <class... Args>
  explicit LoaningWriter(Args&&... args) : writer{std::forward<Args>(args)...} {}

  Writer writer;
  std::size_t loans = 0;
  std::shared_ptr<LoaningWriter> orphaned;  // set while loans outlive the publisher
};

}  // namespace detail

// A slot of the topic, loaned to the publisher: written in place, then
// published (or, if dropped unpublished, handed back). Move-only. It may
// outlive its Publisher: the topic's publisher role ends with the last of them.
template <Message T>
class Loan {
 public:
  Loan(Loan&& other) noexcept
      : owner_{std::exchange(other.owner_, nullptr)}, chunk_{other.chunk_}, size_{other.size_} {}
  Loan& operator=(Loan&& other) noexcept {
    if (this != &other) {
      discard();
      owner_ = std::exchange(other.owner_, nullptr);
      chunk_ = other.chunk_;
      size_ = other.size_;
    }
    return *this;
  }
  ~Loan() { discard(); }

  [[nodiscard]] T& operator*() const noexcept requires(!std::is_same_v<T, Bytes>) { return *get(); }
  [[nodiscard]] T* operator->() const noexcept requires(!std::is_same_v<T, Bytes>) { return get(); }
  [[nodiscard]] T* get() const noexcept requires(!std::is_same_v<T, Bytes>) {
    return std::launder(reinterpret_cast<T*>(owner_->writer.topic()->payload(chunk_)));
  }
  // The loaned bytes of a raw byte topic.
  [[nodiscard]] std::span<std::byte> bytes() const noexcept requires std::is_same_v<T, Bytes> {
    return {owner_->writer.topic()->payload(chunk_), size_};
  }

  // Makes the sample visible to every subscriber; it is never copied.
  // `stamp` is when the sensor took it (steady_clock: one clock for every
  // process); subscribers read it as View::stamp().
  void publish(Clock::time_point stamp = Clock::now()) && {
    owner_->writer.publish(chunk_, size_, stamp);
    end();
  }

 private:
  template <Message>
  friend class Publisher;
  Loan(detail::LoaningWriter* owner, std::uint32_t chunk, std::size_t size) : owner_{owner}, chunk_{chunk}, size_{size} {
    ++owner_->loans;
  }

  void discard() noexcept {
    if (!owner_) return;
    owner_->writer.discard(chunk_);
    end();
  }
  void end() noexcept {
    auto* owner = std::exchange(owner_, nullptr);
    if (--owner->loans > 0) return;
    auto last = std::move(owner->orphaned);  // set once the publisher is gone: its writer ends with this loan
  }

  detail::LoaningWriter* owner_;
  std::uint32_t chunk_;
  std::size_t size_;
};

// The one publisher of a topic in its domain. Publishing is loan → write in
// place → publish. Move-only.
//
// Not thread-safe: one thread at a time loans and publishes.
template <Message T>
class Publisher {
 public:
  Publisher(std::shared_ptr<detail::Topic> topic, std::chrono::milliseconds block_timeout,
            std::function<void(Error)> report)
      : owner_{std::make_shared<detail::LoaningWriter>(std::move(topic), block_timeout, std::move(report))} {}
  Publisher(Publisher&&) noexcept = default;
  Publisher& operator=(Publisher&& other) noexcept {
    if (this != &other) {
      release();
      owner_ = std::move(other.owner_);
    }
    return *this;
  }
  ~Publisher() { release(); }

  // A slot for the next message, default-initialised (not zeroed). On a
  // `block` topic it first waits for every subscriber to have room, except
  // one that read nothing for the block timeout: that one is reported on
  // core.errors() and no longer waited for until it catches up.
  [[nodiscard]] std::expected<Loan<T>, Error> loan() requires(!std::is_same_v<T, Bytes>) {
    auto chunk = owner_->writer.loan();
    if (!chunk) return std::unexpected(std::move(chunk.error()));
    ::new (owner_->writer.topic()->payload(*chunk)) T;
    return Loan<T>{owner_.get(), *chunk, sizeof(T)};
  }

  // A slot of `size` bytes on a raw byte topic; a size over the topic's
  // maximum is Errc::limit_exceeded, naming both.
  [[nodiscard]] std::expected<Loan<T>, Error> loan(std::size_t size) requires std::is_same_v<T, Bytes> {
    const auto max = owner_->writer.topic()->header().max_message_size;
    if (size > max)
      return std::unexpected(Error{Errc::limit_exceeded, "topic '" + name() + "': a message of " +
                                                             std::to_string(size) + " bytes exceeds its maximum of " +
                                                             std::to_string(max) + " bytes"});
    auto chunk = owner_->writer.loan();
    if (!chunk) return std::unexpected(std::move(chunk.error()));
    return Loan<T>{owner_.get(), *chunk, size};
  }

  // Copies `value` into a loaned slot and publishes it: for small messages
  // built elsewhere.
  [[nodiscard]] std::expected<void, Error> publish(const T& value, Clock::time_point stamp = Clock::now())
    requires(!std::is_same_v<T, Bytes>)
  {
    auto slot = loan();
    if (!slot) return std::unexpected(std::move(slot.error()));
    std::memcpy(static_cast<void*>(slot->get()), &value, sizeof(T));
    std::move(*slot).publish(stamp);
    return {};
  }
  [[nodiscard]] std::expected<void, Error> publish(std::span<const std::byte> bytes, Clock::time_point stamp = Clock::now())
    requires std::is_same_v<T, Bytes>
  {
    auto slot = loan(bytes.size());
    if (!slot) return std::unexpected(std::move(slot.error()));
    if (!bytes.empty()) std::memcpy(slot->bytes().data(), bytes.data(), bytes.size());
    std::move(*slot).publish(stamp);
    return {};
  }

  [[nodiscard]] const std::string& name() const noexcept { return owner_->writer.topic()->name(); }

 private:
  void release() noexcept {
    if (owner_ && owner_->loans > 0) owner_->orphaned = owner_;  // the last loan ends the writer
    owner_.reset();
  }

  std::shared_ptr<detail::LoaningWriter> owner_;
};

}  // namespace prime::shm
