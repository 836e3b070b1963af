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
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"

namespace prime::optimus {

namespace detail {

class Pool;  // connections to one server (detail/pool.hpp)

// Services on one server that one request runs through in turn: the first
// gets the request, each passes its result to the next, the last answers the
// caller. Linking chains on one server joins their segments.
struct Segment {
  std::shared_ptr<Pool> pool;
  std::vector<std::string> keys;   // request keys, in order
  std::vector<std::string> names;  // service names, for messages
};

// Sends `payload` down one segment and waits for the answer until `deadline`
// (src/chain.cpp). One write (the request and the wait for the reply are
// pipelined), one wake-up.
std::expected<std::string, Error> call_segment(const Segment& segment, std::string_view payload,
                                               Clock::time_point deadline);

// Whether two segments' services are on one server, in one domain: a
// linked call passes straight from one to the next.
bool same_server(const Segment& a, const Segment& b);

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
    if (detail::same_server(last, next)) {
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
