// A chain's call through its services (chain.hpp): the request sent down a
// segment, the answer waited for.
#include "prime/optimus/chain.hpp"

#include <algorithm>
#include <span>

#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/envelope.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"

namespace prime::optimus::detail {

namespace {

std::string route_name(const Segment& segment) {
  std::string name;
  for (const auto& n : segment.names) name.append(name.empty() ? "" : " | ").append(n);
  return name;
}

}  // namespace

// Sends `payload` down one segment and waits for the answer until `deadline`.
// One write (the request and the wait for the reply are pipelined), one
// wake-up. The reply key is the call's own, so no other caller can take the
// answer; the correlation id is checked all the same.
std::expected<std::string, Error> call_segment(const Segment& segment, std::string_view payload,
                                               Clock::time_point deadline) {
  const auto what = [&] { return "service '" + route_name(segment) + "'"; };
  auto lease = segment.pool->acquire();
  if (!lease) return std::unexpected(Error{lease.error().code, what() + ": " + lease.error().message});
  auto& connection = **lease;
  // A day at most on the wire: a deadline of time_point::max() ("never")
  // would overflow the system clock's deadline sent with the request.
  const auto remaining = std::min<std::chrono::microseconds>(
      std::chrono::duration_cast<std::chrono::microseconds>(deadline - Clock::now()), std::chrono::hours{24});
  if (remaining.count() <= 0) return std::unexpected(Error{Errc::timeout, what() + ": the deadline passed before the call"});

  // The message first: an envelope gives it a 32-bit length (kMaxEnvelope).
  if (auto fits = connection.fits(payload.size(), [&] { return what() + ": a request"; }); !fits)
    return std::unexpected(std::move(fits.error()));
  const auto id = segment.pool->next_id();
  const auto reply = reply_key(segment.pool->domain(), segment.pool->process_id(), id);
  std::string envelope;
  envelope.reserve(payload.size() + reply.size() + 64);
  const std::span<const std::string> rest{segment.keys.data() + 1, segment.keys.size() - 1};
  encode_request(id, reply, rest,
                 segment.pool->server_ms() + std::chrono::duration_cast<std::chrono::milliseconds>(remaining).count(),
                 payload, envelope);
  if (auto fits = connection.fits(envelope.size(), [&] { return what() + ": a request"; }); !fits)
    return std::unexpected(std::move(fits.error()));
  const auto wait = seconds_text(remaining);
  if (!connection.set_timeout(remaining + kSocketMargin))
    return std::unexpected(Error{Errc::unreachable, what() + ": cannot set a socket timeout"});
  const auto ttl = std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(remaining + kUntakenFor).count());
  connection.append({"EVAL", kPushScript, "1", segment.keys.front(), envelope, ttl});
  connection.append({"BLPOP", reply, wait});
  const auto stopped = [&] {
    lease->discard();
    return std::unexpected(Error{Errc::stopped, what() + ": the core that owns this chain is stopping"});
  };
  if (!segment.pool->begin_call(connection)) return stopped();
  auto pushed = connection.reply();
  if (pushed && is_error(**pushed)) {  // refused (another type under the key, out of memory, an ACL): said at once
    segment.pool->end_call(connection);
    lease->discard();  // its BLPOP still waits on the server: the connection goes with it
    return std::unexpected(server_error(**pushed, what() + ": sending the request"));
  }
  auto answer = pushed ? connection.reply() : std::expected<Reply, Error>{std::unexpected(pushed.error())};
  segment.pool->end_call(connection);
  if (!answer && segment.pool->calls_closed()) return stopped();
  if (!pushed) return std::unexpected(Error{pushed.error().code, what() + ": " + pushed.error().message});
  if (!answer) return std::unexpected(Error{answer.error().code, what() + ": " + answer.error().message});
  if (is_error(**answer)) return std::unexpected(server_error(**answer, what() + ": waiting for the reply"));

  if (is_nil(**answer)) {
    // No answer in time. Withdraw the request if no worker took it yet, so a
    // late worker cannot run it for nobody; say whether any worker is alive.
    const auto ms = std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(remaining).count());
    connection.set_timeout(std::chrono::duration_cast<std::chrono::microseconds>(segment.pool->options().connect_timeout));
    connection.append({"LREM", segment.keys.front(), "1", envelope});
    connection.append({"EXISTS", alive_key(segment.keys.front())});
    auto removed = connection.reply();
    auto alive = connection.reply();
    const bool withdrawn = removed && (*removed)->is_integer() && (*removed)->integer() == 1;
    const bool dead = alive && (*alive)->is_integer() && (*alive)->integer() == 0;
    if (withdrawn && dead)
      return std::unexpected(Error{Errc::peer_dead, what() + ": no live worker serves '" + segment.names.front() +
                                                        "' (no answer within " + ms + " ms)"});
    return std::unexpected(Error{Errc::timeout, what() + ": no answer within " + ms + " ms" +
                                                    (withdrawn ? " (the request was never taken; withdrawn)" : "")});
  }
  if (!(**answer).is_array() || (**answer).size() != 2)
    return std::unexpected(Error{Errc::type_mismatch, what() + ": an unexpected reply to BLPOP"});
  const auto value = (**answer)[1];
  auto response = decode_response(text(value));
  if (!response) return std::unexpected(Error{Errc::type_mismatch, what() + ": reply key '" + reply + "' held " + response.error()});
  if (response->id != id)
    return std::unexpected(Error{Errc::type_mismatch, what() + ": an answer to request " + std::to_string(response->id) +
                                                          " came for request " + std::to_string(id)});
  if (response->error) return std::unexpected(Error{*response->error, std::move(response->message)});
  return std::move(response->payload);
}

bool same_server(const Segment& a, const Segment& b) {
  return a.pool == b.pool || (a.pool->url() == b.pool->url() && a.pool->options().domain == b.pool->options().domain);
}

}  // namespace prime::optimus::detail
