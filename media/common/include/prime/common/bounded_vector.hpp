#pragma once

#include <algorithm>
#include <array>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <span>
#include <string>
#include <type_traits>

#include "prime/logic/error.hpp"

namespace prime {

// Up to N values of T stored inline, so a message that holds it stays
// trivially copyable and can live in shared memory or travel as bytes. Its
// accessors never reach past N, whatever count the bytes hold: a message
// another process wrote (in shared memory, through Redis) is read as safely
// as one made here.
template <class T, std::size_t N>
class bounded_vector {
  static_assert(std::is_trivially_copyable_v<T>, "bounded_vector: T must be trivially copyable");
  static_assert(std::default_initializable<T>, "bounded_vector: T must be default-constructible");
  static_assert(N > 0, "bounded_vector: capacity must be at least 1");

 public:
  using value_type = T;
  using iterator = T*;
  using const_iterator = const T*;

  constexpr bounded_vector() noexcept = default;
  // Throws Failure{too_large} when there are more than N values.
  constexpr bounded_vector(std::initializer_list<T> values) { assign(values.begin(), values.end()); }
  constexpr explicit bounded_vector(std::span<const T> values) { assign(values.begin(), values.end()); }

  template <class It>
  constexpr void assign(It first, It last) {
    const auto n = static_cast<std::size_t>(std::distance(first, last));
    if (n > N) throw overflow(n);
    std::copy(first, last, items_.begin());
    size_ = n;
  }

  // Appends, or throws Failure{too_large} when full.
  constexpr void push_back(const T& value) {
    if (!try_push_back(value)) throw overflow(size_ + 1);
  }
  [[nodiscard]] constexpr bool try_push_back(const T& value) noexcept {
    if (size() == N) return false;
    items_[size()] = value;
    size_ = size() + 1;
    return true;
  }
  // Throws Failure{too_large} when n > N. New values are value-initialised.
  constexpr void resize(std::size_t n) {
    if (n > N) throw overflow(n);
    for (auto i = size(); i < n; ++i) items_[i] = T{};
    size_ = n;
  }
  constexpr void clear() noexcept { size_ = 0; }

  // The count the bytes hold, within N.
  [[nodiscard]] constexpr std::size_t size() const noexcept { return size_ < N ? size_ : N; }
  [[nodiscard]] constexpr bool empty() const noexcept { return size() == 0; }
  // Whether the count the bytes hold is one this type could have written
  // (at most N): false for a damaged or forged message, which the
  // accessors still read within N.
  [[nodiscard]] constexpr bool valid() const noexcept { return size_ <= N; }
  [[nodiscard]] static constexpr std::size_t capacity() noexcept { return N; }
  // Where the count and the values lie: for tools that read the bytes of a
  // message whose type they never saw (prime::schema_of).
  [[nodiscard]] static constexpr std::size_t size_offset() noexcept { return offsetof(bounded_vector, size_); }
  [[nodiscard]] static constexpr std::size_t data_offset() noexcept { return offsetof(bounded_vector, items_); }
  [[nodiscard]] constexpr T* data() noexcept { return items_.data(); }
  [[nodiscard]] constexpr const T* data() const noexcept { return items_.data(); }
  // Unchecked, as std::vector's: i < size() is the caller's.
  [[nodiscard]] constexpr T& operator[](std::size_t i) noexcept { return items_[i]; }
  [[nodiscard]] constexpr const T& operator[](std::size_t i) const noexcept { return items_[i]; }
  [[nodiscard]] constexpr iterator begin() noexcept { return data(); }
  [[nodiscard]] constexpr iterator end() noexcept { return data() + size(); }
  [[nodiscard]] constexpr const_iterator begin() const noexcept { return data(); }
  [[nodiscard]] constexpr const_iterator end() const noexcept { return data() + size(); }
  [[nodiscard]] constexpr std::span<T> span() noexcept { return {data(), size()}; }
  [[nodiscard]] constexpr std::span<const T> span() const noexcept { return {data(), size()}; }

  friend constexpr bool operator==(const bounded_vector& a, const bounded_vector& b) {
    return std::equal(a.begin(), a.end(), b.begin(), b.end());
  }

 private:
  static Failure overflow(std::size_t n) {
    return Failure{{Errc::too_large, "bounded_vector<" + std::to_string(N) + ">: " + std::to_string(n) +
                                              " values do not fit"}};
  }

  std::size_t size_ = 0;
  std::array<T, N> items_;  // not zeroed: a 4 MiB image loaned in shared memory must not cost a memset
};

}  // namespace prime
