#pragma once

#include <algorithm>
#include <atomic>
#include <charconv>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <expected>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <stop_token>
#include <string>
#include <unistd.h>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/options.hpp"

namespace prime::optimus::detail {

// Sleeps until `until`; false when a stop request ended it.
inline bool pause(Clock::time_point until, const std::stop_token& stop) {
  std::mutex m;
  std::condition_variable_any cv;
  std::unique_lock lock{m};
  cv.wait_until(lock, stop, until, [] { return false; });
  return !stop.stop_requested();
}

// Connections to one server, shared by every thread of a process that talks
// to it: a thread leases one for what it does and gives it back. A connection
// that broke is dropped, and so is every idle one opened before the break (the
// server may have restarted). After a failed connect, further attempts wait
// out a backoff that doubles up to a second, and callers meanwhile get the
// last error at once instead of a hang.
//
// Thread-safe.
class Pool : public std::enable_shared_from_this<Pool> {
 public:
  // A connection on loan; returned to the pool when the lease ends, unless it broke.
  class Lease {
   public:
    Lease(std::shared_ptr<Pool> pool, Connection connection, std::uint64_t epoch)
        : pool_{std::move(pool)}, connection_{std::move(connection)}, epoch_{epoch} {}
    Lease(Lease&&) noexcept = default;
    Lease& operator=(Lease&&) = delete;
    Lease(const Lease&) = delete;
    ~Lease() {
      if (pool_ && connection_ && connection_->valid()) pool_->give_back(std::move(*connection_), epoch_);
    }
    Connection* operator->() noexcept { return &*connection_; }
    Connection& operator*() noexcept { return *connection_; }

    // Drops the connection without suspecting the server: for one whose
    // socket a stop request shut down.
    void discard() noexcept { connection_.reset(); }

   private:
    std::shared_ptr<Pool> pool_;
    std::optional<Connection> connection_;
    std::uint64_t epoch_;
  };

  static std::shared_ptr<Pool> make(Options options) {
    auto endpoint = parse_url(options.url);
    if (!endpoint) throw Failure{endpoint.error()};
    return std::shared_ptr<Pool>{new Pool{std::move(options), std::move(*endpoint)}};
  }

  std::expected<Lease, Error> acquire() {
    std::uint64_t epoch;
    std::optional<Connection> idle;
    bool clock_due = false;
    {
      std::scoped_lock lock{mutex_};
      epoch = epoch_;
      while (!idle && !idle_.empty()) {
        auto [connection, born] = std::move(idle_.back());
        idle_.pop_back();
        if (born == epoch_) idle.emplace(std::move(connection));
      }
      if (idle && Clock::now() >= clock_due_) {
        clock_due_ = Clock::now() + kClockEvery;
        clock_due = true;
      }
      if (!idle && Clock::now() < retry_after_) return std::unexpected(last_error_);
    }
    if (idle) {
      if (clock_due) learn_clock(*idle);  // one round trip, every kClockEvery
      return Lease{shared_from_this(), std::move(*idle), epoch};
    }
    auto connection = Connection::open(options_, endpoint_);
    if (connection) {
      if (auto learned = connection->learn_max_bulk(); !learned) connection = std::unexpected(std::move(learned.error()));
      else learn_clock(*connection);
    }
    std::scoped_lock lock{mutex_};
    if (!connection) {
      last_error_ = connection.error();
      backoff_ = std::clamp(backoff_ * 2, kFirstBackoff, kMaxBackoff);
      retry_after_ = Clock::now() + backoff_;
      ++epoch_;  // whatever is idle dates from before the failure
      return std::unexpected(std::move(connection.error()));
    }
    backoff_ = std::chrono::milliseconds{0};
    clock_due_ = Clock::now() + kClockEvery;
    return Lease{shared_from_this(), std::move(*connection), epoch};
  }

  // Waits until a connection can be had, or `deadline`, or `stop`: for workers
  // that must ride out a server restart. Sleeps between attempts.
  std::expected<Lease, Error> acquire_until(Clock::time_point deadline, std::stop_token stop) {
    while (true) {
      auto lease = acquire();
      if (lease || stop.stop_requested() || Clock::now() >= deadline) return lease;
      std::unique_lock lock{mutex_};
      const auto until = std::min(deadline, std::max(retry_after_, Clock::now() + kFirstBackoff));
      wake_.wait_until(lock, stop, until, [] { return false; });
      if (stop.stop_requested()) return std::unexpected(Error{Errc::stopped, "redis at " + url() + ": stopped while reconnecting"});
    }
  }

  // Blocking calls (a chain call waiting for its answer) register here while
  // they wait, so that stopping a core can end them: its workers may be
  // waiting for services that are being stopped too. While closed, new calls
  // fail at once with Errc::stopped.
  [[nodiscard]] bool begin_call(const Connection& c) {
    std::scoped_lock lock{calls_mutex_};
    if (closed_) return false;
    calls_.push_back(&c);
    return true;
  }
  void end_call(const Connection& c) {
    {
      std::scoped_lock lock{calls_mutex_};
      std::erase(calls_, &c);
    }
    calls_done_.notify_all();
  }
  [[nodiscard]] bool calls_closed() {
    std::scoped_lock lock{calls_mutex_};
    return closed_;
  }
  // New calls fail from now on; calls under way get `grace` to finish (their
  // answers may be on the way), then their waits are cut.
  void close_calls(std::chrono::milliseconds grace) {
    std::unique_lock lock{calls_mutex_};
    closed_ = true;
    calls_done_.wait_for(lock, grace, [&] { return calls_.empty(); });
    for (const auto* c : calls_) c->interrupt();
  }
  void reopen_calls() {
    std::scoped_lock lock{calls_mutex_};
    closed_ = false;
  }

