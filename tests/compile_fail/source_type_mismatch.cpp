// Must not compile: a source of std::string linked to a chain taking an int.
// CTest expects the compiler to fail with Prime's own message.
#include <string>

#include "prime/liberty.hpp"

int main() {
  prime::liberty::Core core;
  prime::Event<std::string> names;
  auto twice = core.chain([](int x) { return 2 * x; });
  auto broken = core.source(names, "names") | twice;
  return 0;
}
