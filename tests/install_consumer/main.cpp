#include <prime/liberty.hpp>

int main() {
  prime::liberty::Core core;
  auto add = core.chain([](int x) { return x + 1; }) | core.chain([](int x) { return x * 2; });
  return add(20) == 42 ? 0 : 1;
}
