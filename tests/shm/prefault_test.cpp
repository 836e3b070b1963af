// DomainOptions::prefault: every page of a segment is mapped in as it is
// opened, so the first publish into a chunk and the first read of it take
// no page fault; without it, each page of the chunk faults on first touch.
// Counted with getrusage(RUSAGE_THREAD) minor faults, on this thread.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <array>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <numeric>

#include "prime/shm.hpp"
#include "shm/domain.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// 64 pages: a chunk of it spans at least as many.
struct Frame {
  std::array<unsigned char, 64 * 4096> bytes;
};

long minor_faults() {
  rusage usage{};
  ::getrusage(RUSAGE_THREAD, &usage);
  return usage.ru_minflt;
}

struct Faults {
  long publish;
  long read;
};

// The faults this thread takes to publish the first frame of a new topic
// (written in place, in its loan) and to read it back, all of it.
Faults first_publish_and_read(const shm::DomainOptions& options) {
  shm::Core core{unique_domain("prefault"), options};
  const shm::TopicQos qos{.capacity = 4};
  auto publisher = core.publisher<Frame>("camera", qos);
  auto reader = core.subscribe<Frame>("camera", {}, qos).subscribe();
  // Warm what is not the segment's: the code and stack of both paths.
  (void)reader.try_read();
  Faults faults{};
  auto before = minor_faults();
  {
    auto loan = publisher.loan();
    if (!loan) throw Failure{loan.error()};
    std::memset((*loan)->bytes.data(), 7, sizeof(Frame));
    std::move(*loan).publish(Clock::now());
  }
  faults.publish = minor_faults() - before;
  before = minor_faults();
  {
    auto sample = reader.read_for(1s);
    if (!sample) throw Failure{sample.error()};
    const auto& bytes = sample->value->bytes;
    EXPECT_EQ(std::accumulate(bytes.begin(), bytes.end(), 0ull), 7ull * sizeof(Frame));
  }
  faults.read = minor_faults() - before;
  return faults;
}

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;  // their shadow memory faults on its own
#else
constexpr bool kSanitized = false;
#endif

TEST(ShmPrefault, WithoutItTheFirstPublishFaultsInEveryPageOfItsChunk) {
  const auto faults = first_publish_and_read({});
  if (kSanitized) GTEST_SKIP() << "page faults are not counted under a sanitizer (its shadow memory faults too)";
  // One per page of the 64 written, but for those the topic's set-up
  // wrote already (the chunk's first page may hold what comes before it).
  EXPECT_GE(faults.publish, 62) << "the test sees faults";
}

TEST(ShmPrefault, WithItTheFirstPublishAndReadTakeNoPageFault) {
  const auto faults = first_publish_and_read({.prefault = true});
  if (kSanitized) GTEST_SKIP() << "page faults are not counted under a sanitizer (its shadow memory faults too)";
  EXPECT_EQ(faults.publish, 0);
  EXPECT_EQ(faults.read, 0);
}

}  // namespace
}  // namespace prime::test
