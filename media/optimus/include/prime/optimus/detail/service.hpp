#pragma once

#include <chrono>
#include <exception>
#include <expected>
#include <functional>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/optimus/core.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/envelope.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "prime/topology/detail/runtime_state.hpp"

namespace prime::optimus::detail {

// Hands a linked call's request on to the next service (KEYS[1], its
// request key) if a worker of it lives (KEYS[2], its alive key); else
// answers the caller at once (KEYS[3], its reply key) with ARGV[2]. Either
// list lives ARGV[3] ms more at least (kPushFunction). One round trip,
// pipelined as an RPUSH would be.
inline const std::string kForwardScript = std::string{kPushFunction} + R"lua(
if redis.call('EXISTS', KEYS[2]) == 1 then
  push(KEYS[1], ARGV[1], ARGV[3])
  return 1
end
push(KEYS[3], ARGV[2], ARGV[3])
return 0
)lua";

// Why a request may not be followed, if it names a key a worker must not
// write: an answer goes only to one of the domain's reply keys, and a
// linked call is handed on only to one of its services. Whoever can write a
// domain's request keys writes requests, and a worker may have rights
// beyond its domain; so a request never chooses where the worker writes.
inline std::optional<std::string> foreign_key(std::string_view domain, const Request& request) {
  if (!is_reply_key(domain, request.reply_key))
    return "reply key " + shown_key(request.reply_key) + " is not a caller's reply key of domain '" + std::string{domain} + "'";
  for (const auto& next : request.route)
    if (!service_name(domain, next))
      return "next service key " + shown_key(next) + " is not a service's request key of domain '" + std::string{domain} + "'";
  return std::nullopt;
}

