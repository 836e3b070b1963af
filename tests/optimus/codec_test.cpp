// Messages as bytes: the header, the fingerprint, the codecs, and a decoder
// that never trusts what it reads.
#include <gtest/gtest.h>

#include <charconv>
#include <cstdint>
#include <cstring>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "prime/common/bounded_string.hpp"
#include "prime/common/bounded_vector.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/detail/envelope.hpp"

namespace {

struct Pose {
  double x, y, heading;
  std::int32_t frame;
  friend bool operator==(const Pose&, const Pose&) = default;
};

struct Waypoints {
  prime::bounded_string<15> label;
  prime::bounded_vector<float, 8> xs;
  friend bool operator==(const Waypoints&, const Waypoints&) = default;
};

struct Plan {
  std::string name;
  std::vector<double> costs;
  std::map<std::string, int> counts;
  MSGPACK_DEFINE(name, costs, counts)
  friend bool operator==(const Plan&, const Plan&) = default;
};

// A type with a codec of its own: text "x,y".
struct Cell {
  int x = 0, y = 0;
  Cell() = default;
  Cell(int a, int b) : x{a}, y{b} {}
  Cell(const Cell&) = default;
  Cell& operator=(const Cell&) = default;
  ~Cell() {}  // not trivially copyable: the default would be MessagePack
  friend bool operator==(const Cell&, const Cell&) = default;
};

}  // namespace

template <>
struct prime::optimus::Codec<Cell> {
  static void encode(const Cell& c, std::string& out) { out += std::to_string(c.x) + "," + std::to_string(c.y); }
  static std::expected<Cell, std::string> decode(std::string_view body) {
    const auto comma = body.find(',');
    if (comma == std::string_view::npos) return std::unexpected(std::string{"no comma"});
    Cell c;
    const auto x = body.substr(0, comma), y = body.substr(comma + 1);
    if (std::from_chars(x.data(), x.data() + x.size(), c.x).ec != std::errc{} ||
        std::from_chars(y.data(), y.data() + y.size(), c.y).ec != std::errc{})
      return std::unexpected(std::string{"not two numbers"});
    return c;
  }
};

namespace prime::test {
namespace {

using optimus::decode_message;
using optimus::encode_message;

template <class T>
void expect_round_trip(const T& value) {
  const auto bytes = encode_message(value);
  auto back = decode_message<T>(bytes, "key 'k'");
  ASSERT_TRUE(back) << back.error().describe();
  EXPECT_EQ(*back, value);
}

TEST(OptimusCodec, TriviallyCopyableTypesTravelAsTheirBytes) {
  expect_round_trip(42);
  expect_round_trip(Pose{1.5, -2.0, 0.25, 7});
  const auto bytes = encode_message(Pose{});
  EXPECT_EQ(bytes.size(), optimus::detail::kHeaderSize + sizeof(Pose)) << "a header and the bytes, nothing more";
  EXPECT_EQ(static_cast<optimus::Format>(bytes[3]), optimus::Format::bytes);
}

TEST(OptimusCodec, BoundedTypesTravelAsBytesToo) {
  Waypoints w{prime::bounded_string<15>{"dock"}, {1.0f, 2.0f, 3.0f}};
  expect_round_trip(w);
  EXPECT_EQ(static_cast<optimus::Format>(encode_message(w)[3]), optimus::Format::bytes);
}

TEST(OptimusCodec, OtherTypesGoThroughMessagePack) {
  expect_round_trip(std::string{"hello"});
  expect_round_trip(std::vector<int>{1, 2, 3});
  expect_round_trip(std::tuple<int, std::string>{4, "four"});
  expect_round_trip(std::pair<int, double>{1, 2.5});
  expect_round_trip(Plan{"route", {1.0, 2.0}, {{"a", 1}}});
  EXPECT_EQ(static_cast<optimus::Format>(encode_message(std::string{"x"})[3]), optimus::Format::msgpack);
}

TEST(OptimusCodec, AUserRegisteredCodecIsUsedForItsType) {
  expect_round_trip(Cell{3, -4});
  const auto bytes = encode_message(Cell{3, -4});
  EXPECT_EQ(bytes.substr(optimus::detail::kHeaderSize), "3,-4");
  EXPECT_EQ(static_cast<optimus::Format>(bytes[3]), optimus::Format::custom);
  auto bad = decode_message<Cell>(bytes.substr(0, optimus::detail::kHeaderSize - 4) + std::string(4, '\0'), "key 'cells'");
  ASSERT_FALSE(bad);
}

TEST(OptimusCodec, AnotherTypesMessageIsATypeMismatchNamingBoth) {
  const auto bytes = encode_message(std::int64_t{5});
  auto wrong = decode_message<double>(bytes, "key 'dom:src:odom'");
  ASSERT_FALSE(wrong);
  EXPECT_EQ(wrong.error().code, Errc::type_mismatch);
  EXPECT_NE(wrong.error().message.find("key 'dom:src:odom'"), std::string::npos) << wrong.error().message;
  EXPECT_NE(wrong.error().message.find("double"), std::string::npos) << wrong.error().message;
  EXPECT_NE(wrong.error().message.find("another type"), std::string::npos) << wrong.error().message;
}

TEST(OptimusCodec, ForeignDataIsNamedAsSuch) {
  auto foreign = decode_message<int>("{\"json\": true, \"from\": \"elsewhere\"}", "key 'k'");
  ASSERT_FALSE(foreign);
  EXPECT_EQ(foreign.error().code, Errc::type_mismatch);
  EXPECT_NE(foreign.error().message.find("not a Prime message"), std::string::npos) << foreign.error().message;
  auto short_one = decode_message<int>("PO", "key 'k'");
  ASSERT_FALSE(short_one);
  EXPECT_NE(short_one.error().message.find("less than a message header"), std::string::npos);
}

TEST(OptimusCodec, ABoundedStringOrVectorClaimingMoreThanItsCapacityIsRefused) {
  // Their size field comes first: forge it to claim 1000 elements.
  const std::uint32_t forged = 1000;
  auto label = encode_message(prime::bounded_string<15>{"dock"});
  std::memcpy(label.data() + optimus::detail::kHeaderSize, &forged, sizeof forged);
  auto refused = decode_message<prime::bounded_string<15>>(label, "key 'label'");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, Errc::type_mismatch);
  EXPECT_NE(refused.error().message.find("past the capacity"), std::string::npos) << refused.error().message;

