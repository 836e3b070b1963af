// The Optimus side of prime_availability, on a redis-server this binary
// starts itself (persistence off, a free loopback port):
//
//   parent, a worker thread    hosts "shout" (std::string in, checksum out) with a
//                              Core of its own, noting the main client's requests
//                              in a Ledger
//   parent, the main client    another Core: posts every period through four sender
//                              threads (availability) or calls and waits (response)
//   children "Availability.optimus_extra"
//                              0 or 5 extra client processes, calling at random
//                              intervals of 1..20 ms
//
// Redis is the hop between every pair, so the server and the main client
// sharing a process changes no path a request takes.
#include <unistd.h>

#include <condition_variable>
#include <deque>
#include <filesystem>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <vector>

#include "availability.hpp"
#include "optimus/support/redis_server.hpp"
#include "prime/optimus.hpp"

namespace {

namespace av = prime::bench::availability;
namespace ipc = prime::bench::ipc;
namespace optimus = prime::optimus;
using namespace std::chrono_literals;

using Shout = optimus::Chain<std::string, std::uint64_t>;

// The redis-server of this run, started on first use; nullptr (and why, in
// `why`) when it cannot be.
prime::test::RedisServer* redis(std::string& why) {
  static std::optional<prime::test::RedisServer> server;
  static std::string failure;
  if (!server && failure.empty()) {
    if (::access(PRIME_REDIS_SERVER, X_OK) != 0) {
      failure = "redis-server is not installed";
    } else {
      try {
        server.emplace();
      } catch (const std::exception& e) {
        failure = std::string{"redis-server did not start: "} + e.what();
      }
    }
  }
  why = failure;
  return server ? &*server : nullptr;
}

std::string new_domain() {
  static int next = 0;
  return "availability-" + std::to_string(::getpid()) + "-" + std::to_string(next++);
}

bool lost_only(const prime::Error& e) { return e.code == prime::Errc::timeout; }

// ---- the extra clients -----------------------------------------------------

// arg(0): the server's URL; arg(1): the domain; bytes(): the text's length.
void extra_client(ipc::Child& self) {
  optimus::Core core{{.url = self.arg(0), .domain = self.arg(1)}};
  auto service = core.service<std::string, std::uint64_t>("shout", {.timeout = av::kCallTimeout});
  auto request = av::make_request({.from = av::Header::kExtra}, self.bytes());
  av::call_at_random_intervals(self, [&](std::uint64_t seq) {
    av::set_header(request, {.from = av::Header::kExtra, .seq = seq, .sent_ns = av::now_ns()});
    auto got = service.call(request);
    if (!got && !lost_only(got.error())) throw ipc::PeerError{"extra client: " + got.error().describe()};
  });
}
const ipc::ChildEntry kExtra{"Availability.optimus_extra", extra_client};

// ---- the main client's posts -----------------------------------------------

// Optimus chains have no post: the main client hands each request to one of
// kSenders threads, which calls and drops the answer. At most kSenders
// requests are under way at once (as an Shm client has calls_per_client = 4
// cells); a request finding all of them busy is refused.
class Poster {
 public:
  static constexpr std::size_t kSenders = 4;

  explicit Poster(Shout service) : service_{std::move(service)} {
    for (std::size_t i = 0; i < kSenders; ++i)
      senders_.emplace_back([this](std::stop_token stop) { send(stop); });
  }
  Poster(const Poster&) = delete;
  Poster& operator=(const Poster&) = delete;
  ~Poster() {
    for (auto& s : senders_) s.request_stop();
    wake_.notify_all();
  }

  // Queues `request` for a free sender: nullopt, or why it is refused.
  std::optional<std::string> post(std::string request) {
    std::scoped_lock lock{mutex_};
    if (busy_ + queue_.size() >= kSenders)
      return std::to_string(kSenders) + " requests under way already (" + std::to_string(queue_.size()) +
             " of them not yet taken by a sender)";
    queue_.push_back(std::move(request));
    wake_.notify_one();
    return std::nullopt;
  }

  // Waits until every request is answered or has timed out (each call's
  // deadline is kCallTimeout); false if that takes longer than `patience`.
  bool wait_idle(std::chrono::milliseconds patience) {
    std::unique_lock lock{mutex_};
    return idle_.wait_for(lock, patience, [this] { return busy_ == 0 && queue_.empty(); });
  }

  // The first failure that was not a timeout, if any.
  std::optional<std::string> failure() {
    std::scoped_lock lock{mutex_};
    return failure_;
  }

