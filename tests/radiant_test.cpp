// What only Radiant promises: a linked chain is one type the compiler sees
// through, with nothing erased and nothing allocated on the call path.
#include <gtest/gtest.h>

#include <type_traits>

#include "prime/radiant.hpp"

namespace prime::test {
namespace {

TEST(RadiantTest, LinkedBlocksFuseIntoAPlainValueOfTheBlocksThemselves) {
  radiant::Core core;
  auto add = core.chain([](int x) { return x + 1; });
  auto mul = core.chain([](int x) { return x * 3; });
  auto fused = add | mul | add;
  using Fused = std::remove_cvref_t<decltype(fused.block())>;
  static_assert(std::is_trivially_copyable_v<Fused> && !std::is_polymorphic_v<Fused>,
                "the composite holds the blocks themselves: no pointer, no virtual call, no erasure");
  EXPECT_EQ(fused(1), 7);
}

TEST(RadiantTest, AFusedChainIsAConstantExpressionWhenItsBlocksAre) {
  constexpr auto inc = [](int x) { return x + 1; };
  constexpr radiant::detail::Fused<decltype(inc), decltype(inc)> twice_inc{inc, inc};
  static_assert(twice_inc(40) == 42, "the composition is visible to the compiler");
  SUCCEED();
}

}  // namespace
}  // namespace prime::test
