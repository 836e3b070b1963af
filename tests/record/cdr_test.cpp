// Described types as ROS 2 says them: ros2msg definitions, CDR bodies
// (XCDR1, little-endian) encoded and decoded, and CDR that does not fit its
// type refused by name.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "prime/common/bounded_string.hpp"
#include "prime/common/bounded_vector.hpp"
#include "prime/common/schema.hpp"
#include "prime/record/cdr.hpp"
#include "record/described.hpp"

namespace cdr_test {

using described::Point;
using described::Pose;

// Laid out unlike CDR: in memory `in` starts at 8 (its alignment), in CDR
// at 1, and its `c` at 16 in memory, 8 in CDR.
struct Inner {
  std::uint8_t b;
  double c;
};
PRIME_DESCRIBE(Inner, b, c)
struct Outer {
  std::uint8_t a;
  Inner in;
};
PRIME_DESCRIBE(Outer, a, in)

struct Named {
  std::uint32_t id;
  prime::bounded_string<16> name;
  prime::bounded_vector<float, 4> values;
  bool ok;
};
PRIME_DESCRIBE(Named, id, name, values, ok)

struct Blob {
  std::byte raw[16];
};

}  // namespace cdr_test

namespace {

using namespace cdr_test;
using prime::record::CdrCodec;

template <class T>
CdrCodec codec_of() {
  auto codec = CdrCodec::of(prime::schema_of<T>(), sizeof(T));
  if (!codec) throw std::runtime_error{"no codec"};
  return *codec;
}
template <class T>
std::span<const std::byte> bytes_of(const T& v) {
  return std::as_bytes(std::span{&v, 1});
}
template <class T>
T load(const std::vector<std::byte>& b, std::size_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof v);
  return v;
}

TEST(Cdr, ATypeLaidOutAsCdrIsItsOwnBodyAfterTheHeader) {
  const auto codec = codec_of<Pose>();
  EXPECT_TRUE(codec.plain());
  Pose pose{{1, 2, 3}, {0.5, 0.25, 0.125, 1}, 7};
  std::vector<std::byte> out;
  codec.encode(bytes_of(pose), out);
  ASSERT_EQ(out.size(), 4u + 60) << "the header, then up to the end of its last field (not its padding)";
  EXPECT_EQ(out[0], std::byte{0});
  EXPECT_EQ(out[1], std::byte{1});  // CDR little-endian
  EXPECT_EQ(load<double>(out, 4 + 16), 3.0);
  EXPECT_EQ(load<std::uint32_t>(out, 4 + 56), 7u);
  const auto back = codec.decode(out, "pose");
  ASSERT_EQ(back.size(), sizeof(Pose));
  Pose again;
  std::memcpy(&again, back.data(), sizeof again);
  EXPECT_EQ(again.position.z, 3.0);
  EXPECT_EQ(again.orientation[2], 0.125);
  EXPECT_EQ(again.frame, 7u);
}

TEST(Cdr, DefinitionsNameNestedTypesAsRos2Does) {
  EXPECT_EQ(prime::record::ros2_name("robot::msgs::Pose"), "robot_msgs/msg/Pose");
  EXPECT_EQ(prime::record::ros2_name("Pose"), "prime/msg/Pose");
  EXPECT_EQ(prime::record::ros2_name("ns::scan_t"), "ns/msg/Scan_t");
  const auto codec = codec_of<Pose>();
  EXPECT_EQ(codec.definition("described/msg/Pose"),
            "described/PosePosition position\n"
            "float64[4] orientation\n"
            "uint32 frame\n"
            "================================================================================\n"
            "MSG: described/PosePosition\n"
            "float64 x\nfloat64 y\nfloat64 z\n");
  EXPECT_EQ(codec_of<Named>().definition("cdr_test/msg/Named"),
            "uint32 id\nstring<=16 name\nfloat32[<=4] values\nbool ok\n");
}

