// A second process for the cross-process tests: it plays one role on a topic
// of a domain and reports over stdout, one line per step, so the test can
// wait for it and kill it at a known point.
//
//   shm_peer publish  <domain> <topic> <first> <count> <capacity> <block|drop>
//   shm_peer loan_and_hang <domain> <topic> <count> <capacity> [light]
//                     publish count (with PublishFence::light: light), then loan, print, sleep
//   shm_peer hold     <domain> <topic> <capacity> <block|drop>   subscribe, take one sample, print, sleep
//   shm_peer sleep    <domain> <topic>                           subscribe (spin 0), print, wait asleep for a sample
//   shm_peer stuck    <domain> <topic> <capacity>                subscribe to a block topic, print, never read
//   shm_peer count    <domain> <topic> <capacity> <count>        block topic: read 0..count-1, check each, print "ok"
//   shm_peer fill     <domain> <topic> <capacity>                block topic: publish until asleep for room
//   shm_peer receive  <domain> <topic> <count>                   subscribe, print, read count samples, print
//   shm_peer sync     <domain> <seconds>                         sync two topics (max_held 4) into a chain and a collector
//   shm_peer memory   <domain>                                   a topic too big for /dev/shm, then one that fits
//   shm_peer checksum_publish <domain> <topic> <count> [batches|block_batches]
//                     heavy overwrite of checksummed payloads (batches: 1 to 4 at a time, loan_some;
//                     block_batches: the same on a block topic that passes a stopped reader over)
//   shm_peer sequence_publish <domain> <topic> <count>           block: 0..count-1 as fast as possible
//   shm_peer batch_publish <domain> <topic> <count>              the same in batches of 1 to 61 (loan_some)
//   shm_peer leave_segments <domain> <topic>                     create a topic, print, sleep (to be killed)
//   shm_peer serve    <domain> <service> <echo|twice|plus|hang>  serve until killed (hang: answers nothing, says "running")
//   shm_peer loop     <domain> <name> <period_ms>                a periodic loop whose cycle 3 runs two periods
//                     (one overrun); prints "looping" after cycle 5, then runs until killed
//   shm_peer ticks    <domain> <topic> <hz> <age_ms>             publish Ticks at hz, each stamped age_ms in the past
//   shm_peer raw      <domain> <topic>                           publish one Raw {0x1122334455667788, 42}, then wait
//   shm_peer listen   <domain> <topic>                           print each Tick received: "tick <n> <x> <tag>"
//   shm_peer call_many <domain> <service> <threads> <calls>      echo: each thread's calls checked, print "ok <n>"
//   shm_peer call_once <domain> <service> <value>                print "calling", call, print the answer
//   shm_peer emitter  <domain>                                   serve "emit": publish an Emit on lidar, odom or odom_x
//   shm_peer signalfd <domain> <service>                         serve with 2 workers, then block SIGTERM on the
//                     main thread, print "ready", read SIGTERM from a signalfd, print "took SIGTERM", exit 0
//   shm_peer echo_asleep <domain> <in> <out> <count> [no_membarrier]
//                     read count numbers from in asleep (spin 0), each published back on out, then print
//                     "done <heavy fences asked for> <ms>"; with no_membarrier under a seccomp filter that
//                     refuses membarrier(2), as a container's may
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/signalfd.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/shm.hpp"
#include "prime/shm/detail/asymmetric_fence.hpp"
#include "shm/messages.hpp"

using namespace prime;
using namespace std::chrono_literals;

namespace {

void say(const std::string& line) {
  std::printf("%s\n", line.c_str());
  std::fflush(stdout);
}

[[noreturn]] void fail(const std::string& why) {
  std::fprintf(stderr, "shm_peer: %s\n", why.c_str());
  std::exit(1);
}

Overflow overflow_of(const std::string& s) { return s == "block" ? Overflow::block : Overflow::drop_oldest; }

// From here on this process's membarrier(2) calls fail with EPERM.
void refuse_membarrier() {
  sock_filter filter[] = {
      BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(seccomp_data, nr)),
      BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, SYS_membarrier, 0, 1),
      BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ERRNO | EPERM),
      BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW),
  };
  sock_fprog program{static_cast<unsigned short>(sizeof filter / sizeof filter[0]), filter};
  if (::prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0 || ::prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, &program) != 0)
    fail("cannot install a seccomp filter");
  if (::syscall(SYS_membarrier, 0, 0, 0) != -1 || errno != EPERM) fail("membarrier still allowed");
}

