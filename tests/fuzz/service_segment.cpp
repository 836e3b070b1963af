// Fuzz target: a service's segment (header, client slots, cells: sizes,
// routes, statuses, errors) as another process may leave it. Each input is
// written over a live service whose server's workers are running, and a
// cell the input names is queued for them; then a new participant calls
// the service, alone and linked. Failures are fine; a crash, a sanitizer's
// report or a hang is not.
#include <cstring>
#include <span>
#include <vector>

#include "fuzz/fuzz.hpp"
#include "prime/shm.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/detail/service_layout.hpp"
#include "shm/domain.hpp"

namespace {

using namespace std::chrono_literals;
using prime::shm::Bytes;
using prime::shm::detail::Segment;

std::vector<std::byte> echo(std::span<const std::byte> in) { return {in.begin(), in.end()}; }

}  // namespace

int main(int argc, char** argv) {
  const auto domain = prime::test::unique_domain("fuzz-service");
  prime::shm::Core server{domain, {.participant = "server"}};
  const prime::shm::ServiceQos qos{.timeout = 20ms, .max_request_size = 64, .max_reply_size = 64, .max_clients = 4,
                                   .calls_per_client = 2};
  server.serve("fuzzed", echo, qos);
  server.serve("next", echo, qos);
  {  // calls in the image: a cell's route and sizes as a linked call leaves them
    prime::shm::Core client{domain, {.participant = "seed"}};
    auto linked = client.chain<Bytes, Bytes>("fuzzed") | client.chain<Bytes, Bytes>("next");
    const std::vector<std::byte> ten(10, std::byte{1});
    (void)linked.call(ten);
  }
  auto segment = Segment::open_existing(prime::shm::detail::segment_name(domain, "service", "fuzzed"));
  const prime::fuzz::Input seed(reinterpret_cast<const std::uint8_t*>(segment->data()),
                                reinterpret_cast<const std::uint8_t*>(segment->data()) + segment->size());
  auto& header = *std::launder(reinterpret_cast<prime::shm::detail::ServiceHeader*>(segment->data()));
  return prime::fuzz::run(
      argc, argv, {seed},
      [&](std::span<const std::uint8_t> input) {
        // Not the server's own word: a server seen dead would be taken over
        // by the next call's participant, which is another test.
        const auto server_id = header.server.load();
        std::memcpy(segment->data(), input.data(), std::min(input.size(), segment->size()));
        header.server.store(server_id);
        header.pending[0].fetch_or(input.size() > 0 ? 1ull << (input[0] % 8) : 1);  // a cell for the workers
        header.requests.ring_always();
        try {
          prime::shm::Core client{domain, {.participant = "fuzz"}};
          const std::vector<std::byte> four(4, std::byte{2});
          (void)client.chain<Bytes, Bytes>("fuzzed", {.timeout = 20ms}).call(four);
          auto linked = client.chain<Bytes, Bytes>("fuzzed", {.timeout = 20ms}) | client.chain<Bytes, Bytes>("next");
          (void)linked.call(four);
          (void)client.registry();
        } catch (const prime::Failure&) {
        }
        std::memcpy(segment->data(), seed.data(), seed.size());
        header.server.store(server_id);
      },
      false);
}
