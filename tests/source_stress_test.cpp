// In-process sources under load: many producers, slow consumers, both
// overflow policies. Run under ThreadSanitizer too (preset "tsan").
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <map>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

struct Tagged {
  int producer;
  int seq;
};

constexpr int kProducers = 4;
constexpr int kPerProducer = 5000;

// Counts what a reader received, checking that each producer's values arrive
// in order and never twice.
struct Tally {
  std::map<int, int> last_seq;
  std::size_t received = 0;
  bool in_order = true;

  void take(const Tagged& t) {
    auto [it, fresh] = last_seq.try_emplace(t.producer, -1);
    if (t.seq <= it->second) in_order = false;
    it->second = t.seq;
    ++received;
  }

  // Reads `expected` values, pausing 1 ms after every `pause_every` (0: never),
  // and stops early if one takes longer than 30 s.
  template <class R>
  void read(R& reader, int expected, int pause_every = 0) {
    for (int n = 0; n < expected; ++n) {
      auto s = reader.read_for(30s);
      if (!s) return;
      take(s->value);
      if (pause_every > 0 && n % pause_every == 0) std::this_thread::sleep_for(1ms);
    }
  }
};

// Every producer emits kPerProducer values; `emitted` counts them as they go.
void produce(Event<Tagged>& event, std::atomic<int>* emitted = nullptr) {
  std::vector<std::jthread> producers;
  for (int p = 0; p < kProducers; ++p)
    producers.emplace_back([&event, p, emitted] {
      for (int i = 0; i < kPerProducer; ++i) {
        event.emit({p, i});
        if (emitted) ++*emitted;
      }
    });
}

TEST(SourceStress, DropOldestUnderManyProducersLosesOnlyWhatItCounts) {
  liberty::Core core;
  Event<Tagged> event;
  auto source = core.source(event, "tagged", {.capacity = 64, .overflow = Overflow::drop_oldest});
  auto reader = source.subscribe();
  std::atomic<bool> done{false};
  std::atomic<int> emitted{0};
  Tally tally;
  std::jthread consumer{[&] {
    // A reader that falls behind: before it reads on, every 1000 values, it
    // lets the producers get two buffers ahead, so it does lose values.
    for (int n = 0;; ++n) {
      if (n % 1000 == 0) {
        const auto ahead = emitted.load() + 2 * 64;
        while (emitted.load() < std::min(ahead, kProducers * kPerProducer)) std::this_thread::yield();
      }
      auto s = reader.read_for(20ms);
      if (!s) {
        if (done) return;
        continue;
      }
      tally.take(s->value);
    }
  }};
  produce(event, &emitted);
  done = true;
  consumer.join();
  EXPECT_TRUE(tally.in_order);
  EXPECT_EQ(tally.received + reader.lost(), std::size_t{kProducers * kPerProducer});
  EXPECT_GE(reader.lost(), 64u) << "the reader fell two buffers behind at the start: one buffer's worth is lost";
}

TEST(SourceStress, BlockUnderManyProducersDeliversEverythingInOrder) {
  liberty::Core core;
  Event<Tagged> event;
  auto source = core.source(event, "tagged", {.capacity = 16, .overflow = Overflow::block, .block_timeout = 60s});
  auto reader = source.subscribe();
  Tally tally;
  std::jthread consumer{[&] { tally.read(reader, kProducers * kPerProducer, 256); }};  // a slow reader
  produce(event);
  consumer.join();
  EXPECT_TRUE(tally.in_order);
  EXPECT_EQ(tally.received, std::size_t{kProducers * kPerProducer});
  EXPECT_EQ(reader.lost(), 0u);
}

