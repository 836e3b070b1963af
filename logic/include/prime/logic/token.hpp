#pragma once

namespace prime {

// The input of a chain that needs no data, only a trigger: a collector is a
// Chain<Token, T> that answers "what is the latest value?" when called.
struct Token {
  friend constexpr bool operator==(Token, Token) noexcept = default;
};

}  // namespace prime
