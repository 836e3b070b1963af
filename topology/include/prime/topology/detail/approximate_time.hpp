#pragma once

#include <algorithm>
#include <array>
#include <cassert>
#include <cstddef>
#include <optional>
#include <span>
#include <utility>

#include "prime/logic/sample.hpp"

namespace prime::detail {

// Adaptive approximate-time matching, decided from stamps alone.
//
// Inputs give values with rising stamps. After the last set made, the next
// set is the one with the least span (newest stamp − oldest) among the sets
// contiguous to the last, ties going to the earlier set. Contiguous: at
// least one input gives the first value it has after the last set;
// otherwise the values every input skipped would have made a set of their
// own. Every such set holds the head of the input whose head is newest (B),
// so the candidates are the sets whose oldest stamp m is at most B, each
// input giving its first value at or after m.
//
// A set is made only once nothing still to come could make a better one:
// an input's values come after what it has sent (and, given the least
// interval between its values, at least that much after), so a candidate
// all of whose values are here is final, and one still waiting on an input
// can be no better than that input's earliest next stamp allows. So which
// sets are made does not depend on how arrivals on different inputs
// interleave: only when.
//
// An age penalty p > 0 trades that optimality for latency: a set is then
// judged by its span plus p × its start, so a later set must be narrower
// by p × how much later it starts to win, and the matcher stops waiting
// for one sooner. With p = 0 (the default) the sets are the least-span ones.
struct ApproximateMatch {
  static constexpr std::size_t kMaxInputs = 8;
  enum class Kind { wait, make, drop_oldest };
  Kind kind = Kind::wait;
  std::array<std::size_t, kMaxInputs> picks{};  // make: the value each input gives, as an index into its queue
  std::size_t input = 0;                        // drop_oldest: whose head no set within max_span can hold
};

// `queues`: each input's stamps not yet used or dropped, oldest first (at
// most kMaxInputs inputs); `earliest_next`: where each input's next value
// could lie at the earliest. Allocates nothing: it runs on every value a
// sync's input offers. Every walk below moves forward only, as the stamps
// it looks for rise.
inline ApproximateMatch match_approximate(std::span<const std::span<const Clock::time_point>> queues,
                                          std::span<const Clock::time_point> earliest_next, Clock::duration max_span,
                                          double age_penalty = 0) {
  const auto n = queues.size();
  assert(n <= ApproximateMatch::kMaxInputs && earliest_next.size() == n);
  for (const auto& q : queues)
    if (q.empty()) return {};
  auto newest_head = queues[0].front();
  for (const auto& q : queues) newest_head = std::max(newest_head, q.front());
  // What a set costs: its span, plus the age penalty times its start
  // (counted from the newest head; only differences between costs matter).
  auto cost = [&](Clock::duration span, Clock::time_point start) {
    if (age_penalty == 0) return span;
    return span + Clock::duration{static_cast<Clock::rep>(age_penalty * static_cast<double>((start - newest_head).count()))};
  };
  using Indices = std::array<std::size_t, ApproximateMatch::kMaxInputs>;
  // Moves `at` on to input i's first value at or after `t` (t never falls).
  auto first_from = [&](std::size_t i, std::size_t& at, Clock::time_point t) {
    while (at < queues[i].size() && queues[i][at] < t) ++at;
  };

  std::optional<Clock::duration> best_cost;  // the best candidate whose values are all here
  Clock::time_point best_start{};
  Indices best{};
  // The best a candidate still waiting for a value could be: (least cost, earliest start).
  std::optional<std::pair<Clock::duration, Clock::time_point>> open;
  auto consider_open = [&](Clock::duration least_span, Clock::duration least_cost, Clock::time_point start) {
    if (least_span > max_span) return;
    if (!open || least_cost < open->first || (least_cost == open->first && start < open->second))
      open = {least_cost, start};
  };

  Indices picks{};
  for (std::size_t s = 0; s < n; ++s) {
    Indices at{};
    for (const auto m : queues[s]) {
      if (m > newest_head) break;
      auto newest = m;
      bool complete = true;
      for (std::size_t i = 0; i < n; ++i) {
        first_from(i, at[i], m);
        if (at[i] == queues[i].size()) {
          complete = false;
          newest = std::max(newest, earliest_next[i]);  // newest >= m already
        } else {
          picks[i] = at[i];
          newest = std::max(newest, queues[i][at[i]]);
        }
      }
      const auto span = newest - m;
      const auto c = cost(span, m);
      if (!complete) {
        consider_open(span, c, m);
      } else if (span <= max_span && (!best_cost || c < *best_cost || (c == *best_cost && m < best_start))) {
        best_cost = c;
        best_start = m;
        best = picks;
      }
    }
  }
  // A value still to come could start a candidate too: on input i, at its
  // earliest next stamp e_i or later, and at most at B. Between two stamps
  // that lie here, every other input's pick (its first value at or after
  // the start, or its earliest next) stays the same while the start grows,
  // so the span is least at the end of each such stretch; the cost, linear
  // in the start there, is least at one end or the other. The stretches end
  // at e_i, then at every stamp here after it up to B, in order (the
  // queues merged as they are walked).
  for (std::size_t i = 0; i < n; ++i) {
    const auto e = earliest_next[i];
    if (e > newest_head) continue;
    Indices merged{}, pick{};
    for (std::size_t k = 0; k < n; ++k)
      while (merged[k] < queues[k].size() && queues[k][merged[k]] <= e) ++merged[k];
    auto from = e;  // the stretch's first possible start (for ties: the most threatening)
    for (auto end = e;;) {
      // For a start t in the stretch the set's newest stamp is max(t, others).
      auto others = Clock::time_point::min();
      for (std::size_t k = 0; k < n; ++k) {
        if (k == i) continue;
        first_from(k, pick[k], end);
        others = std::max(others, pick[k] == queues[k].size() ? earliest_next[k] : queues[k][pick[k]]);
      }
      const auto span_at = [&](Clock::time_point t) { return std::max(t, others) - t; };
      consider_open(span_at(end), std::min(cost(span_at(end), end), cost(span_at(from), from)), from);
      from = end;
      // The next stretch ends at the oldest stamp not walked yet, if it is at most B.
      std::size_t next = n;
      for (std::size_t k = 0; k < n; ++k)
        if (merged[k] < queues[k].size() && queues[k][merged[k]] <= newest_head &&
            (next == n || queues[k][merged[k]] < queues[next][merged[next]]))
          next = k;
      if (next == n) break;
      end = queues[next][merged[next]++];
    }
  }

  if (best_cost) {
    const bool may_be_beaten = open && (open->first < *best_cost || (open->first == *best_cost && open->second < best_start));
    if (may_be_beaten) return {};
    return {ApproximateMatch::Kind::make, best};
  }
  if (open) return {};  // a set within max_span may still come
  // None can: the oldest head can never be in a set (any set holding it
  // starts at it, and the best of those is already too wide).
  std::size_t oldest = 0;
  for (std::size_t i = 1; i < n; ++i)
    if (queues[i].front() < queues[oldest].front()) oldest = i;
  return {ApproximateMatch::Kind::drop_oldest, {}, oldest};
}

}  // namespace prime::detail
