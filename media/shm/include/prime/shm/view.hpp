#pragma once

#include <concepts>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <ostream>
#include <span>
#include <type_traits>
#include <utility>

#include "prime/logic/sample.hpp"
#include "prime/shm/detail/subscriber.hpp"
#include "prime/shm/message.hpp"

namespace prime::shm {

template <Message>
class SubscriptionReader;

// A sample read in place in the topic's shared memory: no copy is made, and
// the publisher does not reuse its slot while any view of it lives. Copies
// share the slot (and count once against the subscriber's max_held). A view
// may outlive its reader.
// Converts to `const T&`, so a chain taking T (or const T&) links after a
// subscription.
//
// Thread-safe: views of one sample may live and die on any threads.
template <Message T>
class View {
 public:
  View(const View& other) noexcept : owner_{other.owner_}, chunk_{other.chunk_}, seq_{other.seq_}, info_{other.info_} {
    if (owner_) owner_->hold_again(chunk_);
  }
  View(View&& other) noexcept
      : owner_{std::exchange(other.owner_, nullptr)}, chunk_{other.chunk_}, seq_{other.seq_}, info_{other.info_} {}
  View& operator=(View other) noexcept {
    std::swap(owner_, other.owner_);
    std::swap(chunk_, other.chunk_);
    std::swap(seq_, other.seq_);
    std::swap(info_, other.info_);
    return *this;
  }
  ~View() {
    if (owner_) owner_->drop(chunk_);
  }

  [[nodiscard]] const T& operator*() const noexcept requires(!std::is_same_v<T, Bytes>) { return *get(); }
  [[nodiscard]] const T* operator->() const noexcept requires(!std::is_same_v<T, Bytes>) { return get(); }
  [[nodiscard]] const T* get() const noexcept requires(!std::is_same_v<T, Bytes>) {
    return std::launder(reinterpret_cast<const T*>(owner_->topic().payload(chunk_)));
  }
  operator const T&() const noexcept requires(!std::is_same_v<T, Bytes>) { return *get(); }  // NOLINT

  // The bytes of a raw byte topic's message.
  [[nodiscard]] std::span<const std::byte> bytes() const noexcept {
    return {owner_->topic().payload(chunk_), info_.size};
  }
  // Its place in the topic: 0 for the first sample ever published.
  [[nodiscard]] std::uint64_t sequence() const noexcept { return seq_; }
  // When the publisher says it was taken (the sensor's stamp, or when it was published).
  [[nodiscard]] Clock::time_point stamp() const noexcept {
    return Clock::time_point{Clock::duration{info_.stamp}};
  }

  friend bool operator==(const View& a, const T& b) requires(!std::is_same_v<T, Bytes>) && std::equality_comparable<T>
  {
    return *a == b;
  }
  friend std::ostream& operator<<(std::ostream& out, const View& v) requires requires(std::ostream& o, const T& t) { o << t; }
  {
    return out << *v;
  }

 private:
  template <Message>
  friend class SubscriptionReader;
  // Whether no copy of this view lives: letting go of it lets go of its sample.
  [[nodiscard]] bool only_view() const noexcept { return owner_ != nullptr && owner_->views_of(chunk_) == 1; }

  // A sample just taken by `owner`.
  View(detail::Subscriber* owner, const detail::Taken& taken)
      : owner_{owner}, chunk_{taken.chunk}, seq_{taken.seq}, info_{taken.info} {
    owner_->hold_taken(chunk_);
  }
  // One of several samples taken together, held already (Subscriber::hold_taken for them all).
  struct Held {};
  View(detail::Subscriber* owner, const detail::Taken& taken, Held) noexcept
      : owner_{owner}, chunk_{taken.chunk}, seq_{taken.seq}, info_{taken.info} {}

  detail::Subscriber* owner_;  // kept alive by the chunk this view holds
  std::uint32_t chunk_;
  std::uint64_t seq_;
  detail::TakenInfo info_;  // its size and stamp, as read when taken
};

}  // namespace prime::shm
