#pragma once

#include <gtest/gtest.h>

#include <string>

namespace prime::test {

// A fixture for a test that runs twice: ".../counted" proves what it proves
// by counts alone, ".../timed" also compares two speeds. Timed instances
// carry the label `timing` (tests/CMakeLists.txt), which the sanitizer runs
// skip: a sanitizer's slowdown is its own, not the code's. Instantiate with
//   INSTANTIATE_TEST_SUITE_P(Prefix, Fixture, ::testing::Bool(), counted_or_timed);
class CountedAndTimed : public ::testing::TestWithParam<bool> {
 protected:
  static bool timed() { return GetParam(); }
};

inline std::string counted_or_timed(const ::testing::TestParamInfo<bool>& info) {
  return info.param ? "timed" : "counted";
}

}  // namespace prime::test
