#pragma once

#include <cstddef>
#include <cstring>
#include <expected>
#include <functional>
#include <memory>
#include <new>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/shm/service_handles.hpp"
#include "prime/shm/message.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"

namespace prime::shm {

namespace detail {

// How a message type travels in a service's cell: the argument a chain
// takes, the value it gives, and how each is written and read in place.
template <class T>
struct Wire {
  using argument = T;
  using value = T;
  static std::size_t write(const T& v, std::byte* to, std::size_t capacity) {
    ::new (&place_at(to, capacity)) T(v);
    return sizeof(T);
  }
  static T read(const std::byte* from, std::size_t) { return view(from, 0); }
  // The message where it lies.
  static const T& view(const std::byte* at, std::size_t) { return *std::launder(reinterpret_cast<const T*>(at)); }
  // Where a request or reply is written in place, in a cell with room for
  // `capacity` bytes.
  static T& place_at(std::byte* at, std::size_t capacity) {
    if (sizeof(T) > capacity)
      throw Failure{{Errc::too_large, "a request of " + std::to_string(sizeof(T)) + " bytes exceeds the " +
                                               std::to_string(capacity) + " bytes the service's cell has (max_request_size)"}};
    return *::new (at) T;
  }
};
template <>
struct Wire<Bytes> {
  using argument = std::span<const std::byte>;
  using value = std::vector<std::byte>;
  static std::size_t write(std::span<const std::byte> v, std::byte* to, std::size_t capacity) {
    if (v.size() > capacity)
      throw Failure{{Errc::too_large, "a request of " + std::to_string(v.size()) + " bytes exceeds max_request_size (" +
                                               std::to_string(capacity) + " bytes)"}};
    if (!v.empty()) std::memcpy(to, v.data(), v.size());
    return v.size();
  }
  static value read(const std::byte* from, std::size_t size) { return value(from, from + size); }
  static std::span<const std::byte> view(const std::byte* at, std::size_t size) { return {at, size}; }
  static std::span<std::byte> place_at(std::byte* at, std::size_t capacity) { return {at, capacity}; }
};

// The message type a block's argument or result travels as.
template <class T>
using wire_t = std::conditional_t<std::is_same_v<std::remove_cvref_t<T>, std::span<const std::byte>> ||
                                      std::is_same_v<std::remove_cvref_t<T>, std::vector<std::byte>>,
                                  Bytes, std::remove_cvref_t<T>>;

}  // namespace detail

// A chain that calls services hosted by any process of the domain: one, or
// several linked (`a | b`: a's output goes straight into b's input, in
// shared memory; the caller sends once and waits once). Copies share the
// client handle, which calls from any thread may use at once.
//
// A call that fails throws prime::Failure from operator(), or comes back
// from call() as an Error: Errc::not_found (no service, or no live server),
// type_mismatch (other types), too_large (a request or reply over its
// size), queue_full (queue_depth or calls_per_client), rate_limited
// (min_interval), too_many_clients (max_clients), timeout, peer_dead (the
// server died while the call waited), stopped (it stopped, or the
// caller's give_up said so), block_failed (the block threw: its message).
//
// call() and call_in_place() take a way out for a caller that may have to
// stop waiting before the timeout (a shutdown, Ctrl-C): `give_up()` is
// asked on the calling thread each time the call has slept a slice (at
// most 25 ms) with no answer, e.g. `[&] { return token.stop_requested(); }`.
// Given up, the call ends with Errc::stopped; a worker that took the
// request finishes it, and its answer is dropped.
template <Message In, Message Out>
class ServiceChain {
 public:
  using input_type = typename detail::Wire<In>::argument;
  using output_type = typename detail::Wire<Out>::value;
  using Route = detail::Route;

  ServiceChain(Route route, Graph graph)
      : route_{std::make_shared<const Route>(std::move(route))}, graph_{std::make_shared<const Graph>(std::move(graph))} {}

  output_type operator()(input_type in) const {
    auto out = call(in);
    if (!out) throw Failure{std::move(out.error())};
    return std::move(*out);
  }

  // The answer, or the error that kept it.
  [[nodiscard]] std::expected<output_type, Error> call(const input_type& in,
                                                      const std::function<bool()>& give_up = {}) const {
    std::optional<output_type> out;
    auto done = detail::call(
        *route_, [&](std::byte* to, std::size_t capacity) { return detail::Wire<In>::write(in, to, capacity); },
        [&](const std::byte* from, std::size_t size) { out.emplace(detail::Wire<Out>::read(from, size)); }, false,
        give_up);
    if (!done) return std::unexpected(std::move(done.error()));
    return std::move(*out);
  }

  // A call with no copy either way: `write(request)` fills the request
  // where the service reads it, and `read(reply)` reads the answer where the
  // service made it. For messages, write(In&) gets a default-initialised
  // In and read(const Out&) the answer; for raw bytes (shm::Bytes),
  // write(std::span<std::byte>) returns the request's size and
  // read(std::span<const std::byte>) gets the answer.
  template <class Write, class Read>
  [[nodiscard]] std::expected<void, Error> call_in_place(Write&& write, Read&& read,
                                                         const std::function<bool()>& give_up = {}) const {
    return detail::call(
        *route_,
        [&](std::byte* to, std::size_t capacity) -> std::size_t {
          if constexpr (std::is_same_v<In, Bytes>) {
            const std::size_t n = write(detail::Wire<In>::place_at(to, capacity));
            if (n > capacity)
              throw Failure{{Errc::too_large, "a request of " + std::to_string(n) + " bytes exceeds max_request_size (" +
                                                       std::to_string(capacity) + " bytes)"}};
            return n;
          } else {
            write(detail::Wire<In>::place_at(to, capacity));
            return sizeof(In);
          }
        },
        [&](const std::byte* from, std::size_t size) { read(detail::Wire<Out>::view(from, size)); }, false, give_up);
  }

  // Sends `in` and returns once it is queued, not waiting for the answer
  // (which no one reads). Errors are those of sending: no service, a limit.
  [[nodiscard]] std::expected<void, Error> post(const input_type& in) const {
    return detail::call(
        *route_, [&](std::byte* to, std::size_t capacity) { return detail::Wire<In>::write(in, to, capacity); },
        [](const std::byte*, std::size_t) {}, true);
  }

  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const Route& route() const noexcept { return *route_; }

 private:
  std::shared_ptr<const Route> route_;
  std::shared_ptr<const Graph> graph_;
};

static_assert(Chain<ServiceChain<int, double>>);

// Linking two service chains forwards: the first one's output is written
// straight into the second one's cell by the first service's worker. The
// first one's reply type must be the second one's request type, or the
// second must take Bytes (raw chains of tools carry the types their
// services have): Errc::type_mismatch.
template <Message A, Message B, Message C>
[[nodiscard]] ServiceChain<A, C> link(const ServiceChain<A, B>& first, const ServiceChain<B, C>& second) {
  return {detail::linked(first.route(), second.route()), Graph::sequence(first.graph(), second.graph())};
}

using prime::operator|;  // found by argument-dependent lookup for `service | service`

}  // namespace prime::shm
