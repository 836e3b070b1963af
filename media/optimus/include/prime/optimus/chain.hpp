#pragma once

#include <algorithm>
#include <chrono>
#include <expected>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/envelope.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"

namespace prime::optimus {

namespace detail {

// Services on one server that one request runs through in turn: the first
// gets the request, each passes its result to the next, the last answers the
// caller. Linking chains on one server joins their segments.
struct Segment {
  std::shared_ptr<Pool> pool;
  std::vector<std::string> keys;   // request keys, in order
  std::vector<std::string> names;  // service names, for messages
};

inline std::string route_name(const Segment& segment) {
  std::string name;
  for (const auto& n : segment.names) name.append(name.empty() ? "" : " | ").append(n);
  return name;
}

// Sends `payload` down one segment and waits for the answer until `deadline`.
// One write (the request and the wait for the reply are pipelined), one
// wake-up. The reply key is the call's own, so no other caller can take the
// answer; the correlation id is checked all the same.
inline std::expected<std::string, Error> call_segment(const Segment& segment, std::string_view payload,
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

}  // namespace detail

// A chain whose blocks are services reached through a Redis server: each a
// worker thread (in this process or another, on this machine or another)
// waiting on its request key. Calling sends the input once; linked services
// pass the data on to each other, and the last one answers the caller.
//
// Copies share what they hold. Thread-safe: every call has its own reply key
// and correlation id, so concurrent callers never see each other's answers.
template <class In, class Out>
class Chain {
 public:
  using input_type = In;
  using output_type = Out;

  Chain(std::vector<detail::Segment> segments, Graph graph, std::chrono::milliseconds timeout)
      : segments_{std::make_shared<const std::vector<detail::Segment>>(std::move(segments))},
        graph_{std::make_shared<const Graph>(std::move(graph))},
        timeout_{timeout} {}

  // Throws prime::Failure when the call fails: a timeout, an unreachable
  // server, a service's block that threw (Errc::block_failed, its message).
  Out operator()(In in) const {
    auto out = call(in, deadline_after(timeout_));
    if (!out) throw Failure{std::move(out.error())};
    return std::move(*out);
  }

  // The same, as a value or an Error, waiting no later than `deadline`.
  [[nodiscard]] std::expected<Out, Error> call(const In& in, Clock::time_point deadline) const {
    std::string payload = encode_message(in);
    for (const auto& segment : *segments_) {
      auto next = detail::call_segment(segment, payload, deadline);
      if (!next) return std::unexpected(std::move(next.error()));
      payload = std::move(*next);
    }
    const auto& last = segments_->back();
    return decode_message<Out>(payload, "reply of service '" + last.names.back() + "'");
  }
  [[nodiscard]] std::expected<Out, Error> call(const In& in) const { return call(in, deadline_after(timeout_)); }

  // The same chain with another deadline per call.
  [[nodiscard]] Chain with_timeout(std::chrono::milliseconds timeout) const {
    Chain copy = *this;
    copy.timeout_ = timeout;
    return copy;
  }

  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const std::vector<detail::Segment>& segments() const noexcept { return *segments_; }
  [[nodiscard]] std::chrono::milliseconds timeout() const noexcept { return timeout_; }

 private:
  std::shared_ptr<const std::vector<detail::Segment>> segments_;
  std::shared_ptr<const Graph> graph_;
  std::chrono::milliseconds timeout_;
};

static_assert(prime::Chain<Chain<int, double>>);

// Linking Optimus chains joins their routes: services on the same server pass
// the data straight on, and the caller waits for one answer. The linked chain
// keeps the longer of the two deadlines.
template <class In, class Mid, class Out>
[[nodiscard]] Chain<In, Out> link(const Chain<In, Mid>& first, const Chain<Mid, Out>& second) {
  std::vector<detail::Segment> segments = first.segments();
  for (const auto& next : second.segments()) {
    auto& last = segments.back();
    const bool same_server = last.pool == next.pool || (last.pool->url() == next.pool->url() &&
                                                        last.pool->options().domain == next.pool->options().domain);
    if (same_server) {
      last.keys.insert(last.keys.end(), next.keys.begin(), next.keys.end());
      last.names.insert(last.names.end(), next.names.begin(), next.names.end());
    } else {
      segments.push_back(next);
    }
  }
  return {std::move(segments), Graph::sequence(first.graph(), second.graph()), std::max(first.timeout(), second.timeout())};
}

using prime::operator|;

}  // namespace prime::optimus
