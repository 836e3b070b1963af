// Fuzz target: a topic's segment (header, ring, sample infos, chunk
// headers) as another process may leave it. Each input is written over a
// live topic; then a new participant subscribes, observes and reads it
// every way a reader can, and the publisher publishes into it. Failures
// are fine; a crash, a sanitizer's report or a hang is not.
#include <cstring>
#include <optional>
#include <span>
#include <vector>

#include "fuzz/fuzz.hpp"
#include "prime/shm.hpp"
#include "prime/shm/detail/segment.hpp"
#include "shm/domain.hpp"

namespace {

using namespace std::chrono_literals;
using prime::shm::detail::Segment;

constexpr prime::shm::TopicQos kQos{.capacity = 8, .block_timeout = std::chrono::milliseconds{5}, .max_subscribers = 4,
                                    .max_held = 4};

void read_all_ways(prime::shm::Core& core) {
  auto subscription = core.subscribe<std::uint64_t>("fuzzed", {}, kQos);
  auto reader = subscription.subscribe();
  for (int i = 0; i < 4; ++i)
    if (auto sample = reader.try_read()) (void)*sample->value;
  std::vector<prime::Sample<prime::shm::View<std::uint64_t>>> some;
  (void)reader.read_some(some, 8, prime::Clock::now());
  auto batches = subscription.batches();
  (void)batches.try_read(8).size();
  (void)reader.read_for(0ms);
  auto observer = core.observe("fuzzed");
  if (auto sample = observer.try_read()) (void)sample->value.bytes().size();
  (void)core.registry();
}

}  // namespace

int main(int argc, char** argv) {
  const auto domain = prime::test::unique_domain("fuzz-topic");
  prime::shm::Core owner{domain, {.participant = "owner"}};
  auto publisher = owner.publisher<std::uint64_t>("fuzzed", kQos);
  auto held = owner.subscribe<std::uint64_t>("fuzzed", {}, kQos).subscribe();
  for (std::uint64_t i = 0; i < 11; ++i) (void)publisher.publish(i);  // past a lap
  std::optional<prime::shm::View<std::uint64_t>> kept;
  if (auto s = held.try_read()) kept = std::move(s->value);  // a held sample in the image
  auto segment = Segment::open_existing(prime::shm::detail::segment_name(domain, "topic", "fuzzed"));
  const prime::fuzz::Input seed(reinterpret_cast<const std::uint8_t*>(segment->data()),
                                reinterpret_cast<const std::uint8_t*>(segment->data()) + segment->size());
  return prime::fuzz::run(
      argc, argv, {seed},
      [&](std::span<const std::uint8_t> input) {
        std::memcpy(segment->data(), input.data(), std::min(input.size(), segment->size()));
        try {
          prime::shm::Core core{domain, {.participant = "fuzz"}};
          read_all_ways(core);
        } catch (const prime::Failure&) {
        }
        for (std::uint64_t i = 0; i < 3; ++i) (void)publisher.publish(i);
        (void)held.try_read();
        std::memcpy(segment->data(), seed.data(), seed.size());
      },
      false);
}
