// What `prime bench` compares against: the throughput floor is whichever SPSC
// ring depth moved more in the run; and how far a comparison moved from
// round to round.
#include <gtest/gtest.h>

#include "bench/results.hpp"

namespace {

using prime::tool::bench::Figure;
using prime::tool::bench::Results;
using prime::tool::bench::fastest_spsc_floor;
using prime::tool::bench::is_floor;
using prime::tool::bench::is_peer;
using prime::tool::bench::Measure;
using prime::tool::bench::range_over;

Figure rate(const std::string& who, double per_second) { return {who, "throughput", 64, "rate", per_second, "msgs/s"}; }

TEST(BenchResults, TheFloorIsTheDeepRingWhereItMovesMore) {
  const Results r{{rate("SpscFloor", 180e6), rate("SpscFloor256", 96e6)}, {}};
  EXPECT_EQ(fastest_spsc_floor(r), "SpscFloor");
}

TEST(BenchResults, TheFloorIsTheShallowRingWhereItMovesMore) {
  const Results r{{rate("SpscFloor", 78e6), rate("SpscFloor256", 230e6)}, {}};
  EXPECT_EQ(fastest_spsc_floor(r), "SpscFloor256");
}

// A ring carrying a header with each payload is a floor for its layout: not
// a peer Shm is ranked against, nor the floor the ratios are to, even where
// it moves more than the plain rings.
TEST(BenchResults, RingsOfOtherLayoutsAreFloorsButNeverTheFloor) {
  for (const auto* who : {"SpscInline", "SpscRecords", "SpscRecordsHeaders", "SpscShmLayout"}) {
    EXPECT_TRUE(is_floor(who)) << who;
    EXPECT_FALSE(is_peer(who)) << who;
  }
  EXPECT_TRUE(is_peer("Iceoryx"));
  const Results r{{rate("SpscFloor", 70e6), rate("SpscFloor256", 60e6), rate("SpscRecords", 250e6)}, {}};
  EXPECT_EQ(fastest_spsc_floor(r), "SpscFloor");
}

TEST(BenchResults, TheFloorIsTheOneRingMeasuredWhenTheOtherIsMissing) {
  EXPECT_EQ(fastest_spsc_floor(Results{{rate("SpscFloor256", 1e6)}, {}}), "SpscFloor256");
  EXPECT_EQ(fastest_spsc_floor(Results{{rate("SpscFloor", 1e6)}, {}}), "SpscFloor");
  // Another scenario's or payload's figure is not a throughput floor at 64 B.
  const Results elsewhere{{{"SpscFloor256", "throughput", 1 << 20, "rate", 9e9, "msgs/s"}, rate("SpscFloor", 1e6)}, {}};
  EXPECT_EQ(fastest_spsc_floor(elsewhere), "SpscFloor");
}

// Shm's rate over the floor's, as the headline works it out.
const Measure kShmOverFloor = [](const Results& r) -> std::optional<double> {
  const auto shm = r.find("Shm", "throughput", 64, "rate");
  const auto floor = r.find("SpscFloor256", "throughput", 64, "rate");
  if (!shm || !floor) return std::nullopt;
  return *shm / *floor;
};

TEST(BenchResults, ARatiosRangeIsTakenRoundByRoundNotFromEachFiguresOwnRange) {
  // The floor swings 4x with the machine's state and Shm with it: round by
  // round the ratio stays near 0.2, where the figures' own extremes would
  // give 0.05 to 0.8.
  const std::vector<Results> rounds{{{rate("Shm", 50e6), rate("SpscFloor256", 240e6)}, {}},
                                    {{rate("Shm", 12e6), rate("SpscFloor256", 60e6)}, {}},
                                    {{rate("Shm", 13e6), rate("SpscFloor256", 62e6)}, {}}};
  const auto range = range_over(rounds, kShmOverFloor);
  ASSERT_TRUE(range);
  EXPECT_DOUBLE_EQ(range->low, 0.2);
  EXPECT_NEAR(range->high, 13.0 / 62, 1e-12);
  EXPECT_FALSE(range->unsteady());
}

TEST(BenchResults, ARatioThatMovedWithTheMachinesStateIsUnsteady) {
  // Shm held its rate while the floor fell 4x: the ratio holds for one state only.
  const std::vector<Results> rounds{{{rate("Shm", 40e6), rate("SpscFloor256", 240e6)}, {}},
                                    {{rate("Shm", 36e6), rate("SpscFloor256", 60e6)}, {}}};
  const auto range = range_over(rounds, kShmOverFloor);
  ASSERT_TRUE(range);
  EXPECT_NEAR(range->low, 40.0 / 240, 1e-12);
  EXPECT_DOUBLE_EQ(range->high, 0.6);
  EXPECT_TRUE(range->unsteady());
}

TEST(BenchResults, ARatioHasNoRangeFromFewerThanTwoRoundsThatGiveIt) {
  // A quick run has one round; a round missing either figure gives no ratio.
  EXPECT_FALSE(range_over({{{rate("Shm", 1e6), rate("SpscFloor256", 2e6)}, {}}}, kShmOverFloor));
  EXPECT_FALSE(range_over({{{rate("Shm", 1e6), rate("SpscFloor256", 2e6)}, {}}, {{rate("Shm", 1e6)}, {}}},
                          kShmOverFloor));
}

}  // namespace
