#pragma once

#include <algorithm>
#include <compare>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "prime/logic/error.hpp"

namespace prime {

// Text of at most N characters stored inline, so a message that holds it
// stays trivially copyable and can live in shared memory or travel as bytes.
// Its accessors never reach past N, whatever count the bytes hold: a message
// another process wrote (in shared memory, through Redis) is read as safely
// as one made here. There is no c_str(): text of another process need not
// end in a NUL; view() and str() know where it ends.
template <std::size_t N>
class bounded_string {
  static_assert(N > 0 && N < UINT32_MAX, "bounded_string: capacity must be in [1, 2^32)");

 public:
  constexpr bounded_string() noexcept = default;
  // Throws Failure{too_large} when `text` is longer than N.
  constexpr bounded_string(std::string_view text) { assign(text); }  // NOLINT: converts like std::string

  constexpr bounded_string& operator=(std::string_view text) {
    assign(text);
    return *this;
  }

  constexpr void assign(std::string_view text) {
    if (text.size() > N)
      throw Failure{{Errc::too_large, "bounded_string<" + std::to_string(N) + ">: text of " +
                                               std::to_string(text.size()) + " characters does not fit"}};
    std::copy(text.begin(), text.end(), data_);
    size_ = static_cast<std::uint32_t>(text.size());
    data_[size_] = '\0';
  }

  [[nodiscard]] constexpr std::string_view view() const noexcept { return {data_, size()}; }
  // The count the bytes hold, within N.
  [[nodiscard]] constexpr std::size_t size() const noexcept { return size_ < N ? size_ : N; }
  [[nodiscard]] constexpr bool empty() const noexcept { return size() == 0; }
  // Whether the count the bytes hold is one this type could have written
  // (at most N, the text ending in a NUL): false for a damaged or forged
  // message, which the accessors still read within N.
  [[nodiscard]] constexpr bool valid() const noexcept { return size_ <= N && data_[size_] == '\0'; }
  [[nodiscard]] static constexpr std::size_t capacity() noexcept { return N; }
  // Where the count and the characters lie: for tools that read the bytes
  // of a message whose type they never saw (prime::schema_of).
  [[nodiscard]] static constexpr std::size_t size_offset() noexcept { return offsetof(bounded_string, size_); }
  [[nodiscard]] static constexpr std::size_t data_offset() noexcept { return offsetof(bounded_string, data_); }
  [[nodiscard]] std::string str() const { return std::string{view()}; }
  constexpr operator std::string_view() const noexcept { return view(); }  // NOLINT

  friend constexpr bool operator==(const bounded_string& a, const bounded_string& b) noexcept {
    return a.view() == b.view();
  }
  friend constexpr bool operator==(const bounded_string& a, std::string_view b) noexcept { return a.view() == b; }
  friend constexpr auto operator<=>(const bounded_string& a, const bounded_string& b) noexcept {
    return a.view() <=> b.view();
  }

 private:
  std::uint32_t size_ = 0;
  char data_[N + 1]{};
};

}  // namespace prime
