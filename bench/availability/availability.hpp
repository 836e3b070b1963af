#pragma once

// What both media of prime_availability share: the configurations, the
// request and its header, the service's job, the ledger where the service
// notes which of the main client's requests it ran, the main client's
// schedule, the extra clients' loop and the response-time statistics.
// main.cpp says what is measured and how; shm_service.cpp and
// optimus_service.cpp hold one medium each.

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <numeric>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "harness.hpp"

namespace prime::bench::availability {

namespace ipc = prime::bench::ipc;
using namespace std::chrono_literals;
using SteadyClock = std::chrono::steady_clock;

// ---- configurations --------------------------------------------------------

inline constexpr std::int64_t kPeriodsMs[] = {1, 10, 100};
inline constexpr std::int64_t kChars[] = {10, 1000, 20000};
inline constexpr std::int64_t kExtraClients[] = {0, 5};

// Requests the main client sends per availability configuration: at most
// this many, and no more than fit in kSendingTime.
inline constexpr std::size_t kMaxRequests = 200;
inline constexpr auto kSendingTime = 2s;
// Synchronous calls per response-time configuration.
inline constexpr std::size_t kShmResponseCalls = 500;
inline constexpr std::size_t kOptimusResponseCalls = 200;
inline constexpr int kWarmUpCalls = 10;

// The deadline of every call, and how long the main client waits after its
// last request for the service to run what is still queued.
inline constexpr auto kCallTimeout = 1000ms;
inline constexpr auto kDrainTime = 1000ms;

// An extra client waits a uniform 1..20 ms between the end of one call and
// the start of the next.
inline constexpr auto kExtraMinGap = 1ms;
inline constexpr auto kExtraMaxGap = 20ms;

// The extra clients of one configuration: `count` processes of the child
// entry `entry`, started, ready and let go together.
inline void start_extra_clients(ipc::Links& links, const std::string& entry, std::size_t count, std::size_t chars,
                                const std::vector<std::string>& args) {
  for (std::size_t c = 0; c < count; ++c) links.start(entry, chars, {}, args);
  links.wait_ready();
  links.go();
}

// The requests of one availability configuration: min(kMaxRequests,
// kSendingTime / period), lowered by PRIME_AVAILABILITY_REQUESTS=<n> (a
// quick run), at least one.
inline std::size_t requests_for(std::chrono::milliseconds period) {
  std::size_t n = std::min<std::size_t>(kMaxRequests, static_cast<std::size_t>(kSendingTime / period));
  if (const char* cap = std::getenv("PRIME_AVAILABILITY_REQUESTS"); cap && *cap)
    n = std::min<std::size_t>(n, static_cast<std::size_t>(std::max(1L, std::strtol(cap, nullptr, 10))));
  return std::max<std::size_t>(n, 1);
}

inline void availability_configurations(benchmark::internal::Benchmark* b) {
  for (const auto period : kPeriodsMs)
    for (const auto chars : kChars)
      for (const auto extra : kExtraClients) b->Args({period, chars, extra});
  b->Iterations(1)->UseManualTime()->Unit(benchmark::kMillisecond);
}

inline void response_configurations(benchmark::internal::Benchmark* b) {
  for (const auto chars : kChars)
    for (const auto extra : kExtraClients) b->Args({chars, extra});
  b->Iterations(1)->UseManualTime()->Unit(benchmark::kMicrosecond);
}

// ---- the request -----------------------------------------------------------

// Who sent a request, its number and when (steady clock, nanoseconds: one
// clock for every process of the machine). It precedes the text on both
// media, so a request is kHeaderSize + chars bytes.
struct Header {
  enum : std::uint32_t { kMain = 0x4d41494e, kExtra = 0x45585452 };  // "MAIN", "EXTR"
  std::uint32_t from = kMain;
  std::uint32_t reserved = 0;
  std::uint64_t seq = 0;
  std::int64_t sent_ns = 0;
};
inline constexpr std::size_t kHeaderSize = sizeof(Header);
static_assert(kHeaderSize == 24);

inline std::int64_t now_ns() { return SteadyClock::now().time_since_epoch().count(); }

// A request of `chars` characters of lower-case text after `header`.
inline std::string make_request(const Header& header, std::size_t chars) {
  static constexpr std::string_view kText = "the quick brown fox jumps over the lazy robot, ";
  std::string request(kHeaderSize + chars, '\0');
  std::memcpy(request.data(), &header, kHeaderSize);
  for (std::size_t i = 0; i < chars; ++i) request[kHeaderSize + i] = kText[i % kText.size()];
  return request;
}

inline void set_header(std::span<char> request, const Header& header) { std::memcpy(request.data(), &header, kHeaderSize); }

inline Header header_of(std::string_view request) {
  Header h{};
  if (request.size() >= kHeaderSize) std::memcpy(&h, request.data(), kHeaderSize);
  return h;
}

inline std::string_view text_of(std::string_view request) {
  return request.size() >= kHeaderSize ? request.substr(kHeaderSize) : std::string_view{};
}

// ---- the service's job -----------------------------------------------------

// Upper-cases the text (into a buffer of the calling thread) and returns the
// FNV-1a checksum of the result: work proportional to the payload, the same
// on both media.
inline std::uint64_t shout(std::string_view text) {
  thread_local std::string upper;
  upper.resize(text.size());
  std::transform(text.begin(), text.end(), upper.begin(),
                 [](char c) { return c >= 'a' && c <= 'z' ? static_cast<char>(c - 'a' + 'A') : c; });
  std::uint64_t hash = 14695981039346656037ull;
  for (const char c : upper) hash = (hash ^ static_cast<unsigned char>(c)) * 1099511628211ull;
  return hash;
}

// ---- what the service ran --------------------------------------------------

// Written where the service runs: when (steady ns) it started each of the
// main client's requests, and how many extra clients' requests it ran. In
// shared memory for Shm, in this process for Optimus.
struct Ledger {
  std::atomic<std::int64_t> ran_at_ns[kMaxRequests];
  std::atomic<std::uint64_t> extra_calls;
};
static_assert(std::atomic<std::int64_t>::is_always_lock_free);

// The service's side: note the request, then do the job.
inline std::uint64_t serve_request(Ledger& ledger, std::string_view request) {
  const auto started = now_ns();
  const Header h = header_of(request);
  if (h.from == Header::kMain && h.seq < kMaxRequests) {
    std::int64_t never = 0;
    ledger.ran_at_ns[h.seq].compare_exchange_strong(never, started);
  } else if (h.from == Header::kExtra) {
    ledger.extra_calls.fetch_add(1, std::memory_order_relaxed);
  }
  return shout(text_of(request));
}

inline void clear(Ledger& ledger) {
  for (auto& t : ledger.ran_at_ns) t.store(0);
  ledger.extra_calls.store(0);
}

inline std::size_t executed(const Ledger& ledger, std::size_t sent) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < sent; ++i) n += ledger.ran_at_ns[i].load() != 0 ? 1 : 0;
  return n;
}

