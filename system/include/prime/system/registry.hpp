#pragma once

#include <map>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "prime/system/component.hpp"

namespace prime::system {

// The components a program (or a library it loads) can host, by type name.
// Thread-safe.
class Registry {
 public:
  // The program's registry, which PRIME_COMPONENT fills as it starts (or as
  // a shared library of components is loaded).
  static Registry& global();

  // Throws Errc::in_use when a component of that type is registered already.
  void add(Component component);
  // As add, for PRIME_COMPONENT (as a program starts or a library loads,
  // where nothing may throw): what goes wrong is kept for problems().
  bool declare(Component component) noexcept;
  // What declare() could not register, in words.
  [[nodiscard]] std::vector<std::string> problems() const;
  // nullptr when none is.
  [[nodiscard]] const Component* find(std::string_view type) const;
  [[nodiscard]] std::vector<const Component*> components() const;

 private:
  mutable std::mutex mutex_;
  std::map<std::string, Component, std::less<>> components_;  // never erased: pointers into it stay valid
  std::vector<std::string> problems_;
};

}  // namespace prime::system

#define PRIME_SYSTEM_CONCAT2(a, b) a##b
#define PRIME_SYSTEM_CONCAT(a, b) PRIME_SYSTEM_CONCAT2(a, b)

// Registers a component with the program's registry as it starts:
//   PRIME_COMPONENT(robot::planner());
#define PRIME_COMPONENT(...)                                                \
  [[maybe_unused]] static const bool PRIME_SYSTEM_CONCAT(prime_component_, __COUNTER__) = \
      ::prime::system::Registry::global().declare(__VA_ARGS__)
