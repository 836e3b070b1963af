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
// Text that every medium carries, shared memory too.
using Text = bounded_string<16>;
Text show(const int& x) { return Text{std::to_string(x)}; }

template <class M>
class ChainTest : public MediumTest<M> {
 protected:
  void SetUp() override {
    if constexpr (chains_are_another_mediums<M>() != nullptr) GTEST_SKIP() << chains_are_another_mediums<M>();
  }
};
// Chains come from this->chain(...): the medium's own (on Shm, a service).
TYPED_TEST_SUITE(ChainTest, Media, MediumName);

TYPED_TEST(ChainTest, FunctionLambdaAndFunctorAreBlocks) {
  EXPECT_EQ(this->chain(twice)(4), 8);
  EXPECT_EQ(this->chain([](double x) { return x / 2; })(3.0), 1.5);
  EXPECT_EQ(this->chain(AddOne{})(1), 2);
  EXPECT_EQ(this->template chain<int>([](auto x) { return x * 10; })(3), 30);  // generic: input named
}

TYPED_TEST(ChainTest, LinkedChainsRunInOrderAndChangeType) {
  auto pipeline = this->chain(twice) | this->chain(AddOne{}) | this->chain(show);
  static_assert(std::same_as<typename decltype(pipeline)::input_type, int>);
  static_assert(std::same_as<typename decltype(pipeline)::output_type, Text>);
  EXPECT_EQ(pipeline(5), "11");
}

TYPED_TEST(ChainTest, LinkedChainsAreOfTheMediumsOwnKind) {
  using One = decltype(this->chain(twice));
  using Two = decltype(this->chain(twice) | this->chain(twice));
  static_assert(!std::same_as<Two, Linked<One, One>>, "a medium links its own chains, not the generic link");
  if constexpr (std::same_as<TypeParam, liberty::Core>) static_assert(std::same_as<One, Two>, "liberty: linking keeps the erased type");
  SUCCEED();
}

TYPED_TEST(ChainTest, ChainsOfDifferentMediaLinkThroughTheGenericLink) {
  liberty::Core other;
  auto mixed = this->chain(twice) | other.chain(AddOne{}) | this->chain(twice);
  EXPECT_EQ(mixed(3), 14);
  EXPECT_NE(mixed.graph().text().find("liberty"), std::string::npos);
}

TYPED_TEST(ChainTest, ExceptionFromABlockReachesTheCaller) {
  auto failing = this->chain(twice) | this->chain([](int x) -> int {
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
  auto guarded = if_then_else(core, [](const int& x) { return x >= 0; }, this->chain(twice),
                              this->chain([](int x) { return -x * 100; }));
  EXPECT_EQ(guarded(4), 8);
  EXPECT_EQ(guarded(-2), 200);
}

TYPED_TEST(ChainTest, ForeachMapsAChainOverEveryElement) {
  auto& core = *this->core;
  auto each = foreach(core, this->chain(twice) | this->chain(show));
  EXPECT_EQ(each({1, 2, 3}), (std::vector<Text>{Text{"2"}, Text{"4"}, Text{"6"}}));
  EXPECT_TRUE(each({}).empty());
}

TYPED_TEST(ChainTest, RepeatIteratesUntilTheCondition) {
  auto& core = *this->core;
  auto grow = repeat(core, this->chain(twice), [](const int& x) { return x > 100; });
  EXPECT_EQ(grow(1), 128);
  EXPECT_EQ(grow(1000), 2000) << "the body runs at least once";
}

TYPED_TEST(ChainTest, RepeatThatNeverEndsIsAnErrorNotAHang) {
  auto& core = *this->core;
  auto stuck = repeat(core, this->chain([](int x) { return x; }), [](const int&) { return false; },
                      RepeatLimits{.max_iterations = 1000});
  EXPECT_TRUE(fails_with([&] { (void)stuck(1); }, Errc::iteration_limit, "1000 iterations"));
}

TYPED_TEST(ChainTest, ARepeatAllowedNoIterationIsRefusedByName) {
  auto& core = *this->core;
  EXPECT_TRUE(fails_with([&] { (void)repeat(core, this->chain(twice), [](const int&) { return true; }, RepeatLimits{.max_iterations = 0}, "grow"); },
                         Errc::invalid_argument, "repeat 'grow': max_iterations must be at least 1"));
}

TYPED_TEST(ChainTest, ForkTeesEveryOutputIntoASource) {
  auto& core = *this->core;
  auto [teed, outputs] = fork(core, this->chain(twice), "doubled");
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
    auto step = [](Lifetime m) {
      ++m.value;
      return m;
    };
    auto one = this->chain(step);
    auto ten = one | one | one | one | one | one | one | one | one | one;
    Lifetime::reset();
    EXPECT_EQ(ten(Lifetime{0}).value, 10);
    EXPECT_EQ(Lifetime::copies, 0);
  }
}

TYPED_TEST(ChainTest, DescribesItselfAsTextAndDot) {
  auto& core = *this->core;
  auto pipeline = this->chain(twice, "localize") | this->chain(AddOne{}, "plan") | this->chain(show, "control");
  const auto kind = std::string{chain_kind<TypeParam>()} + ", " + std::string{core.medium()};
  EXPECT_EQ(pipeline.graph().text(), "localize [" + kind + "] -> plan [" + kind + "]\nplan [" + kind + "] -> control [" +
                                         kind + "]\n");
  const auto dot = pipeline.graph().dot();
  EXPECT_EQ(dot.rfind("digraph prime {", 0), 0u);
  EXPECT_EQ(std::ranges::count(dot, '>'), 2) << dot;
  EXPECT_NE(dot.find("label=\"plan\\n" + kind + "\""), std::string::npos) << dot;
}

TYPED_TEST(ChainTest, CombinatorsAppearInTheDescription) {
  auto& core = *this->core;
  auto guarded = if_then_else(core, [](const int& x) { return x > 0; }, this->chain(twice, "go"),
                              this->chain(twice, "stop"), "blocked?");
  const auto text = guarded.graph().text();
  EXPECT_NE(text.find("blocked? [branch"), std::string::npos) << text;
  EXPECT_NE(text.find("-> go [" + std::string{chain_kind<TypeParam>()}), std::string::npos) << text;
  EXPECT_NE(text.find("-> stop [" + std::string{chain_kind<TypeParam>()}), std::string::npos) << text;
}

}  // namespace
}  // namespace prime::test
