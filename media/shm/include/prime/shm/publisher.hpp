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
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/writer.hpp"
#include "prime/shm/message.hpp"
#include "prime/shm/qos.hpp"

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
  // The last batch's list of chunks, kept for the next: a batch then costs
  // no allocation.
  std::vector<std::uint32_t> chunk_list;

  // A loan (or a batch) ends: the last to end after the publisher is gone
  // takes the writer with it.
  static void end_loan(LoaningWriter* owner) noexcept {
    if (--owner->loans > 0) return;
    auto last = std::move(owner->orphaned);
  }
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
  void end() noexcept { detail::LoaningWriter::end_loan(std::exchange(owner_, nullptr)); }

  detail::LoaningWriter* owner_;
  std::uint32_t chunk_;
  std::size_t size_;
};

// Several slots of the topic, loaned at once (Publisher::loan_some): each
// written in place, then all published in one step, in order, so that a
// subscriber takes them with one transfer of the ring's line rather than
// one per sample. Dropped unpublished, they are handed back. Move-only; it
// may outlive its Publisher, like a Loan.
template <Message T>
class Batch {
 public:
  Batch(Batch&& other) noexcept
      : owner_{std::exchange(other.owner_, nullptr)},
        places_{other.places_},
        chunks_{std::move(other.chunks_)},
        size_{other.size_} {}
  Batch& operator=(Batch&& other) noexcept {
    if (this != &other) {
      discard();
      owner_ = std::exchange(other.owner_, nullptr);
      places_ = other.places_;
      chunks_ = std::move(other.chunks_);
      size_ = other.size_;
    }
    return *this;
  }
  ~Batch() { discard(); }

  // How many slots were loaned: at least one, at most what was asked.
  [[nodiscard]] std::size_t size() const noexcept { return chunks_.size(); }
  [[nodiscard]] T& operator[](std::size_t i) const noexcept requires(!std::is_same_v<T, Bytes>) {
    return *std::launder(reinterpret_cast<T*>(places_.payload(chunks_[i])));
  }
  // Slot `i`'s bytes, on a raw byte topic.
  [[nodiscard]] std::span<std::byte> bytes(std::size_t i) const noexcept requires std::is_same_v<T, Bytes> {
    return {places_.payload(chunks_[i]), size_};
  }

  // Publishes every slot, stamped `stamp`.
  void publish(Clock::time_point stamp = Clock::now()) && {
    owner_->writer.publish_some(chunks_, size_, [&](std::size_t) { return stamp; });
    end();
  }
  // Publishes every slot, slot i stamped stamps[i] (as many stamps as slots).
  void publish(std::span<const Clock::time_point> stamps) && {
    if (stamps.size() != chunks_.size())
      throw Failure{{Errc::invalid_argument, "topic '" + owner_->writer.topic()->name() + "': a batch of " +
                                                 std::to_string(chunks_.size()) + " slots published with " +
                                                 std::to_string(stamps.size()) + " stamps"}};
    owner_->writer.publish_some(chunks_, size_, [&](std::size_t i) { return stamps[i]; });
    end();
  }

 private:
  template <Message>
  friend class Publisher;
  Batch(detail::LoaningWriter* owner, std::vector<std::uint32_t> chunks, std::size_t size)
      : owner_{owner}, places_{owner->writer.topic()->places()}, chunks_{std::move(chunks)}, size_{size} {
    ++owner_->loans;
  }

  void discard() noexcept {
    if (!owner_) return;
    for (const auto chunk : chunks_) owner_->writer.discard(chunk);
    end();
  }
  void end() noexcept {
    chunks_.clear();
    owner_->chunk_list = std::move(chunks_);
    detail::LoaningWriter::end_loan(std::exchange(owner_, nullptr));
  }

  detail::LoaningWriter* owner_;
  detail::Places places_;  // the topic's, copied: slot i is found without a walk through the owner
  std::vector<std::uint32_t> chunks_;
  std::size_t size_;  // bytes in each slot
};

