#pragma once

#include <gtest/gtest.h>

#include <string>
#include <string_view>

#include "prime/logic/error.hpp"

namespace prime::test {

// Whether `action` throws a prime::Failure with `code` whose message mentions
// `mentions`: errors must say what went wrong and where.
template <class F>
::testing::AssertionResult fails_with(F&& action, Errc code, std::string_view mentions) {
  try {
    action();
  } catch (const Failure& f) {
    if (f.error().code != code)
      return ::testing::AssertionFailure() << "failed with " << to_string(f.error().code) << ": " << f.what();
    if (std::string_view{f.what()}.find(mentions) == std::string_view::npos)
      return ::testing::AssertionFailure() << "the message does not mention '" << mentions << "': " << f.what();
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure() << "no prime::Failure was thrown";
}

}  // namespace prime::test
