#pragma once

#include <cstddef>
#include <cstdint>
#include <new>
#include <span>
#include <type_traits>
#include <utility>

#include "prime/logic/sample.hpp"
#include "prime/shm/detail/subscriber.hpp"
#include "prime/shm/message.hpp"

namespace prime::shm {

template <Message>
class SubscriptionReader;

// Samples read together in place (BatchReader::read): consecutive
// sequences of one topic, kept from reuse until the batch is destroyed, and
// then let go of all at once. On a `block` topic the cursor keeps them:
// reading a batch writes nothing in shared memory per sample, two words
// per batch (a batch kept out for long is held instead, see
// detail/cursor.hpp). Its samples count against the reader's max_held
// while it lives.
//
// Move-only; it may outlive its reader. Thread-safe to destroy on any
// thread; one thread at a time reads it.
template <Message T>
class Views {
 public:
  Views() = default;  // empty
  Views(Views&& other) noexcept
      : owner_{std::exchange(other.owner_, nullptr)},
        places_{other.places_},
        index_{other.index_},
        chunks_{std::exchange(other.chunks_, {})},
        info_{std::exchange(other.info_, {})},
        first_{other.first_} {}
  Views& operator=(Views&& other) noexcept {
    if (this != &other) {
      end();
      owner_ = std::exchange(other.owner_, nullptr);
      places_ = other.places_;
      index_ = other.index_;
      chunks_ = std::exchange(other.chunks_, {});
      info_ = std::exchange(other.info_, {});
      first_ = other.first_;
    }
    return *this;
  }
  ~Views() { end(); }

  [[nodiscard]] std::size_t size() const noexcept { return chunks_.size(); }
  [[nodiscard]] bool empty() const noexcept { return chunks_.empty(); }
  // Sample `i`, where its publisher wrote it.
  [[nodiscard]] const T& operator[](std::size_t i) const noexcept requires(!std::is_same_v<T, Bytes>) {
    return *std::launder(reinterpret_cast<const T*>(places_.payload(chunks_[i])));
  }
  // The bytes of sample `i` of a raw byte topic.
  [[nodiscard]] std::span<const std::byte> bytes(std::size_t i) const noexcept {
    return {places_.payload(chunks_[i]), static_cast<std::size_t>(info_[i].size)};
  }
  // Sample `i`'s place in the topic: the first's plus i.
  [[nodiscard]] std::uint64_t sequence(std::size_t i) const noexcept { return first_ + i; }
  // When the publisher says sample `i` was taken.
  [[nodiscard]] Clock::time_point stamp(std::size_t i) const noexcept {
    return Clock::time_point{Clock::duration{info_[i].stamp}};
  }

 private:
  template <Message>
  friend class SubscriptionReader;
  // Batch `index` of `owner`'s cursor, just taken (Subscriber::hold_batch counted it).
  Views(detail::Subscriber* owner, std::uint32_t index)
      : owner_{owner}, places_{owner->topic().places()}, index_{index} {
    const auto& batch = owner->cursor().batch(index);
    chunks_ = batch.chunks;
    info_ = batch.info;
    first_ = batch.first;
  }
  void end() noexcept {
    if (owner_) std::exchange(owner_, nullptr)->end_batch(index_);
    chunks_ = {};
    info_ = {};
  }

  detail::Subscriber* owner_ = nullptr;  // kept alive by the samples this batch counts
  detail::Places places_{};  // the topic's, copied: sample i is found without a walk through the owner
  std::uint32_t index_ = 0;
  std::span<const std::uint32_t> chunks_;  // the batch's, unchanged while it is out
  std::span<const detail::TakenInfo> info_;  // each sample's size and stamp, copied when taken
  std::uint64_t first_ = 0;
};

}  // namespace prime::shm
