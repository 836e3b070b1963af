#pragma once

#include <atomic>

namespace prime::test {

// A message that counts how it is made and unmade, to prove data moves
// through a topology without copies and nothing leaks.
struct Lifetime {
  static inline std::atomic<int> copies{0};
  static inline std::atomic<int> moves{0};
  static inline std::atomic<int> alive{0};
  static void reset() {
    copies = 0;
    moves = 0;
  }

  int value = 0;

  explicit Lifetime(int v = 0) : value{v} { ++alive; }
  Lifetime(const Lifetime& other) : value{other.value} {
    ++copies;
    ++alive;
  }
  Lifetime(Lifetime&& other) noexcept : value{other.value} {
    ++moves;
    ++alive;
  }
  Lifetime& operator=(const Lifetime& other) {
    value = other.value;
    ++copies;
    return *this;
  }
  Lifetime& operator=(Lifetime&& other) noexcept {
    value = other.value;
    ++moves;
    return *this;
  }
  ~Lifetime() { --alive; }
};

}  // namespace prime::test
