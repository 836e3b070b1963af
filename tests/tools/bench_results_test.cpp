// What `prime bench` compares against: the throughput floor is whichever SPSC
// ring depth moved more in the run.
#include <gtest/gtest.h>

#include "bench/results.hpp"

namespace {

using prime::tool::bench::Figure;
using prime::tool::bench::Results;
using prime::tool::bench::fastest_spsc_floor;

Figure rate(const std::string& who, double per_second) { return {who, "throughput", 64, "rate", per_second, "msgs/s"}; }

TEST(BenchResults, TheFloorIsTheDeepRingWhereItMovesMore) {
  const Results r{{rate("SpscFloor", 180e6), rate("SpscFloor256", 96e6)}, {}};
  EXPECT_EQ(fastest_spsc_floor(r), "SpscFloor");
}

TEST(BenchResults, TheFloorIsTheShallowRingWhereItMovesMore) {
  const Results r{{rate("SpscFloor", 78e6), rate("SpscFloor256", 230e6)}, {}};
  EXPECT_EQ(fastest_spsc_floor(r), "SpscFloor256");
}

TEST(BenchResults, TheFloorIsTheOneRingMeasuredWhenTheOtherIsMissing) {
  EXPECT_EQ(fastest_spsc_floor(Results{{rate("SpscFloor256", 1e6)}, {}}), "SpscFloor256");
  EXPECT_EQ(fastest_spsc_floor(Results{{rate("SpscFloor", 1e6)}, {}}), "SpscFloor");
  // Another scenario's or payload's figure is not a throughput floor at 64 B.
  const Results elsewhere{{{"SpscFloor256", "throughput", 1 << 20, "rate", 9e9, "msgs/s"}, rate("SpscFloor", 1e6)}, {}};
  EXPECT_EQ(fastest_spsc_floor(elsewhere), "SpscFloor");
}

}  // namespace