[[noreturn]] void forever() {
  while (true) std::this_thread::sleep_for(1h);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) fail("usage: shm_peer <role> <domain> ...");
  const std::string role = argv[1];
  if (role == "echo_asleep" && argc == 7 && std::string{argv[6]} == "no_membarrier") refuse_membarrier();
  shm::Core core{argv[2], {.participant = "peer-" + role}};
  const std::string topic = argc > 3 ? argv[3] : "";
  auto arg = [&](int i) { return std::strtoull(argv[i], nullptr, 10); };

  if (role == "publish" && argc == 8) {
    auto publisher = core.publisher<std::uint64_t>(topic, {.capacity = arg(6), .overflow = overflow_of(argv[7]),
                                                           .block_timeout = 200ms});
    for (std::uint64_t i = arg(4); i < arg(4) + arg(5); ++i) {
      if (auto sent = publisher.publish(i); !sent) fail(sent.error().describe());
    }
    say("published");
    return 0;
  }
  if (role == "loan_and_hang" && (argc == 6 || argc == 7)) {
    const auto fence = argc == 7 && std::string{argv[6]} == "light" ? shm::PublishFence::light : shm::PublishFence::full;
    auto publisher = core.publisher<std::uint64_t>(topic, {.capacity = arg(5), .publish_fence = fence});
    for (std::uint64_t i = 0; i < arg(4); ++i) (void)publisher.publish(i);
    auto loan = publisher.loan();
    if (!loan) fail(loan.error().describe());
    **loan = 0xdead;
    say("loaned");
    forever();
  }
  if (role == "hold" && argc == 7) {  // argv[6]: one view ("view") or a batch of them ("views")
    auto subscription = core.subscribe<std::uint64_t>(topic, {}, {.capacity = arg(4), .overflow = overflow_of(argv[5])});
    if (std::string{argv[6]} == "views") {
      auto batches = subscription.batches();
      say("subscribed");
      auto held = batches.read(arg(4), Clock::now() + 10s);
      if (!held) fail(held.error().describe());
      say("holding");
      forever();
    }
    auto reader = subscription.subscribe();
    say("subscribed");
    auto held = reader.read_for(10s);
    if (!held) fail(held.error().describe());
    say("holding");
    forever();
  }
  if (role == "sleep" && argc == 4) {
    auto reader = core.subscribe<std::uint64_t>(topic, {.spin = 0us}).subscribe();
    say("subscribed");
    (void)reader.read_for(1h);
    say("woken");
    forever();
  }
  if (role == "echo_asleep" && (argc == 6 || argc == 7)) {
    auto in = core.subscribe<std::uint64_t>(topic, {.spin = 0us}).subscribe();
    auto out = core.publisher<std::uint64_t>(argv[4]);
    say("subscribed");
    const auto start = std::chrono::steady_clock::now();
    for (std::uint64_t i = 0; i < arg(5); ++i) {
      auto got = in.read_for(30s);
      if (!got) fail(got.error().describe() + " waiting for " + std::to_string(i));
      if (auto sent = out.publish(*got->value); !sent) fail(sent.error().describe());
    }
    const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - start);
    say("done " + std::to_string(shm::detail::heavy_fences.load()) + " " + std::to_string(ms.count()));
    return 0;
  }
  if (role == "stuck" && argc == 5) {
    auto reader = core.subscribe<std::uint64_t>(topic, {}, {.capacity = arg(4), .overflow = Overflow::block}).subscribe();
    say("subscribed");
    forever();
  }
  if (role == "count" && argc == 6) {
    auto reader = core.subscribe<std::uint64_t>(topic, {}, {.capacity = arg(4), .overflow = Overflow::block}).subscribe();
    say("subscribed");
    std::uint64_t wrong = 0;
    std::vector<Sample<shm::View<std::uint64_t>>> batch;
    for (std::uint64_t expected = 0; expected < arg(5);) {
      batch.clear();
      auto got = reader.read_some(batch, 64, Clock::now() + 30s);
      if (!got) fail(got.error().describe() + " after " + std::to_string(expected));
      for (const auto& s : batch) wrong += *s.value != expected++ ? 1 : 0;
    }
    say("ok wrong=" + std::to_string(wrong) + " lost=" + std::to_string(reader.lost()));
    return 0;
  }
  if (role == "fill" && argc == 5) {
    auto publisher = core.publisher<std::uint64_t>(topic, {.capacity = arg(4), .overflow = Overflow::block,
                                                           .block_timeout = 1h});
    say("publishing");
    for (std::uint64_t i = 0;; ++i)
      if (auto sent = publisher.publish(i); !sent) fail(sent.error().describe());
  }
  if (role == "receive" && argc == 5) {
    auto reader = core.subscribe<std::uint64_t>(topic).subscribe();
    say("subscribed");
    for (std::uint64_t i = 0; i < arg(4); ++i) {
      auto got = reader.read_for(30s);
      if (!got) fail(got.error().describe());
    }
    say("received");
    forever();
  }
  if (role == "sync" && argc == 4) {
    const shm::TopicQos qos{.capacity = 16, .max_held = 4};
    liberty::Core local;
    auto sets = sync(exact_time, core.subscribe<std::uint64_t>("sync/lidar", {}, qos),
                     core.subscribe<std::uint64_t>("sync/odom", {}, qos));
    std::atomic<std::uint64_t> matched{0}, wrong{0};
    auto checked = sets | local.chain([&](const std::tuple<shm::View<std::uint64_t>, shm::View<std::uint64_t>>& set) {
                     wrong += *std::get<0>(set) == *std::get<1>(set) ? 0 : 1;
                     std::this_thread::sleep_for(1ms);  // a slow consumer: sets wait for it
                     return ++matched;
                   });
    auto newest = collector(local, sets, or_nothing);
    say("subscribed");
    const auto end = Clock::now() + std::chrono::seconds{arg(3)};
    std::uint64_t polled = 0;
    while (Clock::now() < end) {
      if (auto set = newest(Token{})) {  // held until the next call, like a control loop
        const auto& [lidar, odom] = *set;
        polled += *lidar == *odom ? 1 : 0;
      }
      std::this_thread::sleep_for(20ms);  // the control loop's period
    }
    say("matched=" + std::to_string(matched.load()) + " wrong=" + std::to_string(wrong.load()) +
        " polled=" + std::to_string(polled));
    return 0;
  }
  if (role == "memory" && argc == 3) {
    using test::Image;
    try {
      auto huge = core.publisher<Image>("huge");
      say("huge created");
    } catch (const Failure& f) {
      say("refused " + std::string{to_string(f.error().code)} + ": " + f.error().message);
    }
    auto fits = core.publisher<Image>("fits", {.capacity = 16, .max_subscribers = 1, .max_held = 2});
    for (int i = 0; i < 700; ++i) {
      auto loan = fits.loan();
      if (!loan) fail(loan.error().describe());
      for (std::size_t at = 0; at < sizeof(Image); at += 4096) (*loan)->pixels[at] = std::byte(i);
      std::move(*loan).publish();
    }
    say("published 700");
    return 0;
  }
  if (role == "checksum_publish" &&
      (argc == 5 || (argc == 6 && (std::string_view{argv[5]} == "batches" || std::string_view{argv[5]} == "block_batches")))) {
    const bool block = argc == 6 && std::string_view{argv[5]} == "block_batches";
    auto publisher = core.publisher<test::Checked>(topic, block ? test::kCheckedBlockQos : test::kCheckedQos);
    for (std::uint64_t i = 0, round = 0; i < arg(4); ++round) {
      if (argc == 6) {
        auto batch = publisher.loan_some(std::min<std::uint64_t>(1 + round % 4, arg(4) - i));
        if (!batch) fail(batch.error().describe());
        for (std::size_t k = 0; k < batch->size(); ++k) test::fill((*batch)[k], i++);
        std::move(*batch).publish();
        continue;
      }
      auto loan = publisher.loan();
      if (!loan) fail(loan.error().describe());
      test::fill(**loan, i++);
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
  if (role == "batch_publish" && argc == 5) {
    auto publisher = core.publisher<std::uint64_t>(topic, test::kSequenceQos);
    say("ready");
    for (std::uint64_t i = 0, round = 0; i < arg(4); ++round) {
      auto batch = publisher.loan_some(std::min<std::uint64_t>(1 + round % 61, arg(4) - i));  // 1 to 61 at a time
      if (!batch) fail(batch.error().describe());
      for (std::size_t k = 0; k < batch->size(); ++k) (*batch)[k] = i++;
      std::move(*batch).publish();
    }
    say("published");
    return 0;
  }
  if (role == "leave_segments" && argc == 4) {
    auto publisher = core.publisher<std::uint64_t>(topic);
    (void)publisher.publish(42);
    say("created");
    forever();
  }
  if (role == "loop" && argc == 5) {
    const auto period = std::chrono::milliseconds{arg(4)};
    std::atomic<bool> said{false};
    auto loop = every(core, period, [&](Token) {
      const auto tick = this_tick();
      if (tick->cycle == 3) std::this_thread::sleep_for(2 * period);
      if (tick->cycle >= 5 && !said.exchange(true)) say("looping");
    }, {.name = topic});
    forever();
  }
  if (role == "signalfd" && argc == 4) {
    // As a daemon with an event loop does: its signals read from a
    // signalfd, set up after the core has started its workers (which must
    // take none of them: a signal this thread blocks goes to one that does
    // not).
    (void)core.serve(topic, [](const std::int64_t& x) { return x + 1; }, {.workers = 2});
    sigset_t term;
    sigemptyset(&term);
    sigaddset(&term, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &term, nullptr);
    const int fd = signalfd(-1, &term, SFD_CLOEXEC);
    if (fd < 0) fail("signalfd");
    say("ready");
    pollfd p{fd, POLLIN, 0};
    signalfd_siginfo info{};
    if (poll(&p, 1, 30'000) != 1 || read(fd, &info, sizeof info) != sizeof info || info.ssi_signo != SIGTERM)
      fail("no SIGTERM on the signalfd within 30 s");
    say("took SIGTERM");
    return 0;
  }
  if (role == "serve" && argc == 5) {
    const std::string kind = argv[4];
    if (kind == "echo")
      (void)core.serve(topic, [](const test::Ask& a) { return test::Answer{a.who, a.n * 3}; }, {.workers = 2});
    else if (kind == "twice")
      (void)core.serve(topic, [](const std::int64_t& x) { return 2 * x; });
    else if (kind == "plus")
      (void)core.serve(topic, [](const std::int64_t& x) { return x + 1; });
    else if (kind == "hang")
      (void)core.serve(topic, [](const std::int64_t& x) -> std::int64_t {
        say("running");
        forever();
        return x;
      });
    else
      fail("unknown service kind " + kind);
    say("serving");
    forever();
  }
  if (role == "ticks" && argc == 6) {
    auto publisher = core.publisher<test::Tick>(topic);
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / static_cast<double>(arg(4))));
    const auto age = std::chrono::milliseconds{arg(5)};
    say("publishing");
    std::uint64_t n = 0;
    for (auto next = Clock::now();; next += period) {
      std::this_thread::sleep_until(next);
      test::Tick tick{n, static_cast<double>(n) / 2, bounded_string<8>{"t" + std::to_string(n % 100)}};
      ++n;
      if (auto sent = publisher.publish(tick, Clock::now() - age); !sent) fail(sent.error().describe());
    }
  }
  if (role == "raw" && argc == 4) {
    auto publisher = core.publisher<test::Raw>(topic);
    auto reader = core.subscribe<test::Raw>(topic).subscribe();  // so the topic keeps its sample for a late observer
    say("ready");
    for (int i = 0;; ++i) {
      if (auto sent = publisher.publish({0x1122334455667788ull, 42}); !sent) fail(sent.error().describe());
      std::this_thread::sleep_for(20ms);
    }
  }
  if (role == "listen" && argc == 4) {
    auto reader = core.subscribe<test::Tick>(topic).subscribe();
    say("listening");
    while (true) {
      auto got = reader.read_for(1h);
      if (got) say("tick " + std::to_string(got->value->n) + " " + std::to_string(got->value->x) + " " + got->value->tag.str());
    }
  }
  if (role == "call_many" && argc == 6) {
    auto echo = core.chain<test::Ask, test::Answer>(topic, {.timeout = 30s});
    std::atomic<std::uint64_t> right{0}, wrong{0};
    {
      std::vector<std::jthread> threads;
      for (std::uint64_t t = 0; t < arg(4); ++t)
        threads.emplace_back([&, t] {
          const auto who = static_cast<std::uint64_t>(::getpid()) * 100 + t;
          for (std::uint64_t i = 0; i < arg(5); ++i) {
            auto got = echo.call({who, i});
            if (got && got->who == who && got->n == 3 * i)
              ++right;
            else
              ++wrong;
          }
        });
    }
    say("ok " + std::to_string(right.load()) + " wrong " + std::to_string(wrong.load()));
    return 0;
  }
  if (role == "call_once" && argc == 5) {
    auto service = core.chain<std::int64_t, std::int64_t>(topic, {.timeout = 1h});
    say("calling");
    auto got = service.call(static_cast<std::int64_t>(arg(4)));
    say(got ? "answer " + std::to_string(*got) : "error " + got.error().describe());
    forever();
  }
  if (role == "emitter" && argc == 3) {
    auto lidar = core.publisher<int>("lidar", test::kEmitterTopics);
    auto odom = core.publisher<int>("odom", test::kEmitterTopics);
    auto odom_x = core.publisher<double>("odom_x", test::kEmitterTopics);
    (void)core.serve("emit", [&](const test::Emit& e) -> std::int64_t {
      const Clock::time_point stamp{Clock::duration{e.stamp_ns}};
      const auto sent = e.topic == 0   ? lidar.publish(e.value, stamp)
                        : e.topic == 1 ? odom.publish(e.value, stamp)
                                       : odom_x.publish(static_cast<double>(e.value), stamp);
      if (!sent) fail(sent.error().describe());
      return e.value;
    });
    say("serving");
    forever();
  }
  fail("unknown role or wrong arguments: " + role);
}