  [[nodiscard]] const Options& options() const noexcept { return options_; }
  // The server's URL as messages show it (no password).
  [[nodiscard]] const std::string& url() const noexcept { return endpoint_.shown; }

  // The prefix of every key this pool's users touch (keys.hpp).
  [[nodiscard]] const std::string& domain() const noexcept { return options_.domain; }

  // The server's clock now, in ms since the epoch: this machine's system
  // clock and how far the server's is ahead of it, which the pool measures
  // on each connection it opens and, every kClockEvery, on one it lends
  // out. The deadlines of service calls are on the server's clock, so a
  // caller and a worker agree on them even when their machines' clocks do
  // not (robots off the network rarely keep theirs in step); to within
  // half a round trip.
  [[nodiscard]] std::int64_t server_ms() const {
    return system_ms_now() + server_ahead_ms_.load(std::memory_order_relaxed);
  }

  // A name no other process shares: for reply keys and anonymous services.
  [[nodiscard]] const std::string& process_id() const noexcept { return process_id_; }
  [[nodiscard]] std::uint64_t next_id() noexcept { return next_id_.fetch_add(1, std::memory_order_relaxed); }

 private:
  static constexpr std::chrono::milliseconds kFirstBackoff{10};
  static constexpr std::chrono::milliseconds kMaxBackoff{1000};
  static constexpr std::size_t kMaxIdle = 32;
  static constexpr std::chrono::seconds kClockEvery{10};  // clocks off the network drift by ms a minute

  Pool(Options options, Endpoint endpoint) : options_{std::move(options)}, endpoint_{std::move(endpoint)} {
    std::random_device entropy;
    const std::uint64_t r = (std::uint64_t{entropy()} << 32) ^ entropy() ^
                            static_cast<std::uint64_t>(Clock::now().time_since_epoch().count());
    char buffer[48];
    const int n = std::snprintf(buffer, sizeof buffer, "%d.%016llx", static_cast<int>(::getpid()),
                                static_cast<unsigned long long>(r));
    process_id_.assign(buffer, static_cast<std::size_t>(n));
  }

  static std::int64_t system_ms_now() {
    return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
  }

  // Asks the server for its clock (TIME) and keeps how far it is ahead of
  // this machine's, taking the reply as read halfway through the round
  // trip: so off by at most half of it. A round trip more than twice the
  // shortest seen (a server busy with a long command, this process
  // descheduled) says little, and is kept only when no better one came for
  // a minute (clocks drift). A failed ask changes nothing: the connection
  // says it broke when next used. Bounded as a connect is, whatever the
  // connection's last user waited for.
  void learn_clock(Connection& connection) {
    if (!connection.set_timeout(std::chrono::duration_cast<std::chrono::microseconds>(options_.connect_timeout))) return;
    const auto sent = std::chrono::system_clock::now();
    auto time = connection.command({"TIME"});
    const auto received = std::chrono::system_clock::now();
    if (!time || !(*time)->is_array() || (*time)->size() != 2) return;
    std::int64_t seconds = 0, micros = 0;
    const auto number = [](ReplyRef r, std::int64_t& out) {
      const auto t = r.text();
      return !t.empty() && std::from_chars(t.data(), t.data() + t.size(), out).ec == std::errc{};
    };
    if (!number((**time)[0], seconds) || !number((**time)[1], micros)) return;
    const auto round_trip = received - sent;
    const auto midway = std::chrono::duration_cast<std::chrono::microseconds>((sent + round_trip / 2).time_since_epoch());
    std::scoped_lock lock{clock_mutex_};
    const auto now = Clock::now();
    if (round_trip > 2 * best_round_trip_ && now < clock_kept_until_) return;
    best_round_trip_ = std::min(best_round_trip_, round_trip);
    clock_kept_until_ = now + std::chrono::minutes{1};
    server_ahead_ms_.store((seconds * 1'000'000 + micros - midway.count()) / 1000, std::memory_order_relaxed);
  }

  void give_back(Connection connection, std::uint64_t born) {
    std::scoped_lock lock{mutex_};
    if (connection.broken()) {
      ++epoch_;  // the server may have gone: do not trust the idle ones either
      return;
    }
    if (connection.pending() > 0) return;  // replies still due: not reusable
    if (born == epoch_ && idle_.size() < kMaxIdle) idle_.emplace_back(std::move(connection), born);
  }

  const Options options_;
  const Endpoint endpoint_;
  std::string process_id_;
  std::atomic<std::uint64_t> next_id_{1};
  std::mutex mutex_;
  std::condition_variable_any wake_;
  std::vector<std::pair<Connection, std::uint64_t>> idle_;
  std::uint64_t epoch_ = 0;
  std::chrono::milliseconds backoff_{0};
  Clock::time_point retry_after_{};
  Clock::time_point clock_due_{};  // when to measure the server's clock again
  std::atomic<std::int64_t> server_ahead_ms_{0};
  std::mutex clock_mutex_;  // for the two below
  std::chrono::system_clock::duration best_round_trip_ = std::chrono::system_clock::duration::max() / 4;
  Clock::time_point clock_kept_until_{};  // a measure kept until then is replaced only by a good one
  Error last_error_{Errc::unreachable, ""};
  std::mutex calls_mutex_;
  std::condition_variable calls_done_;
  std::vector<const Connection*> calls_;
  bool closed_ = false;
};

}  // namespace prime::optimus::detail