TEST(Cdr, ATypeLaidOutUnlikeCdrIsEncodedFieldByField) {
  const auto codec = codec_of<Outer>();
  EXPECT_FALSE(codec.plain());
  Outer o{9, {4, 2.5}};
  std::vector<std::byte> out;
  codec.encode(bytes_of(o), out);
  ASSERT_EQ(out.size(), 4u + 16);
  EXPECT_EQ(load<std::uint8_t>(out, 4 + 0), 9);
  EXPECT_EQ(load<std::uint8_t>(out, 4 + 1), 4);
  EXPECT_EQ(load<double>(out, 4 + 8), 2.5);
  const auto back = codec.decode(out, "outer");
  Outer again;
  std::memcpy(&again, back.data(), sizeof again);
  EXPECT_EQ(again.a, 9);
  EXPECT_EQ(again.in.b, 4);
  EXPECT_EQ(again.in.c, 2.5);
}

TEST(Cdr, BoundedStringsAndVectorsCarryTheirLengths) {
  const auto codec = codec_of<Named>();
  Named n{};
  n.id = 3;
  n.name = "lidar";
  n.values.push_back(1.5f);
  n.values.push_back(-2);
  n.ok = true;
  std::vector<std::byte> out;
  codec.encode(bytes_of(n), out);
  // id; "lidar" as 6 (with its NUL) and its characters; 2 floats after their count; the bool.
  ASSERT_EQ(out.size(), 4u + 4 + 4 + 6 + 2 + 4 + 8 + 1);
  EXPECT_EQ(load<std::uint32_t>(out, 4 + 4), 6u);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(out.data() + 4 + 8), 5), "lidar");
  EXPECT_EQ(load<std::uint32_t>(out, 4 + 16), 2u);
  EXPECT_EQ(load<float>(out, 4 + 24), -2.0f);
  const auto back = codec.decode(out, "named");
  Named again;
  std::memcpy(&again, back.data(), sizeof again);
  EXPECT_EQ(again.id, 3u);
  EXPECT_EQ(again.name.view(), "lidar");
  ASSERT_EQ(again.values.size(), 2u);
  EXPECT_EQ(again.values.span()[0], 1.5f);
  EXPECT_TRUE(again.ok);
}

TEST(Cdr, CdrThatDoesNotFitItsTypeIsDamagedByName) {
  const auto codec = codec_of<Named>();
  Named n{};
  n.name = "x";
  std::vector<std::byte> good;
  codec.encode(bytes_of(n), good);
  auto code_and_text = [&](std::vector<std::byte> message) -> std::pair<std::optional<prime::Errc>, std::string> {
    try {
      (void)codec.decode(message, "sample 4 of 'scan'");
    } catch (const prime::Failure& f) {
      return {f.error().code, f.error().message};
    }
    return {std::nullopt, "decoded"};
  };
  auto long_name = good;
  const std::uint32_t seventeen = 18;  // 17 characters and a NUL, in a field of 16
  std::memcpy(long_name.data() + 8, &seventeen, 4);
  auto [code, text] = code_and_text(long_name);
  EXPECT_EQ(code, prime::Errc::damaged);
  EXPECT_NE(text.find("sample 4 of 'scan'"), std::string::npos) << text;
  EXPECT_NE(text.find("a string of 17 characters, in a field of at most 16"), std::string::npos) << text;
  std::tie(code, text) = code_and_text(std::vector<std::byte>(good.begin(), good.begin() + 10));
  EXPECT_EQ(code, prime::Errc::damaged);
  EXPECT_NE(text.find("ends before its fields do"), std::string::npos) << text;
  auto big_endian = good;
  big_endian[1] = std::byte{0};
  std::tie(code, text) = code_and_text(big_endian);
  EXPECT_NE(text.find("not a CDR little-endian message"), std::string::npos) << text;
  auto many = good;
  const std::uint32_t five = 5;  // values: 5 in a field of 4
  std::memcpy(many.data() + 4 + 12, &five, 4);
  std::tie(code, text) = code_and_text(many);
  EXPECT_NE(text.find("a sequence of 5 elements, in a field of at most 4"), std::string::npos) << text;
}

TEST(Cdr, ATypeWithoutADescriptionHasNoCodec) {
  EXPECT_FALSE(CdrCodec::of(prime::schema_of<Blob>(), sizeof(Blob)));
  EXPECT_FALSE(CdrCodec::of("{x@0:f64,y@8:?8}", 16)) << "bytes of no description inside";
  EXPECT_FALSE(CdrCodec::of("{x@0:f64}", 4)) << "a description larger than its type";
  EXPECT_FALSE(CdrCodec::of("not a description", 8));
}

}  // namespace