// The one publisher of a topic in its domain. Publishing is loan → write in
// place → publish. Move-only.
//
// Not thread-safe: one thread at a time loans and publishes.
template <Message T>
class Publisher {
 public:
  Publisher(std::shared_ptr<detail::Topic> topic, std::chrono::milliseconds block_timeout, PublishFence fence,
            std::function<void(Error)> report)
      : owner_{std::make_shared<detail::LoaningWriter>(std::move(topic), saturating_cast<std::chrono::nanoseconds>(block_timeout),
                                                       fence == PublishFence::light,
                                                       std::move(report))} {}
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
  // core.errors() and no longer waited for until it catches up. There,
  // every loan out (and every slot of a batch) takes its place in the ring:
  // the room waited for is after theirs, and a loan beyond the ring's
  // capacity is Errc::queue_full. Under drop_oldest, loans are bounded
  // by the topic's spare chunks (Errc::queue_full, saying how many are out).
  [[nodiscard]] std::expected<Loan<T>, Error> loan() requires(!std::is_same_v<T, Bytes>) {
    auto chunk = owner_->writer.loan();
    if (!chunk) return std::unexpected(std::move(chunk.error()));
    ::new (owner_->writer.topic()->payload(*chunk)) T;
    return Loan<T>{owner_.get(), *chunk, sizeof(T)};
  }

  // A slot of `size` bytes on a raw byte topic; a size over the topic's
  // maximum is Errc::too_large, naming both.
  [[nodiscard]] std::expected<Loan<T>, Error> loan(std::size_t size) requires std::is_same_v<T, Bytes> {
    if (auto fits = check_size(size); !fits) return std::unexpected(std::move(fits.error()));
    auto chunk = owner_->writer.loan();
    if (!chunk) return std::unexpected(std::move(chunk.error()));
    return Loan<T>{owner_.get(), *chunk, size};
  }

  // Up to `max` slots at once, default-initialised: the first as loan()
  // gives it (waiting under `block`), then as many more as the topic has
  // free now (and, under `block`, room for in the ring), never more than its
  // capacity. For streams of small messages: a batch costs the subscriber
  // about one transfer of the ring's cache line, not one per sample.
  [[nodiscard]] std::expected<Batch<T>, Error> loan_some(std::size_t max) requires(!std::is_same_v<T, Bytes>) {
    auto chunks = loan_chunks(max);
    if (!chunks) return std::unexpected(std::move(chunks.error()));
    for (const auto chunk : *chunks) ::new (owner_->writer.topic()->payload(chunk)) T;
    return Batch<T>{owner_.get(), std::move(*chunks), sizeof(T)};
  }
  // The same on a raw byte topic, each slot `size` bytes.
  [[nodiscard]] std::expected<Batch<T>, Error> loan_some(std::size_t max, std::size_t size)
    requires std::is_same_v<T, Bytes>
  {
    if (auto fits = check_size(size); !fits) return std::unexpected(std::move(fits.error()));
    auto chunks = loan_chunks(max);
    if (!chunks) return std::unexpected(std::move(chunks.error()));
    return Batch<T>{owner_.get(), std::move(*chunks), size};
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
  std::expected<void, Error> check_size(std::size_t size) const {
    const auto max = owner_->writer.topic()->geometry().max_message_size;
    if (size <= max) return {};
    return std::unexpected(Error{Errc::too_large, "topic '" + name() + "': a message of " + std::to_string(size) +
                                                           " bytes exceeds its maximum of " + std::to_string(max) + " bytes"});
  }
  std::expected<std::vector<std::uint32_t>, Error> loan_chunks(std::size_t max) {
    if (max == 0)
      return std::unexpected(Error{Errc::invalid_argument, "topic '" + name() + "': a batch of 0 slots asked for"});
    auto chunks = std::move(owner_->chunk_list);
    chunks.clear();
    chunks.reserve(max);
    if (auto done = owner_->writer.loan_some(max, chunks); !done) return std::unexpected(std::move(done.error()));
    return chunks;
  }

  void release() noexcept {
    if (owner_ && owner_->loans > 0) owner_->orphaned = owner_;  // the last loan ends the writer
    owner_.reset();
  }

  std::shared_ptr<detail::LoaningWriter> owner_;
};

}  // namespace prime::shm
