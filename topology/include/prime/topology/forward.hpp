#pragma once

#include <concepts>
#include <stop_token>
#include <string>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/runtime.hpp"

namespace prime {

// Hands every value of `source`, with its stamp, to `sink(value, stamp)`, in
// one worker of the source's core, until that core stops: how a source
// leaves its medium for another (a bridge from a shared-memory topic into a
// Redis stream, say), or reaches an actuator. What the sink throws, or an
// error it returns in a std::expected, is reported on the core's errors()
// under `name`, and the next value goes on.
template <Source S, class Sink>
  requires std::invocable<Sink&, const typename S::value_type&, Clock::time_point>
void forward(const S& source, Sink sink, std::string name = "forward") {
  using T = typename S::value_type;
  const auto what = "forward '" + name + "' of '" + source.name() + "'";
  auto runtime = source.runtime();
  detail::spawn_reader(runtime, source.subscribe(), what,
                       [sink = std::move(sink), runtime, what](Sample<T>&& s, std::stop_token) mutable {
                         using Result = std::invoke_result_t<Sink&, const T&, Clock::time_point>;
                         if constexpr (requires(Result r) { r.has_value(); r.error(); }) {
                           auto result = sink(std::as_const(s.value), s.stamp);
                           if (!result.has_value()) {
                             if (auto r = runtime.lock()) r->report({result.error().code, what + ": " + result.error().message});
                           }
                         } else {
                           sink(std::as_const(s.value), s.stamp);
                         }
                       });
}

}  // namespace prime
