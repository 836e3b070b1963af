#pragma once

// A small system for the placement tests: a counter publishes 1..limit
// from a periodic trigger; a doubler publishes each count times its factor
// and serves "triple"; a checker (reading each doubled value shared, the
// doubler each count as a value) calls "triple" on each doubled value and
// keeps what it got, and publishes it on "checked" (which nobody in the
// system reads, so it is in the Shm domain for a test outside). Registered by the test and by system_peer alike.

#include <atomic>
#include <condition_variable>
#include <stdexcept>
#include <string>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <vector>

#include "prime/system.hpp"
#include "prime/topology/forward.hpp"

namespace pipeline {

using namespace std::chrono_literals;

struct Count {
  std::int64_t n;
};
PRIME_DESCRIBE(Count, n)

inline prime::system::Component counter() {
  return prime::system::Component{"test.counter"}
      .publishes<Count>("counts", {.capacity = 256, .overflow = prime::Overflow::block})
      .every("tick", 2ms)
      .param("limit", 40, "how many counts, from 1")
      .build([](prime::system::Context& ctx) {
        auto out = ctx.output<Count>("counts");
        const auto limit = ctx.param<std::int64_t>("limit");
        ctx.every("tick", [out, limit, n = std::int64_t{0}](prime::Token) mutable {
          if (n < limit) (void)out.publish(Count{++n});
        });
      });
}

inline prime::system::Component doubler() {
  return prime::system::Component{"test.doubler"}
      .subscribes<Count>("counts", {.capacity = 256})
      .publishes<Count>("doubled", {.capacity = 256, .overflow = prime::Overflow::block})
      .serves<Count, Count>("triple")
      .param("factor", 2)
      .build([](prime::system::Context& ctx) {
        auto out = ctx.output<Count>("doubled");
        const auto factor = ctx.param<std::int64_t>("factor");
        prime::forward(ctx.input<Count>("counts"),
                       [out, factor](const Count& c, prime::Clock::time_point stamp) { (void)out.publish(Count{c.n * factor}, stamp); });
        ctx.serve<Count, Count>("triple", [](const Count& c) {
          if (c.n < 0) throw std::invalid_argument{"negative count"};
          return Count{c.n * 3};
        });
      });
}

// What the checker saw: each doubled value with the answer of "triple".
struct Seen {
  std::int64_t doubled, tripled;
  bool operator==(const Seen&) const = default;
};
PRIME_DESCRIBE(Seen, doubled, tripled)
struct Observed {
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<Seen> seen;
  std::vector<std::uintptr_t> where;  // of each doubled value the checker read (shared)
  std::vector<std::string> errors;

  void clear() {
    std::scoped_lock lock{mutex};
    seen.clear();
    where.clear();
    errors.clear();
  }
  // Whether `done(seen)` held within `timeout`.
  template <class Done>
  bool wait_for(std::chrono::milliseconds timeout, Done done) {
    std::unique_lock lock{mutex};
    return changed.wait_for(lock, timeout, [&] { return done(seen); });
  }
};
inline Observed& observed() {
  static Observed o;
  return o;
}

inline prime::system::Component checker() {
  return prime::system::Component{"test.checker"}
      .subscribes<Count>("doubled", {.capacity = 256})
      .calls<Count, Count>("triple", {.timeout = 2s, .wait_for_service = 5s})
      .publishes<Seen>("checked", {.capacity = 1024})
      .build([](prime::system::Context& ctx) {
        auto triple = ctx.client<Count, Count>("triple");
        auto checked = ctx.output<Seen>("checked");
        // Read shared: in place in shared memory from another process.
        prime::forward(ctx.shared_input<Count>("doubled"), [triple, checked](const std::shared_ptr<const Count>& doubled,
                                                                             prime::Clock::time_point) {
          const Count c = *doubled;
          auto answer = triple.call(c);
          auto& o = observed();
          {
            std::scoped_lock lock{o.mutex};
            o.where.push_back(reinterpret_cast<std::uintptr_t>(doubled.get()));
            if (answer) o.seen.push_back({c.n, answer->n});
            else o.errors.push_back(answer.error().describe());
          }
          o.changed.notify_all();
          if (answer) (void)checked.publish(Seen{c.n, answer->n});
        });
      });
}

inline void register_all() {
  static const bool done = [] {
    auto& registry = prime::system::Registry::global();
    registry.add(counter());
    registry.add(doubler());
    registry.add(checker());
    return true;
  }();
  (void)done;
}

}  // namespace pipeline