TEST(SourceStress, ASlowLossyReaderDoesNotHoldBackALosslessOne) {
  liberty::Core core;
  Event<Tagged> event;
  auto source = core.source(event, "tagged", {.capacity = 32, .overflow = Overflow::block, .block_timeout = 60s});
  auto lossless = (source | core.chain([](Tagged t) { return t; })).subscribe();
  auto lossy = source.subscribe({.capacity = 4, .overflow = Overflow::drop_oldest});
  Tally tally;
  std::jthread consumer{[&] { tally.read(lossless, kProducers * kPerProducer); }};
  produce(event);
  consumer.join();
  EXPECT_EQ(tally.received, std::size_t{kProducers * kPerProducer});
  EXPECT_TRUE(tally.in_order);
  EXPECT_EQ(lossy.read_all().size(), 4u);
  EXPECT_EQ(lossy.lost(), std::size_t{kProducers * kPerProducer - 4});
}

TEST(SourceStress, ReadersComeAndGoWhileProducersRun) {
  liberty::Core core;
  Event<Tagged> event;
  auto source = core.source(event, "tagged", {.capacity = 8, .overflow = Overflow::block, .block_timeout = 50ms});
  // A link is a lasting part of the topology (it runs until the core stops),
  // so links are made a few times; readers and collectors come and go freely.
  std::vector<LocalSource<int>> links;
  for (int i = 0; i < 4; ++i) links.push_back(source | core.chain([](Tagged t) { return t.seq; }));
  std::atomic<bool> stop{false};
  std::jthread churn{[&] {
    for (std::size_t n = 0; !stop; ++n) {
      auto reader = source.subscribe();
      auto linked = links[n % links.size()].subscribe();
      auto latest = collector(core, links[(n + 1) % links.size()]);
      (void)reader.try_read();
      (void)linked.read_for(1ms);
    }
  }};
  produce(event);
  stop = true;
  churn.join();
  SUCCEED() << "no crash, no hang, nothing for the sanitizers";
}

TEST(SourceStress, SyncMatchesEveryStampWhileItsInputsArriveConcurrently) {
  constexpr int kValues = 2000;
  liberty::Core core;
  const Qos lossless{.capacity = 64, .overflow = Overflow::block, .block_timeout = 60s};
  std::array<Event<int>, 3> events;
  auto a = core.source(events[0], "a", lossless);
  auto b = core.source(events[1], "b", lossless);
  auto c = core.source(events[2], "c", lossless);
  SyncPolicy policy = exact_time;
  policy.depth = kValues;  // room to wait for the slowest input: nothing is dropped
  auto triples = sync(policy, a, b, c).subscribe();
  const auto t0 = Clock::now();
  {
    std::vector<std::jthread> producers;
    for (auto& event : events)
      producers.emplace_back([&event, t0] {
        for (int i = 0; i < kValues; ++i) event.emit(i, t0 + std::chrono::microseconds{i});
      });
    for (int i = 0; i < kValues; ++i) {
      auto triple = triples.read_for(30s);
      ASSERT_TRUE(triple) << "triple " << i << ": " << triple.error().describe();
      EXPECT_EQ(triple->value, std::make_tuple(i, i, i));
      EXPECT_EQ(triple->stamp, t0 + std::chrono::microseconds{i});
    }
  }
  EXPECT_EQ(triples.lost(), 0u);
}

TEST(SourceStress, CoreDestroyedWhileProducersEmit) {
  for (int round = 0; round < 10; ++round) {
    Event<Tagged> event;
    std::optional<Reader<int>> reader;
    {
      auto core = std::make_unique<liberty::Core>();
      auto source = core->source(event, "tagged", {.capacity = 4, .overflow = Overflow::block, .block_timeout = 20ms});
      reader.emplace((source | core->chain([](Tagged t) { return t.seq; }) | core->chain([](int x) { return x; }))
                         .subscribe({.capacity = 2, .overflow = Overflow::block, .block_timeout = 20ms}));
      std::jthread producer{[&] {
        for (int i = 0; i < 500; ++i) event.emit({0, i});
      }};
      std::this_thread::sleep_for(2ms);
      core.reset();
    }
    EXPECT_LE(reader->read_all().size(), 2u);
  }
}

}  // namespace
}  // namespace prime::test