// One worker of a service: waits on the request key, runs the block, and
// sends the result on (the next service of the request's route) or back (the
// caller's reply key). Runs until `stop`; rides out a lost server by
// reconnecting with backoff, and a server that refuses its wait (a key of
// another type, a server still loading, an ACL) by asking again after a
// backoff of its own, reporting the server's error each time. A request
// that names a key the worker must not write (foreign_key) is dropped and
// reported. What it sends is pipelined with its next wait, so a busy worker
// makes one round trip per request.
inline void serve_requests(const std::shared_ptr<Pool>& pool, const std::string& name, const std::string& key,
                           const Handler& handler, const std::weak_ptr<prime::detail::RuntimeState>& runtime, std::stop_token stop) {
  const std::string where = "service '" + name + "'";
  const std::string wait = seconds_text(kWaitSlice);
  const auto report = [&](Error error) {
    if (auto r = runtime.lock()) r->report(std::move(error));
  };
  std::vector<std::vector<std::string>> outbox;  // commands to send with the next wait
  auto refused_backoff = kFirstRefusedBackoff;
  // A key of this worker's own that it also waits on: a stop pushes to it,
  // which ends the wait without cutting it, so a request the server handed
  // out meanwhile still arrives, and is answered.
  const auto wake = wake_key(pool->domain(), pool->process_id(), pool->next_id());
  const auto push_wake = [&] {
    auto lease = pool->acquire();
    if (!lease || !(*lease)->set_timeout(std::chrono::microseconds{pool->options().connect_timeout})) return false;
    (*lease)->append({"RPUSH", wake, "stop"});
    (*lease)->append({"PEXPIRE", wake, std::to_string((kWaitSlice + kSocketMargin).count())});
    auto pushed = (*lease)->reply();
    auto expires = (*lease)->reply();
    return pushed && expires && !is_error(**pushed);
  };

  while (!stop.stop_requested()) {
    bool refused = false;
    auto lease = pool->acquire_until(Clock::time_point::max(), stop);
    if (!lease) return;  // stopped
    auto& connection = **lease;
    StopGuard guard{connection, stop, push_wake};
    while (true) {
      std::size_t queued = 0;
      for (const auto& command : outbox) {
        std::vector<std::string_view> args{command.begin(), command.end()};
        connection.append(args);
        ++queued;
      }
      outbox.clear();
      const bool stopping = guard.stopping();
      if (!stopping) {
        connection.set_timeout(kWaitSlice + kSocketMargin);
        connection.append({"BLPOP", key, wake, wait});
      }
      if (!connection.flush()) break;
      bool ok = true;
      for (; queued > 0; --queued) {
        auto r = connection.reply();
        if (!r) {
          ok = false;
          break;
        }
        if (is_error(**r)) report(server_error(**r, where + ": sending a result"));
      }
      if (!ok) break;
      if (stopping) return;  // nothing is under way on the connection: it goes back
      // Read even when a stop came since the wait was sent: the push to the
      // wake key (or, failing that, a shutdown) ends it at once.
      (void)guard.begin_blocking();
      auto got = connection.reply();
      guard.end_blocking();
      if (!got) break;
      if (is_error(**got)) {
        report(server_error(**got, where + ": waiting for requests"));
        refused = true;
        break;
      }
      refused_backoff = kFirstRefusedBackoff;
      if (is_nil(**got) || !(**got).is_array() || (**got).size() != 2) continue;
      if (text((**got)[0]) == wake) continue;  // stopping: the loop's next turn ends it

      auto request = decode_request(text((**got)[1]));
      if (!request) {
        report({Errc::type_mismatch, where + ": request key '" + key + "' held " + request.error() + "; dropped"});
        continue;
      }
      if (auto foreign = foreign_key(pool->domain(), *request)) {
        report({Errc::damaged, where + ": a request in '" + key + "' names " + *foreign + "; dropped"});
        continue;
      }
      if (request->deadline_ms != 0 &&
          pool->server_ms() > request->deadline_ms)
        continue;  // its caller has given up: running it would answer nobody
      auto result = handler(request->payload);
      if (result)  // before it is wrapped: an envelope gives it a 32-bit length (kMaxEnvelope)
        if (auto fits = connection.fits(result->size(), [&] { return where + ": its output"; }); !fits)
          result = std::unexpected(std::move(fits.error()));
      // An answer nobody takes (its caller gave up) goes away by itself.
      const auto left = request->deadline_ms - pool->server_ms();
      const auto ttl = std::to_string(std::max<std::int64_t>(left, 0) + kUntakenFor.count());
      if (result && !request->route.empty()) {
        const auto& next = request->route.front();
        std::string forwarded;
        forwarded.reserve(result->size() + request->reply_key.size() + 64);
        const std::span<const std::string> rest{request->route.data() + 1, request->route.size() - 1};
        encode_request(request->id, request->reply_key, rest, request->deadline_ms, *result, forwarded);
        const auto next_name = service_name(pool->domain(), next).value_or(next);  // checked above
        if (auto fits = connection.fits(forwarded.size(), [&] { return where + ": its output for '" + next_name + "'"; });
            !fits) {
          result = std::unexpected(std::move(fits.error()));  // said to the caller instead
        } else {
          std::string refused;
          encode_response(request->id, Errc::peer_dead,
                          "service '" + next_name + "': no live worker serves it (next after '" + name + "' in a linked call)",
                          {}, refused);
          outbox.push_back({"EVAL", kForwardScript, "3", next, alive_key(next), request->reply_key,
                            std::move(forwarded), std::move(refused), ttl});
          continue;
        }
      }
      std::string response;
      if (result) {
        encode_response(request->id, std::nullopt, {}, *result, response);
        if (auto fits = connection.fits(response.size(), [&] { return where + ": its output"; }); !fits) {
          result = std::unexpected(std::move(fits.error()));  // said to the caller instead
          response.clear();
        }
      }
      if (!result) encode_response(request->id, result.error().code, result.error().message, {}, response);
      outbox.push_back({"EVAL", kPushScript, "1", request->reply_key, std::move(response), ttl});
    }
    if (stop.stop_requested()) {
      lease->discard();
      return;
    }
    if (refused) {  // the connection is sound (it goes back after): the worker waits before asking again
      if (!pause(Clock::now() + refused_backoff, stop)) return;
      refused_backoff = std::min(refused_backoff * 2, kMaxRefusedBackoff);
      continue;
    }
    report({Errc::unreachable, where + ": lost " + pool->url() + "; reconnecting"});
  }
}

// Sets the alive keys `keys` (a service's liveness) for kAliveFor from now.
inline std::expected<void, Error> mark_alive(Pool& pool, const std::vector<std::string>& keys) {
  if (keys.empty()) return {};
  auto lease = pool.acquire();
  if (!lease) return std::unexpected(std::move(lease.error()));
  auto& connection = **lease;
  const auto ms = std::to_string(kAliveFor.count());
  for (const auto& key : keys) connection.append({"SET", key, "1", "PX", ms});
  if (!connection.flush()) {
    lease->discard();
    return std::unexpected(Error{Errc::unreachable, "lost " + pool.url()});
  }
  for (std::size_t n = 0; n < keys.size(); ++n) {
    auto reply = connection.reply();
    if (!reply) {
      lease->discard();
      return std::unexpected(std::move(reply.error()));
    }
    if (is_error(**reply)) return std::unexpected(server_error(**reply, "marking a service alive"));
  }
  return {};
}

// Keeps the alive keys of a process's services (`keys()`, asked each round)
// set until `stop`: a service lives as long as the process hosting it and
// its link to the server, however long its blocks run (a worker busy for
// longer than kAliveFor is slow, not dead).
inline void keep_alive(const std::shared_ptr<Pool>& pool, const std::function<std::vector<std::string>()>& keys,
                       const std::stop_token& stop) {
  while (pause(Clock::now() + kAliveRefresh, stop)) (void)mark_alive(*pool, keys());  // a lost server: the next round tries again
}

}  // namespace prime::optimus::detail
