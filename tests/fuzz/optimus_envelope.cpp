// Fuzz target: what comes through Redis: a request's or a response's
// envelope, and the message inside it, decoded as a bounded type, as a
// MessagePack one and as raw bytes. Refusals are fine; a crash, a
// sanitizer's report or a hang is not.
#include <map>
#include <string>
#include <vector>

#include "fuzz/fuzz.hpp"
#include "prime/common/bounded_string.hpp"
#include "prime/common/bounded_vector.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/detail/envelope.hpp"

namespace {

struct Pose {
  double x, y;
  prime::bounded_string<8> frame;
  prime::bounded_vector<float, 4> cov;
};

prime::fuzz::Input bytes(const std::string& s) { return {s.begin(), s.end()}; }

void decode_all(std::string_view payload) {
  (void)prime::optimus::decode_message<Pose>(payload, "fuzz");
  (void)prime::optimus::decode_message<prime::bounded_string<32>>(payload, "fuzz");
  (void)prime::optimus::decode_message<std::map<std::string, std::vector<double>>>(payload, "fuzz");
  (void)prime::optimus::decode_message<std::string>(payload, "fuzz");
}

}  // namespace

int main(int argc, char** argv) {
  using namespace prime::optimus;
  Pose pose{1, 2, prime::bounded_string<8>{"map"}, {0.5f}};
  const std::vector<std::string> route{"robot:svc:planner"};
  std::string request, response, map;
  detail::encode_request(7, "robot:reply:1.ab:1", route, 123, encode_message(pose), request);
  detail::encode_response(7, prime::Errc::timeout, "late", encode_message(std::map<std::string, std::vector<double>>{{"a", {1, 2}}}), response);
  return prime::fuzz::run(
      argc, argv, {bytes(request), bytes(response), bytes(encode_message(pose))},
      [](std::span<const std::uint8_t> input) {
        const std::string_view data{reinterpret_cast<const char*>(input.data()), input.size()};
        if (auto r = detail::decode_request(data)) decode_all(r->payload);
        if (auto r = detail::decode_response(data)) decode_all(r->payload);
        decode_all(data);
      },
      true);
}
