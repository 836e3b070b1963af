// Fuzz target: a type description (prime::schema_of's text), as another
// process leaves it in a segment's header, and a message of that type: the
// tool parses it against the message's size, then prints the message field
// by field, as JSON, and writes it back from that JSON. Refusals are fine;
// a crash, a sanitizer's report or a hang is not.
//
// An input is the description, a NUL, then the message's bytes.
#include <algorithm>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "fuzz/fuzz.hpp"
#include "message_text.hpp"
#include "prime/common/bounded_string.hpp"
#include "prime/common/bounded_vector.hpp"
#include "prime/common/schema.hpp"

namespace {

struct Inner {
  float v[3];
  bool ok;
};
struct Scan {
  double stamp;
  prime::bounded_string<16> frame;
  prime::bounded_vector<float, 8> ranges;
  std::array<Inner, 2> inner;
  std::int8_t mode;
};

}  // namespace

PRIME_DESCRIBE(Inner, v, ok)
PRIME_DESCRIBE(Scan, stamp, frame, ranges, inner, mode)

int main(int argc, char** argv) {
  Scan scan{};
  scan.stamp = 1.5;
  scan.frame = "laser";
  scan.ranges = {1.f, 2.f, 3.f};
  scan.inner[1].ok = true;
  auto seed_of = [](const std::string& description, const void* data, std::size_t size) {
    prime::fuzz::Input seed(description.begin(), description.end());
    seed.push_back(0);
    const auto* bytes = static_cast<const std::uint8_t*>(data);
    seed.insert(seed.end(), bytes, bytes + size);
    return seed;
  };
  const double pair[2] = {3, 4};
  const std::vector<prime::fuzz::Input> seeds{seed_of(prime::schema_of<Scan>(), &scan, sizeof scan),
                                              seed_of("{x@0:f64,y@8:f64}", pair, sizeof pair)};
  return prime::fuzz::run(
      argc, argv, seeds,
      [](std::span<const std::uint8_t> input) {
        const auto nul = std::find(input.begin(), input.end(), std::uint8_t{0});
        const std::string description(input.begin(), nul);
        std::vector<std::byte> data(nul == input.end() ? 0 : static_cast<std::size_t>(input.end() - nul - 1));
        if (!data.empty()) std::memcpy(data.data(), &*(nul + 1), data.size());
        try {
          const auto layout = prime::tool::parse_layout(description, data.size());
          std::ostringstream out;
          prime::tool::print_fields(out, *layout, data.data());
          const auto json = prime::tool::to_json(*layout, data.data());
          std::vector<std::byte> written(data.size());
          prime::tool::fill(*layout, written.data(), prime::tool::parse_json(json));
        } catch (const std::exception&) {
        }
      },
      true);
}
