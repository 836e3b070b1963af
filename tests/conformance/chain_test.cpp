// Synchronous chains: every behaviour written once, run on every medium.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "conformance/media.hpp"
#include "support/failure.hpp"
#include "support/lifetime.hpp"

namespace prime::test {
namespace {

int twice(int x) { return 2 * x; }
struct AddOne {
  int operator()(int x) const { return x + 1; }
};
std::string show(const int& x) { return std::to_string(x); }

template <class M>
class ChainTest : public MediumTest<M> {
 protected:
  void SetUp() override {
    if constexpr (chains_are_another_mediums<M>() != nullptr) GTEST_SKIP() << chains_are_another_mediums<M>();
  }
};
TYPED_TEST_SUITE(ChainTest, Media, MediumName);

TYPED_TEST(ChainTest, FunctionLambdaAndFunctorAreBlocks) {
  auto& core = *this->core;
  EXPECT_EQ(core.chain(twice)(4), 8);
  EXPECT_EQ(core.chain([](double x) { return x / 2; })(3.0), 1.5);
  EXPECT_EQ(core.chain(AddOne{})(1), 2);
  EXPECT_EQ(core.template chain<int>([](auto x) { return x * 10; })(3), 30);  // generic: input named
}

TYPED_TEST(ChainTest, LinkedChainsRunInOrderAndChangeType) {
  auto& core = *this->core;
  auto pipeline = core.chain(twice) | core.chain(AddOne{}) | core.chain(show);
  static_assert(std::same_as<typename decltype(pipeline)::input_type, int>);
  static_assert(std::same_as<typename decltype(pipeline)::output_type, std::string>);
  EXPECT_EQ(pipeline(5), "11");
}

TYPED_TEST(ChainTest, LinkedChainsAreOfTheMediumsOwnKind) {
  auto& core = *this->core;
  using One = decltype(core.chain(twice));
  using Two = decltype(core.chain(twice) | core.chain(twice));
  static_assert(!std::same_as<Two, Linked<One, One>>, "a medium links its own chains, not the generic link");
  if constexpr (std::same_as<TypeParam, liberty::Core>) static_assert(std::same_as<One, Two>, "liberty: linking keeps the erased type");
  SUCCEED();
}

TYPED_TEST(ChainTest, ChainsOfDifferentMediaLinkThroughTheGenericLink) {
  liberty::Core other;
  auto mixed = this->core->chain(twice) | other.chain(AddOne{}) | this->core->chain(twice);
  EXPECT_EQ(mixed(3), 14);
  EXPECT_NE(mixed.graph().text().find("liberty"), std::string::npos);
}

TYPED_TEST(ChainTest, ExceptionFromABlockReachesTheCaller) {
  auto& core = *this->core;
  auto failing = core.chain(twice) | core.chain([](int x) -> int {
                   if (x > 10) throw std::domain_error{"too far"};
                   return x;
                 });
  EXPECT_EQ(failing(5), 10);
  if constexpr (passes_objects_in_place<TypeParam>()) {
    EXPECT_THROW((void)failing(6), std::domain_error);
  } else {  // the exception crossed a process boundary: its message and a code remain
    EXPECT_TRUE(fails_with([&] { (void)failing(6); }, Errc::block_failed, "too far"));
  }
  EXPECT_EQ(failing(1), 2) << "a chain that threw once keeps working";
}

TYPED_TEST(ChainTest, IfThenElseRunsOneOfTwoChains) {
  auto& core = *this->core;
  auto guarded = if_then_else(core, [](const int& x) { return x >= 0; }, core.chain(twice),
                              core.chain([](int x) { return -x * 100; }));
  EXPECT_EQ(guarded(4), 8);
  EXPECT_EQ(guarded(-2), 200);
}

TYPED_TEST(ChainTest, ForeachMapsAChainOverEveryElement) {
  auto& core = *this->core;
  auto each = foreach(core, core.chain(twice) | core.chain(show));
  EXPECT_EQ(each({1, 2, 3}), (std::vector<std::string>{"2", "4", "6"}));
  EXPECT_TRUE(each({}).empty());
}

TYPED_TEST(ChainTest, RepeatIteratesUntilTheCondition) {
  auto& core = *this->core;
  auto grow = repeat(core, core.chain(twice), [](const int& x) { return x > 100; });
  EXPECT_EQ(grow(1), 128);
  EXPECT_EQ(grow(1000), 2000) << "the body runs at least once";
}

TYPED_TEST(ChainTest, RepeatThatNeverEndsIsAnErrorNotAHang) {
  auto& core = *this->core;
  auto stuck = repeat(core, core.chain([](int x) { return x; }), [](const int&) { return false; },
                      RepeatLimits{.max_iterations = 1000});
  EXPECT_TRUE(fails_with([&] { (void)stuck(1); }, Errc::limit_exceeded, "1000 iterations"));
}

TYPED_TEST(ChainTest, ForkTeesEveryOutputIntoASource) {
  auto& core = *this->core;
  auto [teed, outputs] = fork(core, core.chain(twice), "doubled");
  auto watcher = outputs.subscribe();
  EXPECT_EQ(teed(1), 2);
  EXPECT_EQ(teed(5), 10);
  auto seen = watcher.read_all();
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_EQ(seen[0].value, 2);
  EXPECT_EQ(seen[1].value, 10);
}

TYPED_TEST(ChainTest, ChainsMoveTheirMessageWithoutCopying) {
  if constexpr (!passes_objects_in_place<TypeParam>()) {
    GTEST_SKIP() << "this medium serialises messages: there are no copies of the object to count";
  } else {
    auto& core = *this->core;
    auto step = [](Lifetime m) {
      ++m.value;
      return m;
    };
    auto one = core.chain(step);
    auto ten = one | one | one | one | one | one | one | one | one | one;
    Lifetime::reset();
    EXPECT_EQ(ten(Lifetime{0}).value, 10);
    EXPECT_EQ(Lifetime::copies, 0);
  }
}

TYPED_TEST(ChainTest, DescribesItselfAsTextAndDot) {
  auto& core = *this->core;
  auto pipeline = core.chain(twice, "localize") | core.chain(AddOne{}, "plan") | core.chain(show, "control");
  const auto medium = std::string{core.medium()};
  EXPECT_EQ(pipeline.graph().text(), "localize [chain, " + medium + "] -> plan [chain, " + medium +
                                         "]\nplan [chain, " + medium + "] -> control [chain, " + medium + "]\n");
  const auto dot = pipeline.graph().dot();
  EXPECT_EQ(dot.rfind("digraph prime {", 0), 0u);
  EXPECT_EQ(std::ranges::count(dot, '>'), 2) << dot;
  EXPECT_NE(dot.find("label=\"plan\\nchain, " + medium + "\""), std::string::npos) << dot;
}

TYPED_TEST(ChainTest, CombinatorsAppearInTheDescription) {
  auto& core = *this->core;
  auto guarded = if_then_else(core, [](const int& x) { return x > 0; }, core.chain(twice, "go"),
                              core.chain(twice, "stop"), "blocked?");
  const auto text = guarded.graph().text();
  EXPECT_NE(text.find("blocked? [branch"), std::string::npos) << text;
  EXPECT_NE(text.find("-> go [chain"), std::string::npos) << text;
  EXPECT_NE(text.find("-> stop [chain"), std::string::npos) << text;
}

}  // namespace
}  // namespace prime::test
