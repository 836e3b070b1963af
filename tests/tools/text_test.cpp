// What `prime pub` and `prime call` read from the command line (JSON) and
// what `prime graph` writes (DOT labels), from text alone.
#include <gtest/gtest.h>

#include <string>

#include "dot.hpp"
#include "json.hpp"

namespace prime::tool {
namespace {

std::string string_of(const std::string& json) { return std::get<std::string>(parse_json(json).value); }

TEST(Json, EscapesInAStringAreTheCharactersTheyStandFor) {
  EXPECT_EQ(string_of(R"("a\nb\tc")"), "a\nb\tc");
  EXPECT_EQ(string_of(R"("say \"hi\" \\ /")"), "say \"hi\" \\ /");
  EXPECT_EQ(string_of(R"("caf\u00e9")"), "caf\xc3\xa9");
  EXPECT_EQ(string_of(R"("\ud83e\udd16")"), "\xf0\x9f\xa4\x96") << "a surrogate pair is one code point";
  EXPECT_THROW((void)parse_json(R"("\u12")"), std::invalid_argument);
}

TEST(Dot, ALabelsLinesAreJoinedByALineBreakAndEachIsEscaped) {
  EXPECT_EQ(dot_label({"planner", "Path -> Pose"}), R"("planner\nPath -> Pose")");
  EXPECT_EQ(dot_label({"a \"quoted\" name"}), R"("a \"quoted\" name")");
}

}  // namespace
}  // namespace prime::tool
