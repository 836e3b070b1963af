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

// The error `text` gets from the JSON reader ("" when it reads it).
std::string json_error(const std::string& text) {
  try {
    (void)parse_json(text);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

// A unicode escape is four hex digits, and a surrogate comes in a pair (a
// high one, then a low one): anything else names where it is.
TEST(Json, AMalformedUnicodeEscapeIsRefusedNamingWhereItIs) {
  EXPECT_NE(json_error(R"("ab\u00g1")").find("four hex digits at character 4"), std::string::npos) << json_error(R"("ab\u00g1")");
  for (const auto* bad : {R"("\u+123")", R"("\u 123")", R"("\u0x12")", R"("\u-001")"})
    EXPECT_NE(json_error(bad).find("four hex digits at character 2"), std::string::npos) << bad << ": " << json_error(bad);
  EXPECT_NE(json_error(R"("\ud83e")").find("a high surrogate without its low one at character 2"), std::string::npos)
      << json_error(R"("\ud83e")");
  EXPECT_NE(json_error(R"("x\ud83e\u0041")").find("a high surrogate without its low one at character 3"), std::string::npos)
      << json_error(R"("x\ud83e\u0041")");
  EXPECT_NE(json_error(R"("\udd16")").find("a low surrogate without a high one at character 2"), std::string::npos)
      << json_error(R"("\udd16")");
  EXPECT_EQ(string_of(R"("\u0041\uD83E\uDD16")"), "A\xf0\x9f\xa4\x96") << "upper-case hex digits";
}

// Nesting is bounded, so no input, however deep, exhausts the stack.
TEST(Json, NestingDeeperThanTheLimitIsRefusedInsteadOfOverflowingTheStack) {
  const auto nested = [](std::size_t depth, char open, char close, const std::string& inner) {
    std::string text;
    for (std::size_t i = 0; i < depth; ++i) text += open == '{' ? std::string{"{\"a\":"} : std::string(1, open);
    return text + inner + std::string(depth, close);
  };
  EXPECT_EQ(json_error(nested(64, '[', ']', "1")), "");
  EXPECT_EQ(json_error(nested(64, '{', '}', "1")), "");
  EXPECT_NE(json_error(nested(65, '[', ']', "1")).find("nested more than 64 deep at character 65"), std::string::npos)
      << json_error(nested(65, '[', ']', "1"));
  EXPECT_NE(json_error(nested(65, '{', '}', "1")).find("nested more than 64 deep"), std::string::npos);
  EXPECT_NE(json_error(std::string(131000, '[')).find("nested more than 64 deep"), std::string::npos);
}

// A number is JSON's: no hex, no infinity, no leading '+' or zero, no
// text after it, none out of a double's range.
TEST(Json, ANumberIsAJsonNumberAndNothingAfterIt) {
  EXPECT_EQ(std::get<double>(parse_json("-12.5e1").value), -125);
  for (const auto* bad : {"5m", "0x10", "+1", "01", ".5", "1.", "1e", "nan", "inf", "-"})
    EXPECT_NE(json_error(bad), "") << bad;
  EXPECT_NE(json_error("1e999").find("a number out of range at character 1"), std::string::npos) << json_error("1e999");
}

// field=value words: a value that is not JSON is text, and text is a
// number only when all of it is one.
TEST(MessageText, TextAfterANumberIsRefusedNotCutOff) {
  const auto layout = parse_layout("{x@0:f64,n@8:i32}");
  std::vector<std::byte> bytes(16);
  auto fill_with = [&](std::vector<std::string> words) { fill(*layout, bytes.data(), from_assignments(words)); };
  try {
    fill_with({"x=5m"});
    ADD_FAILURE() << "x=5m was taken as 5";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string{e.what()}.find("x: expected a number, not \"5m\""), std::string::npos) << e.what();
  }
  EXPECT_THROW(fill_with({"n=1_000"}), std::invalid_argument);
  EXPECT_THROW(fill_with({"x=1e999"}), std::invalid_argument);
  EXPECT_THROW(fill_with({"x=0x10"}), std::invalid_argument);
  EXPECT_NO_THROW(fill_with({"x=nan"})) << "a float may be nan, written as text";
  EXPECT_THROW(fill_with({"n=nan"}), std::invalid_argument);
  try {
    fill_with({"x=[1,"});
    ADD_FAILURE() << "a broken list was taken as text";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string{e.what()}.find("x: JSON: unexpected end"), std::string::npos) << e.what();
  }
}

// The error a description gets against a message of `size` bytes ("" when it passes).
std::string description_error(const std::string& description, std::size_t size) {
  try {
    (void)parse_layout(description, size);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// A description comes from shared memory: whatever another program wrote
// there, every count and extent is bounded by the message, or the
// description is refused naming the field, never read by.
TEST(MessageText, ADescriptionWhoseCountsDoNotFitItsMessageIsRefusedNamingTheField) {
  EXPECT_EQ(description_error("{x@0:f64,v@8:vec4@0,8,8(f64),a@48:arr2,8(f64)}", 64), "");
  const auto names = [&](const std::string& description, std::size_t size, const std::string& what) {
    const auto error = description_error(description, size);
    EXPECT_NE(error.find(what), std::string::npos) << description << ": " << error;
  };
  names("{a@0:arr18446744073709551615,0(u8)}", 16, "field 'a': a stride of 0");
  names("{a@0:arr18446744073709551615,1(u8)}", 16, "field 'a': 18446744073709551615 elements of 1 bytes do not fit in 16");
  names("{a@0:arr3074457345618258603,6(u8)}", 16, "field 'a'");
  names("{p@0:{q@8:vec1000@0,8,8(f64)}}", 64, "field 'p.q': 1000 elements of 8 bytes do not fit in 48");
  names("{a@0:arr4,4(f64)}", 64, "field 'a[]': 8 bytes do not fit in 4");
  names("{far@100:f64}", 64, "field 'far': offset 100 is past the 64 bytes of its record");
  names("{s@0:str100@0,4}", 64, "field 's': 100 characters do not fit");
  names("{a@0:arr18446744073709551616,8(f64)}", 64, "a number too large");
  names("{a@0:arr8,1(arr8,1(arr8,1(u8)))}", 64, "field 'a[][]': 8 elements of 1 bytes do not fit in 1");
  // Fields laid over one another in an array of records: each takes no
  // room of its own, and a reader would visit 64 x 200 values of 64 bytes.
  std::string many = "{a@0:arr64,1({";
  for (int i = 0; i < 200; ++i) many += std::string{i ? "," : ""} + "f@0:u8";
  names(many + "})}", 64, "12800 values in 64 bytes");
  std::string deep;
  for (int i = 0; i < 200; ++i) deep += "{a@0:";
  names(deep + "u8" + std::string(200, '}'), 64, "types nested more than 64 deep");
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
