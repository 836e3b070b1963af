// What `prime pub` and `prime call` read from the command line (JSON), how
// far a type's description reaches, and what `prime graph` writes (DOT
// labels), from text alone.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "dot.hpp"
#include "json.hpp"
#include "message_text.hpp"

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

// What a tool prints as JSON is JSON whatever a message's text holds: each
// byte that is not part of a UTF-8 character is U+FFFD; UTF-8 is kept as it is.
TEST(Json, TextThatIsNotUtf8IsQuotedAsJsonWithEachStrayByteReplaced) {
  EXPECT_EQ(quote("caf\xc3\xa9 \xf0\x9f\xa4\x96"), "\"caf\xc3\xa9 \xf0\x9f\xa4\x96\"");
  EXPECT_EQ(quote("caf\xe9"), R"("caf\ufffd")") << "Latin-1";
  EXPECT_EQ(quote("\x80x\xff"), R"("\ufffdx\ufffd")") << "stray bytes";
  EXPECT_EQ(quote("\xc3"), R"("\ufffd")") << "a character cut short";
  EXPECT_EQ(quote("\xc0\xaf"), R"("\ufffd\ufffd")") << "an overlong '/'";
  EXPECT_EQ(quote("\xed\xa0\x80"), R"("\ufffd\ufffd\ufffd")") << "a surrogate";
  EXPECT_EQ(quote("\xf4\x90\x80\x80"), R"("\ufffd\ufffd\ufffd\ufffd")") << "past U+10FFFF";
  EXPECT_EQ(string_of(quote("a\xff" "b\n\"")), "a\xef\xbf\xbd" "b\n\"") << "and it reads back";
}

TEST(Dot, ALabelsLinesAreJoinedByALineBreakAndEachIsEscaped) {
  EXPECT_EQ(dot_label({"planner", "Path -> Pose"}), R"("planner\nPath -> Pose")");
  EXPECT_EQ(dot_label({"a \"quoted\" name"}), R"("a \"quoted\" name")");
}

// How far a description reaches into a message: what a damaged or foreign
// one is checked by before a tool reads or writes by it.
TEST(MessageText, ADescriptionReachesAsFarAsItsFarthestField) {
  EXPECT_EQ(extent(*parse_layout("{x@0:f64,y@8:f64,n@16:u32}")), 20u);
  EXPECT_EQ(extent(*parse_layout("{frame@8:str16@0,4}")), 29u) << "sixteen characters and a '\\0'";
  EXPECT_EQ(extent(*parse_layout("{far@4096:f64}")), 4104u) << "wherever the text says";
  EXPECT_EQ(extent(*parse_layout("{v@0:vec4@0,8,4(f64)}")), ~std::size_t{0}) << "an element wider than its stride";
  EXPECT_EQ(extent(*parse_layout("{a@0:arr18446744073709551615,8(f64)}")), ~std::size_t{0}) << "no wrap-around";
}

// A number given for a field of an integer type is a whole number within
// its range, or an error naming the field, the number and the range.
TEST(MessageText, ANumberOutsideItsFieldsRangeIsRefusedByName) {
  const auto layout = parse_layout("{level@0:u8,offset@8:i64}");
  std::vector<std::byte> bytes(16);
  auto fill_with = [&](const std::string& json) { fill(*layout, bytes.data(), parse_json(json)); };
  EXPECT_NO_THROW(fill_with(R"({"level": 255, "offset": -3})"));
  EXPECT_EQ(static_cast<int>(bytes[0]), 255);
  try {
    fill_with(R"({"level": 300})");
    ADD_FAILURE() << "300 went into a u8";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string{e.what()}.find("level: 300 is not a whole number from 0 to 255 (u8)"), std::string::npos) << e.what();
  }
  EXPECT_THROW(fill_with(R"({"level": -1})"), std::invalid_argument);
  EXPECT_THROW(fill_with(R"({"level": 1.5})"), std::invalid_argument);
  EXPECT_THROW(fill_with(R"({"offset": 1e30})"), std::invalid_argument);
}

}  // namespace
}  // namespace prime::tool
