// Fuzz target: what a user types to the prime tool: a JSON value, and
// field=value words, written into a message by a type description (pub,
// call). Refusals are fine; a crash, a sanitizer's report or a hang is not.
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "fuzz/fuzz.hpp"
#include "json.hpp"
#include "message_text.hpp"

namespace {

prime::fuzz::Input text(std::string_view s) { return {s.begin(), s.end()}; }

// The input's words, split at spaces, as a shell would hand them on.
std::vector<std::string> words(std::string_view s) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= s.size()) {
    const auto end = std::min(s.find(' ', start), s.size());
    if (end > start) out.emplace_back(s.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  const auto layout = prime::tool::parse_layout("{x@0:f64,n@8:i32,frame@12:str15@0,4,v@32:vec4@0,8,4(f32),a@56:arr2,1(u8)}", 64);
  const std::vector<prime::fuzz::Input> seeds{
      text(R"({"x":1.5,"n":-3,"frame":"laser","v":[1,2e3,-0.5],"a":[1,2]})"),
      text("x=1.5 n=-3 frame=laser v=[1,2,3] a=[7,8]"),
      text(R"(["\u00e9\ud83d\ude00",true,false,null,{"a":{"b":[[]]}}])"),
  };
  return prime::fuzz::run(
      argc, argv, seeds,
      [&](std::span<const std::uint8_t> input) {
        const std::string_view s{reinterpret_cast<const char*>(input.data()), input.size()};
        std::vector<std::byte> message(64);
        try {
          prime::tool::fill(*layout, message.data(), prime::tool::parse_json(s));
        } catch (const std::exception&) {
        }
        try {
          prime::tool::fill(*layout, message.data(), prime::tool::from_assignments(words(s)));
        } catch (const std::exception&) {
        }
        (void)prime::tool::quote(s);
      },
      true);
}
