// Must not compile: a chain giving std::string linked to one taking a double.
// CTest expects the compiler to fail with Prime's own message.
#include <string>

#include "prime/liberty.hpp"

int main() {
  prime::liberty::Core core;
  auto name = core.chain([](int x) { return std::to_string(x); });
  auto half = core.chain([](double x) { return x / 2; });
  auto broken = name | half;
  return static_cast<int>(broken(1));
}
