#pragma once

#include <algorithm>
#include <cstddef>
#include <optional>
#include <span>
#include <utility>
#include <vector>

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
  enum class Kind { wait, make, drop_oldest };
  Kind kind = Kind::wait;
  std::vector<std::size_t> picks{};  // make: the value each input gives, as an index into its queue
  std::size_t input = 0;             // drop_oldest: whose head no set within max_span can hold
};

// `queues`: each input's stamps not yet used or dropped, oldest first;
// `earliest_next`: where each input's next value could lie at the earliest.
inline ApproximateMatch match_approximate(const std::vector<std::span<const Clock::time_point>>& queues,
                                          const std::vector<Clock::time_point>& earliest_next, Clock::duration max_span,
                                          double age_penalty = 0) {
  const auto n = queues.size();
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

  std::optional<Clock::duration> best_cost;  // the best candidate whose values are all here
  Clock::time_point best_start{};
  std::vector<std::size_t> best;
  // The best a candidate still waiting for a value could be: (least cost, earliest start).
  std::optional<std::pair<Clock::duration, Clock::time_point>> open;
  auto consider_open = [&](Clock::duration least_span, Clock::duration least_cost, Clock::time_point start) {
    if (least_span > max_span) return;
    if (!open || least_cost < open->first || (least_cost == open->first && start < open->second))
      open = {least_cost, start};
  };

  std::vector<std::size_t> picks(n);
  for (std::size_t s = 0; s < n; ++s) {
    for (const auto m : queues[s]) {
      if (m > newest_head) break;
      auto newest = m;
      bool complete = true;
      for (std::size_t i = 0; i < n; ++i) {
        const auto at = std::lower_bound(queues[i].begin(), queues[i].end(), m);
        if (at == queues[i].end()) {
          complete = false;
          newest = std::max(newest, earliest_next[i]);  // newest >= m already
        } else {
          picks[i] = static_cast<std::size_t>(at - queues[i].begin());
          newest = std::max(newest, *at);
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
  // in the start there, is least at one end or the other.
  std::vector<Clock::time_point> ends;
  for (std::size_t i = 0; i < n; ++i) {
    if (earliest_next[i] > newest_head) continue;
    ends.clear();
    for (const auto& q : queues)
      for (const auto t : q)
        if (t > earliest_next[i] && t <= newest_head) ends.push_back(t);
    ends.push_back(earliest_next[i]);
    std::sort(ends.begin(), ends.end());
    auto from = earliest_next[i];  // the stretch's first possible start (for ties: the most threatening)
    for (const auto end : ends) {
      // For a start t in the stretch the set's newest stamp is max(t, others).
      auto others = Clock::time_point::min();
      for (std::size_t k = 0; k < n; ++k) {
        if (k == i) continue;
        const auto at = std::lower_bound(queues[k].begin(), queues[k].end(), end);
        others = std::max(others, at == queues[k].end() ? earliest_next[k] : *at);
      }
      const auto span_at = [&](Clock::time_point t) { return std::max(t, others) - t; };
      consider_open(span_at(end), std::min(cost(span_at(end), end), cost(span_at(from), from)), from);
      from = end;
    }
  }

  if (best_cost) {
    const bool may_be_beaten = open && (open->first < *best_cost || (open->first == *best_cost && open->second < best_start));
    if (may_be_beaten) return {};
    return {ApproximateMatch::Kind::make, std::move(best)};
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
