#pragma once

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "optimus/support/redis_server.hpp"
#include "prime/optimus.hpp"
#include "prime/optimus/detail/connection.hpp"  // a raw connection, to look at and tamper with the server

namespace prime::test {

using namespace std::chrono_literals;

// The server every test of this binary shares, started on first use and
// stopped at exit. Each test works in a domain of its own.
inline RedisServer& shared_redis() {
  static RedisServer server;
  return server;
}

// A plain connection to a server, for a test to look at (or tamper with) keys.
class RawRedis {
 public:
  explicit RawRedis(const std::string& url) {
    optimus::Options options{.url = url};
    auto endpoint = optimus::detail::parse_url(url);
    auto c = optimus::detail::Connection::open(options, *endpoint);
    if (!c) throw Failure{c.error()};
    connection_.emplace(std::move(*c));
  }
  optimus::detail::Reply command(optimus::detail::Args args) {
    auto r = connection_->command(args);
    if (!r) throw Failure{r.error()};
    return std::move(*r);
  }
  long long integer(optimus::detail::Args args) { return command(args)->integer(); }
  std::string text(optimus::detail::Args args) { return std::string{optimus::detail::text(*command(args))}; }

 private:
  std::optional<optimus::detail::Connection> connection_;
};

inline std::string unique_domain(std::string_view stem) {
  static std::atomic<int> next{0};
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return std::string{stem} + ":" + (info ? info->name() : "x") + ":" + std::to_string(::getpid()) + ":" +
         std::to_string(next++);
}

class OptimusTest : public ::testing::Test {
 protected:
  [[nodiscard]] optimus::Options options() const { return {.url = shared_redis().url(), .domain = domain}; }
  std::string domain = unique_domain("test");
};

// Waits (with a deadline) until `done` holds; for effects a worker has on the world.
template <class F>
bool eventually(F done, std::chrono::milliseconds patience = 5000ms) {
  const auto deadline = std::chrono::steady_clock::now() + patience;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

}  // namespace prime::test