// ---- the main client -------------------------------------------------------

struct Sending {
  std::size_t sent = 0;
  std::size_t refused = 0;
  std::vector<std::int64_t> sent_at_ns;  // per request
  std::string first_refusal;             // what the medium said, the first time it refused
  SteadyClock::duration took{};
};

// Sends `n` requests, one every `period` (a fixed schedule: a late send does
// not move the next one); `post(seq, sent_ns)` returns nullopt if the medium
// took the request, or why it refused it. `check()` runs between sends (throws if a peer is gone).
template <class Post, class Check>
Sending send_periodically(std::size_t n, std::chrono::milliseconds period, Post post, Check check) {
  Sending s;
  s.sent_at_ns.resize(n);
  const auto start = SteadyClock::now();
  for (std::size_t seq = 0; seq < n; ++seq) {
    std::this_thread::sleep_until(start + seq * period);
    check();
    s.sent_at_ns[seq] = now_ns();
    ++s.sent;
    if (auto refusal = post(seq, s.sent_at_ns[seq])) {
      if (s.refused++ == 0) s.first_refusal = std::move(*refusal);
    }
  }
  s.took = SteadyClock::now() - start;
  return s;
}

// Reports availability, sent, executed, refused, on_time (run by the
// service before the next request was due) and extra_calls.
inline void report_availability(benchmark::State& state, const Sending& s, const Ledger& ledger,
                                std::chrono::milliseconds period) {
  const auto done = executed(ledger, s.sent);
  std::size_t on_time = 0;
  const auto period_ns = std::chrono::nanoseconds{period}.count();
  for (std::size_t i = 0; i < s.sent; ++i) {
    const auto ran = ledger.ran_at_ns[i].load();
    if (ran != 0 && ran - s.sent_at_ns[i] < period_ns) ++on_time;
  }
  state.counters["availability"] = s.sent == 0 ? 0.0 : static_cast<double>(done) / static_cast<double>(s.sent);
  state.counters["sent"] = static_cast<double>(s.sent);
  state.counters["executed"] = static_cast<double>(done);
  state.counters["refused"] = static_cast<double>(s.refused);
  state.counters["on_time"] = static_cast<double>(on_time);
  state.counters["extra_calls"] = static_cast<double>(ledger.extra_calls.load());
  if (s.refused > 0) state.SetLabel("first refusal: " + s.first_refusal);
  state.SetIterationTime(std::chrono::duration<double>{s.took}.count());
}

