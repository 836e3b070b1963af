// What only Liberty promises: topologies assembled while the program runs.
#include <gtest/gtest.h>

#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "prime/liberty.hpp"
#include "support/lifetime.hpp"

namespace prime::test {
namespace {

TEST(LibertyTest, AChainIsAssembledFromAConfigAtRunTime) {
  liberty::Core core;
  const std::map<std::string, liberty::Chain<double, double>> blocks{
      {"scale", core.chain([](double x) { return x * 10; }, "scale")},
      {"offset", core.chain([](double x) { return x + 1; }, "offset")},
      {"clamp", core.chain([](double x) { return std::min(x, 25.0); }, "clamp")},
  };
  std::istringstream config{"offset scale clamp"};
  std::string name;
  config >> name;
  liberty::Chain<double, double> pipeline = blocks.at(name);
  while (config >> name) pipeline = pipeline | blocks.at(name);

  EXPECT_EQ(pipeline(0.5), 15.0);
  EXPECT_EQ(pipeline(2.0), 25.0);
  EXPECT_EQ(pipeline.graph().text(),
            "offset [chain, liberty] -> scale [chain, liberty]\nscale [chain, liberty] -> clamp [chain, liberty]\n");
}

TEST(LibertyTest, LinkingSharesBlocksInsteadOfCopyingThem) {
  liberty::Core core;
  auto counted = std::make_shared<int>(0);
  auto block = core.chain([counted](int x) { return x + *counted; });
  const auto owners = counted.use_count();
  auto longer = block | block | block;
  EXPECT_EQ(counted.use_count(), owners) << "linked chains point at the block, they do not copy it";
  EXPECT_EQ(longer(1), 1);
}

// A hop of a run-time chain costs what a hand-written call costs: the
// message moved into the block, out of it, and back into the chain's value
// (Table 1's Liberty row, a Source's linked chain), never a copy and no
// temporary besides.
TEST(LibertyTest, AHopMovesItsMessageInOutAndBackOnly) {
  liberty::Core core;
  auto one = core.chain([](Lifetime m) {
    ++m.value;
    return m;
  });
  auto hundred = one;
  for (int i = 1; i < 100; ++i) hundred = hundred | one;
  Lifetime input{0};
  Lifetime::reset();
  const auto output = hundred(std::move(input));
  EXPECT_EQ(output.value, 100);
  EXPECT_EQ(Lifetime::copies, 0);
  EXPECT_LE(Lifetime::moves, 3 * 100 + 3) << "per hop: in, out and back; and three to enter and leave the chain";
}

// A message that cannot be assigned still links, step after step.
TEST(LibertyTest, AMessageThatCannotBeAssignedStillLinks) {
  struct Fixed {
    const int value;
  };
  liberty::Core core;
  auto one = core.chain([](Fixed m) { return Fixed{m.value + 1}; });
  EXPECT_EQ((one | one | one)(Fixed{1}).value, 4);
}

// A source takes another event while the program runs, and keeps the first.
TEST(LibertyTest, ASourceFedFromASecondEventKeepsTheFirst) {
  liberty::Core core;
  Event<int> left, right;
  auto wheels = core.source(left, "wheels");
  wheels.feed_from(right);
  auto reader = wheels.subscribe();
  left.emit(1);
  right.emit(2);
  left.emit(3);
  std::vector<int> got;
  for (const auto& s : reader.read_all()) got.push_back(s.value);
  EXPECT_EQ(got, (std::vector<int>{1, 2, 3}));
}

}  // namespace
}  // namespace prime::test