 private:
  void send(const std::stop_token& stop) {
    std::unique_lock lock{mutex_};
    while (true) {
      if (!wake_.wait(lock, stop, [this] { return !queue_.empty(); })) return;
      auto request = std::move(queue_.front());
      queue_.pop_front();
      ++busy_;
      lock.unlock();
      auto got = service_.call(request);
      lock.lock();
      if (!got && !lost_only(got.error()) && !failure_) failure_ = got.error().describe();
      --busy_;
      idle_.notify_all();
    }
  }

  Shout service_;
  std::mutex mutex_;
  std::condition_variable_any wake_;
  std::condition_variable idle_;
  std::deque<std::string> queue_;
  std::size_t busy_ = 0;
  std::optional<std::string> failure_;
  std::vector<std::jthread> senders_;  // last: they use what is above
};

// ---- one configuration -----------------------------------------------------

// The server (a Core of this process), the extra client processes, and the
// main client's Core. Extra clients are stopped first, then the server.
class Setup {
 public:
  Setup(const prime::test::RedisServer& redis, std::size_t chars, std::size_t extra_clients)
      : url_{redis.url()}, domain_{new_domain()}, server_{{.url = url_, .domain = domain_}} {
    av::clear(ledger_);
    (void)server_.serve("shout", [this](std::string request) { return av::serve_request(ledger_, request); });
    client_.emplace(optimus::Options{.url = url_, .domain = domain_});
    av::start_extra_clients(extras_.emplace(), "Availability.optimus_extra", extra_clients, chars,
                            std::vector<std::string>{url_, domain_});
  }
  Setup(const Setup&) = delete;
  Setup& operator=(const Setup&) = delete;
  ~Setup() {
    extras_.reset();
    client_.reset();
    server_.stop();
  }

  Shout service() { return client_->service<std::string, std::uint64_t>("shout", {.timeout = av::kCallTimeout}); }
  av::Ledger& ledger() { return ledger_; }

  void check() { extras_->check(); }
  void stop() { extras_->stop(); }

 private:
  std::string url_;
  std::string domain_;
  av::Ledger ledger_;
  optimus::Core server_;
  std::optional<optimus::Core> client_;
  std::optional<ipc::Links> extras_;
};

template <class Body>
void with_redis(benchmark::State& state, Body body) {
  std::string why;
  auto* server = redis(why);
  if (!server) {
    for (auto _ : state) state.SkipWithError(why.c_str());
    return;
  }
  av::run_once(state, [&] { body(*server); });
}

void BM_Availability_Optimus(benchmark::State& state) {
  with_redis(state, [&](const prime::test::RedisServer& redis) {
    const std::chrono::milliseconds period{state.range(0)};
    const auto chars = static_cast<std::size_t>(state.range(1));
    Setup setup{redis, chars, static_cast<std::size_t>(state.range(2))};
    auto service = setup.service();
    auto request = av::make_request({.from = av::Header::kExtra}, chars);
    // One call first, untimed and not counted: the service is up and answers.
    if (auto first = service.call(request); !first) throw ipc::PeerError{"optimus service: " + first.error().describe()};
    av::clear(setup.ledger());

    Poster poster{service};
    const auto n = av::requests_for(period);
    auto sending = av::send_periodically(
        n, period,
        [&](std::size_t seq, std::int64_t sent_ns) {
          av::set_header(request, {.from = av::Header::kMain, .seq = seq, .sent_ns = sent_ns});
          return poster.post(request);
        },
        [&] { setup.check(); });
    if (!poster.wait_idle(av::kCallTimeout + av::kDrainTime))
      throw ipc::PeerError{"optimus: the main client's calls outlived their deadline"};
    if (auto failure = poster.failure()) throw ipc::PeerError{"optimus service: " + *failure};
    av::report_availability(state, sending, setup.ledger(), period);
    setup.stop();
  });
}
BENCHMARK(BM_Availability_Optimus)->Apply(av::availability_configurations);

void BM_Response_Optimus(benchmark::State& state) {
  with_redis(state, [&](const prime::test::RedisServer& redis) {
    const auto chars = static_cast<std::size_t>(state.range(0));
    Setup setup{redis, chars, static_cast<std::size_t>(state.range(1))};
    auto service = setup.service();
    auto request = av::make_request({}, chars);
    const auto expected = av::shout(av::text_of(request));
    av::time_calls(state, av::kOptimusResponseCalls, [&](std::uint64_t seq) {
      av::set_header(request, {.from = av::Header::kMain, .seq = av::kMaxRequests + seq, .sent_ns = av::now_ns()});
      auto got = service.call(request);
      if (!got) throw ipc::PeerError{"optimus service: " + got.error().describe()};
      if (*got != expected) throw ipc::PeerError{"optimus service: a wrong checksum"};
      if (seq % 16 == 0) setup.check();
    });
    setup.stop();
  });
}
BENCHMARK(BM_Response_Optimus)->Apply(av::response_configurations);

}  // namespace