// ---- the extra clients -----------------------------------------------------

// An extra client's life in its own process: until the parent stops it,
// wait a uniform 1..20 ms, then `call(seq)` synchronously. A call the medium
// refuses or lets time out is simply the next one's loss; `call` throws on
// anything else.
template <class Call>
void call_at_random_intervals(ipc::Child& self, Call call) {
  std::mt19937_64 random{static_cast<std::uint64_t>(::getpid()) ^ static_cast<std::uint64_t>(now_ns())};
  std::uniform_int_distribution<std::int64_t> gap_us{std::chrono::microseconds{kExtraMinGap}.count(),
                                                     std::chrono::microseconds{kExtraMaxGap}.count()};
  self.ready();
  for (std::uint64_t seq = 0;; ++seq) {
    std::this_thread::sleep_for(std::chrono::microseconds{gap_us(random)});
    self.check();
    call(seq);
  }
}

// ---- response time ---------------------------------------------------------

// Times `n` calls, `call(seq)` each (after a few untimed), and reports
// mean_ns, p50_ns, p99_ns, max_ns, outliers (samples above 10 × the median:
// reported, never dropped) and outlier_share.
template <class Call>
void time_calls(benchmark::State& state, std::size_t n, Call call) {
  for (int i = 0; i < kWarmUpCalls; ++i) call(static_cast<std::uint64_t>(i));
  std::vector<std::int64_t> samples(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto start = SteadyClock::now();
    call(kWarmUpCalls + i);
    samples[i] = (SteadyClock::now() - start).count();
  }
  const double total = static_cast<double>(std::accumulate(samples.begin(), samples.end(), std::int64_t{0}));
  std::sort(samples.begin(), samples.end());
  auto at = [&](double q) {
    return static_cast<double>(samples[std::min(n - 1, static_cast<std::size_t>(q * static_cast<double>(n)))]);
  };
  const double median = at(0.5);
  const auto outliers =
      static_cast<std::size_t>(samples.end() - std::upper_bound(samples.begin(), samples.end(),
                                                                 static_cast<std::int64_t>(10.0 * median)));
  state.counters["calls"] = static_cast<double>(n);
  state.counters["mean_ns"] = total / static_cast<double>(n);
  state.counters["p50_ns"] = median;
  state.counters["p99_ns"] = at(0.99);
  state.counters["max_ns"] = static_cast<double>(samples.back());
  state.counters["outliers"] = static_cast<double>(outliers);
  state.counters["outlier_share"] = static_cast<double>(outliers) / static_cast<double>(n);
  state.SetIterationTime(total * 1e-9 / static_cast<double>(n));  // the mean call
}

// Runs one benchmark's body once, turning what it throws into
// state.SkipWithError.
template <class Body>
void run_once(benchmark::State& state, Body body) {
  for (auto _ : state) {
    try {
      body();
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
    }
  }
}

}  // namespace prime::bench::availability
