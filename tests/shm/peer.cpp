// A second process for the cross-process tests: it plays one role on a topic
// of a domain and reports over stdout, one line per step, so the test can
// wait for it and kill it at a known point.
//
//   shm_peer publish  <domain> <topic> <first> <count> <capacity> <block|drop>
//   shm_peer loan_and_hang <domain> <topic> <count> <capacity>   publish count, then loan, print, sleep
//   shm_peer hold     <domain> <topic> <capacity> <block|drop>   subscribe, take one sample, print, sleep
//   shm_peer checksum_publish <domain> <topic> <count>           heavy overwrite of checksummed payloads
//   shm_peer sequence_publish <domain> <topic> <count>           block: 0..count-1 as fast as possible
//   shm_peer leave_segments <domain> <topic>                     create a topic, print, sleep (to be killed)
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "prime/shm.hpp"
#include "shm/messages.hpp"

using namespace prime;
using namespace std::chrono_literals;

namespace {

void say(const char* line) {
  std::printf("%s\n", line);
  std::fflush(stdout);
}

[[noreturn]] void fail(const std::string& why) {
  std::fprintf(stderr, "shm_peer: %s\n", why.c_str());
  std::exit(1);
}

Overflow overflow_of(const std::string& s) { return s == "block" ? Overflow::block : Overflow::drop_oldest; }

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) fail("usage: shm_peer <role> <domain> <topic> ...");
  const std::string role = argv[1];
  shm::Core core{argv[2], {.participant = "peer-" + role}};
  const std::string topic = argv[3];
  auto arg = [&](int i) { return std::strtoull(argv[i], nullptr, 10); };

  if (role == "publish" && argc == 8) {
    auto publisher = core.publisher<std::uint64_t>(
        topic, {.capacity = arg(6), .overflow = overflow_of(argv[7]), .block_timeout = 200ms});
    for (std::uint64_t i = arg(4); i < arg(4) + arg(5); ++i) {
      if (auto sent = publisher.publish(i); !sent) fail(sent.error().describe());
    }
    say("published");
    return 0;
  }
  if (role == "loan_and_hang" && argc == 6) {
    auto publisher = core.publisher<std::uint64_t>(topic, {.capacity = arg(5)});
    for (std::uint64_t i = 0; i < arg(4); ++i) (void)publisher.publish(i);
    auto loan = publisher.loan();
    if (!loan) fail(loan.error().describe());
    **loan = 0xdead;
    say("loaned");
    std::this_thread::sleep_for(1h);
  }
  if (role == "hold" && argc == 6) {
    auto reader = core.subscribe<std::uint64_t>(topic, {}, {.capacity = arg(4), .overflow = overflow_of(argv[5]),
                                                            .block_timeout = 200ms})
                      .subscribe();
    say("subscribed");
    auto held = reader.read_for(10s);
    if (!held) fail(held.error().describe());
    say("holding");
    std::this_thread::sleep_for(1h);
  }
  if (role == "checksum_publish" && argc == 5) {
    auto publisher = core.publisher<test::Checked>(topic, test::kCheckedQos);
    for (std::uint64_t i = 0; i < arg(4); ++i) {
      auto loan = publisher.loan();
      if (!loan) fail(loan.error().describe());
      test::fill(**loan, i);
      std::move(*loan).publish();
    }
    say("published");
    return 0;
  }
  if (role == "sequence_publish" && argc == 5) {
    auto publisher = core.publisher<std::uint64_t>(topic, test::kSequenceQos);
    say("ready");
    for (std::uint64_t i = 0; i < arg(4); ++i) {
      auto loan = publisher.loan();
      if (!loan) fail(loan.error().describe());
      **loan = i;
      std::move(*loan).publish();
    }
    say("published");
    return 0;
  }
  if (role == "leave_segments" && argc == 4) {
    auto publisher = core.publisher<std::uint64_t>(topic);
    (void)publisher.publish(42);
    say("created");
    std::this_thread::sleep_for(1h);
  }
  fail("unknown role or wrong arguments: " + role);
}
