// FutexWake: Floor's ping-pong, but each side sleeps in FUTEX_WAIT on the
// number it waits for and the other wakes it with FUTEX_WAKE after writing it.
// No spinning at all: the floor for a subscriber that sleeps until data
// arrives (two wake-ups per round trip). Payload-independent; 64 B only.

#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <ctime>
#include <system_error>

#include "harness.hpp"

namespace {

namespace ipc = prime::bench::ipc;

struct alignas(64) Words {
  std::atomic<std::uint32_t> ping{0};
  std::atomic<std::uint32_t> pong{0};
};
static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t), "a futex is a plain 32-bit word");

// Shared futexes (no FUTEX_PRIVATE_FLAG): the words live in a MAP_SHARED mapping.
void wake(std::atomic<std::uint32_t>& word) {
  ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAKE, 1, nullptr, nullptr, 0);
}

// Sleeps until `word` holds `value`; a sleep that times out counts as idle.
template <ipc::Side S>
void sleep_until_equal(S& side, std::atomic<std::uint32_t>& word, std::uint32_t value) {
  ipc::Patience<S> patience{side};
  const timespec slice{0, 50'000'000};
  for (std::uint32_t seen; (seen = word.load(std::memory_order_acquire)) != value;) {
    if (::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAIT, seen, &slice, nullptr, 0) == 0) continue;
    if (errno == ETIMEDOUT) patience.idle();
    else if (errno != EAGAIN && errno != EINTR) throw std::system_error{errno, std::generic_category(), "FUTEX_WAIT"};
  }
}

void echo(ipc::Child& self) {
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(Words));
  auto& words = mapping.as<Words>();
  self.ready();
  for (std::uint32_t seq = 1;; ++seq) {
    sleep_until_equal(self, words.ping, seq);
    words.pong.store(seq, std::memory_order_release);
    wake(words.pong);
  }
}
const ipc::ChildEntry kEcho{"FutexWake.echo", echo};

void BM_Latency_FutexWake(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    auto mapping = ipc::SharedMapping::create("prime-ipc-futex", sizeof(Words));
    auto& words = mapping.construct<Words>();
    ipc::Link child{"FutexWake.echo", bytes, {mapping.fd()}};
    child.wait_ready();
    child.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      const auto value = static_cast<std::uint32_t>(seq);
      words.ping.store(value, std::memory_order_release);
      wake(words.ping);
      sleep_until_equal(child, words.pong, value);
    });
    child.stop();
  });
}
BENCHMARK(BM_Latency_FutexWake)->Arg(64)->UseRealTime();

}  // namespace