  auto xs = encode_message(prime::bounded_vector<float, 8>{1.0f, 2.0f});
  const std::size_t many = 1000;
  std::memcpy(xs.data() + optimus::detail::kHeaderSize, &many, sizeof many);
  EXPECT_FALSE((decode_message<prime::bounded_vector<float, 8>>(xs, "key 'xs'")));
}

// Random, truncated and bit-flipped buffers: the decoder answers every one
// with a value or an error, never a crash, a hang or a huge allocation (run
// under ASan and UBSan in the asan preset).
template <class T>
int hammer(std::mt19937_64& random, const std::vector<std::string>& valid, int rounds) {
  int errors = 0;
  std::uniform_int_distribution<int> byte{0, 255};
  for (int i = 0; i < rounds; ++i) {
    std::string buffer;
    switch (i % 5) {
      case 0: {  // noise
        buffer.resize(random() % 64);
        for (auto& c : buffer) c = static_cast<char>(byte(random));
        break;
      }
      case 1: {  // a valid message, truncated
        const auto& v = valid[random() % valid.size()];
        buffer = v.substr(0, random() % (v.size() + 1));
        break;
      }
      case 2: {  // a valid message with bits flipped (anywhere, the header included)
        buffer = valid[random() % valid.size()];
        for (int flips = 1 + static_cast<int>(random() % 4); flips > 0; --flips)
          buffer[random() % buffer.size()] ^= static_cast<char>(1u << (random() % 8));
        break;
      }
      case 3: {  // a valid header over a random body of the promised size
        const auto& v = valid[random() % valid.size()];
        buffer = v.substr(0, optimus::detail::kHeaderSize);
        for (std::size_t k = optimus::detail::kHeaderSize; k < v.size(); ++k) buffer += static_cast<char>(byte(random));
        break;
      }
      default: {  // a valid body's bytes with the header's size fixed up: forged lengths inside the body
        buffer = valid[random() % valid.size()];
        for (std::size_t k = optimus::detail::kHeaderSize; k < buffer.size(); ++k)
          if (random() % 4 == 0) buffer[k] = static_cast<char>(0xdc + random() % 4);  // msgpack array/map 16/32 markers
        break;
      }
    }
    if (!optimus::decode_message<T>(buffer, "fuzz")) ++errors;
  }
  return errors;
}

TEST(OptimusCodec, TheDecoderSurvivesRandomTruncatedAndFlippedBuffers) {
  std::mt19937_64 random{20240607};
  constexpr int kRounds = 20'000;
  std::vector<std::string> plans, strings, vectors, tuples, ints, labels;
  for (int i = 0; i < 16; ++i) {
    plans.push_back(encode_message(Plan{std::string(static_cast<std::size_t>(i), 'p'), std::vector<double>(static_cast<std::size_t>(i), 0.5),
                                        {{"k" + std::to_string(i), i}}}));
    strings.push_back(encode_message(std::string(static_cast<std::size_t>(i * 7), 's')));
    vectors.push_back(encode_message(std::vector<int>(static_cast<std::size_t>(i * 3), i)));
    tuples.push_back(encode_message(std::tuple<int, std::string, std::vector<float>>{i, "t", {1.0f}}));
    ints.push_back(encode_message(i));
    labels.push_back(encode_message(prime::bounded_string<15>{std::string(static_cast<std::size_t>(i) % 15, 'l')}));
  }
  EXPECT_GT(hammer<Plan>(random, plans, kRounds), kRounds / 2);
  EXPECT_GT(hammer<std::string>(random, strings, kRounds), kRounds / 2);
  EXPECT_GT(hammer<std::vector<int>>(random, vectors, kRounds), kRounds / 2);
  EXPECT_GT((hammer<std::tuple<int, std::string, std::vector<float>>>(random, tuples, kRounds)), kRounds / 2);
  EXPECT_GT(hammer<int>(random, ints, kRounds), kRounds / 2);
  EXPECT_GT(hammer<prime::bounded_string<15>>(random, labels, kRounds), kRounds / 2);
  // Each shape also goes through the envelope decoders.
  for (int i = 0; i < kRounds; ++i) {
    std::string noise(random() % 128, '\0');
    for (auto& c : noise) c = static_cast<char>(random());
    if (i % 2 == 0 && !plans.empty()) {
      std::string request;
      optimus::detail::encode_request(7, "dom:reply:1", std::vector<std::string>{"a", "b"}, 0, plans[0], request);
      noise = request.substr(0, random() % (request.size() + 1));
      if (!noise.empty() && random() % 2) noise[random() % noise.size()] ^= 0x10;
    }
    (void)optimus::detail::decode_request(noise);
    (void)optimus::detail::decode_response(noise);
  }
}

}  // namespace
}  // namespace prime::test
