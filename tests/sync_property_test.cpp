// Adaptive approximate-time matching against its guarantees and against an
// exhaustive reference, on random stamp streams: 2 to 4 inputs, different
// rates, jitter, drops and bursts, delivered in different interleavings.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <limits>
#include <optional>
#include <random>
#include <span>
#include <vector>

#include "prime/topology/detail/approximate_time.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;
using Stamps = std::vector<Clock::time_point>;
using Set = std::vector<std::size_t>;  // one index per input, into its stream

const Clock::time_point kT0{};

// Streams of rising stamps: each input has its own period and phase, jitter,
// drops and the odd burst of values close together.
std::vector<Stamps> random_streams(std::mt19937& random, std::size_t inputs, std::size_t length) {
  std::vector<Stamps> streams(inputs);
  for (auto& s : streams) {
    const auto period = std::chrono::microseconds{std::uniform_int_distribution<int>{3000, 40000}(random)};
    auto at = kT0 + std::chrono::microseconds{std::uniform_int_distribution<int>{0, 20000}(random)};
    while (s.size() < length) {
      const auto roll = std::uniform_int_distribution<int>{0, 99}(random);
      if (roll < 10) {  // dropped
        at += period;
        continue;
      }
      if (roll < 18) {  // a burst
        for (int k = 0; k < 3 && s.size() < length; ++k) s.push_back(at += std::chrono::microseconds{300});
        continue;
      }
      const auto jitter = std::uniform_int_distribution<long>{-period.count() / 5, period.count() / 5}(random);
      at += period + std::chrono::microseconds{jitter};
      if (!s.empty() && at < s.back()) at = s.back();
      s.push_back(at);
    }
  }
  return streams;
}

// The matcher fed value by value in the order `arrival` gives (a sequence of
// input numbers), with the least intervals it is told; then every stream is
// closed by a value an hour later on each input. Returns the sets made
// before that closing, as indices into the streams.
std::vector<Set> online(const std::vector<Stamps>& streams, const std::vector<std::size_t>& arrival,
                        std::vector<Clock::duration> min_interval, Clock::duration max_span,
                        std::size_t* decided_before_close = nullptr, double age_penalty = 0) {
  const auto n = streams.size();
  std::vector<Stamps> queue(n);
  std::vector<std::size_t> next_index(n, 0), front_index(n, 0);
  std::vector<Clock::time_point> earliest(n, Clock::time_point::min());
  std::vector<Set> sets;
  auto run = [&] {
    while (true) {
      std::vector<std::span<const Clock::time_point>> spans;
      for (auto& q : queue) spans.emplace_back(q);
      const auto m = detail::match_approximate(spans, earliest, max_span, age_penalty);
      if (m.kind == detail::ApproximateMatch::Kind::wait) return;
      if (m.kind == detail::ApproximateMatch::Kind::drop_oldest) {
        queue[m.input].erase(queue[m.input].begin());
        ++front_index[m.input];
        continue;
      }
      Set set(n);
      for (std::size_t i = 0; i < n; ++i) {
        set[i] = front_index[i] + m.picks[i];
        queue[i].erase(queue[i].begin(), queue[i].begin() + static_cast<long>(m.picks[i]) + 1);
        front_index[i] += m.picks[i] + 1;
      }
      sets.push_back(set);
    }
  };
  auto add = [&](std::size_t i, Clock::time_point stamp) {
    queue[i].push_back(stamp);
    earliest[i] = stamp + min_interval[i];
    ++next_index[i];
    run();
  };
  for (const auto i : arrival) add(i, streams[i][next_index[i]]);
  if (decided_before_close) *decided_before_close = sets.size();
  auto close = kT0;
  for (const auto& s : streams) close = std::max(close, s.back());
  for (std::size_t i = 0; i < n; ++i) add(i, close + 1h);
  // Sets holding a closing value are not the streams'.
  std::erase_if(sets, [&](const Set& set) {
    for (std::size_t i = 0; i < n; ++i)
      if (set[i] >= streams[i].size()) return true;
    return false;
  });
  return sets;
}

// Whether some set within max_span can be made of values from `from` (each
// input's first) up to but not including `to`.
bool set_within(const std::vector<Stamps>& streams, const Set& from, const Set& to, Clock::duration max_span) {
  const auto n = streams.size();
  Set pick(n);
  auto visit = [&](auto&& self, std::size_t i) -> bool {
    if (i == n) {
      auto lo = Clock::time_point::max(), hi = Clock::time_point::min();
      for (std::size_t k = 0; k < n; ++k) {
        lo = std::min(lo, streams[k][pick[k]]);
        hi = std::max(hi, streams[k][pick[k]]);
      }
      return hi - lo <= max_span;
    }
    for (std::size_t k = from[i]; k < to[i]; ++k) {
      pick[i] = k;
      if (self(self, i + 1)) return true;
    }
    return false;
  };
  return visit(visit, 0);
}

// The definition, by brute force: after the last set, of all the sets within
// max_span that are contiguous to it (no set within max_span could be made
// of the values skipped between them), the one of least span (plus the age
// penalty times its start), ties to the earlier start.
std::vector<Set> reference(const std::vector<Stamps>& streams, Clock::duration max_span, double age_penalty = 0) {
  const auto n = streams.size();
  std::vector<Set> sets;
  Set after(n, 0);  // the first index each input may still give
  while (true) {
    std::optional<Set> best;
    Clock::duration best_cost{};
    Clock::time_point best_start{};
    Set candidate(n);
    // Enumerate every combination (the streams are short).
    auto visit = [&](auto&& self, std::size_t i) -> void {
      if (i == n) {
        auto lo = Clock::time_point::max(), hi = Clock::time_point::min();
        for (std::size_t k = 0; k < n; ++k) {
          lo = std::min(lo, streams[k][candidate[k]]);
          hi = std::max(hi, streams[k][candidate[k]]);
        }
        if (hi - lo > max_span) return;
        const auto cost = (hi - lo) + Clock::duration{static_cast<Clock::rep>(age_penalty * static_cast<double>((lo - kT0).count()))};
        if (best && (cost > best_cost || (cost == best_cost && lo >= best_start))) return;
        if (set_within(streams, after, candidate, max_span)) return;  // not contiguous
        best = candidate;
        best_cost = cost;
        best_start = lo;
        return;
      }
      for (std::size_t k = after[i]; k < streams[i].size(); ++k) {
        candidate[i] = k;
        self(self, i + 1);
      }
    };
    visit(visit, 0);
    if (!best) break;
    sets.push_back(*best);
    for (std::size_t i = 0; i < n; ++i) after[i] = (*best)[i] + 1;
  }
  return sets;
}

std::vector<std::size_t> interleaving(std::mt19937& random, const std::vector<Stamps>& streams) {
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < streams.size(); ++i) order.insert(order.end(), streams[i].size(), i);
  std::shuffle(order.begin(), order.end(), random);
  return order;
}

// The order values would reach a sync if each came when stamped.
std::vector<std::size_t> by_stamp(const std::vector<Stamps>& streams) {
  std::vector<std::pair<Clock::time_point, std::size_t>> all;
  for (std::size_t i = 0; i < streams.size(); ++i)
    for (auto t : streams[i]) all.emplace_back(t, i);
  std::stable_sort(all.begin(), all.end(), [](auto& a, auto& b) { return a.first < b.first; });
  std::vector<std::size_t> order;
  for (auto& [t, i] : all) order.push_back(i);
  return order;
}

void check_guarantees(const std::vector<Stamps>& streams, const std::vector<Set>& sets, Clock::duration max_span) {
  const auto n = streams.size();
  Set after(n, 0);
  for (std::size_t k = 0; k < sets.size(); ++k) {
    auto lo = Clock::time_point::max(), hi = Clock::time_point::min();
    for (std::size_t i = 0; i < n; ++i) {
      lo = std::min(lo, streams[i][sets[k][i]]);
      hi = std::max(hi, streams[i][sets[k][i]]);
    }
    ASSERT_LE(hi - lo, max_span) << "set " << k << " is wider than max_span";
    for (std::size_t i = 0; i < n && k > 0; ++i)
      ASSERT_GT(sets[k][i], sets[k - 1][i]) << "sets " << k - 1 << " and " << k << " cross, or share a value, on input " << i;
    ASSERT_FALSE(set_within(streams, after, sets[k], max_span))
        << "the values skipped before set " << k << " would make a set of their own";
    for (std::size_t i = 0; i < n; ++i) after[i] = sets[k][i] + 1;
  }
}

TEST(ApproximateTimeProperties, RandomStreamsGiveTheBestSetsWhateverTheArrivalOrder) {
  std::mt19937 random{20261126};
  std::size_t total_sets = 0;
  for (int round = 0; round < 120; ++round) {
    const std::size_t inputs = 2 + static_cast<std::size_t>(round % 3);
    const auto max_span = round % 4 == 0 ? Clock::duration{8ms} : Clock::duration::max();
    // Short enough for the exhaustive reference (shorter still with a max_span, whose check is dearer).
    const std::size_t length = max_span != Clock::duration::max() ? (inputs == 4 ? 6 : 9) : (inputs == 4 ? 10 : 16);
    const auto streams = random_streams(random, inputs, length);
    const std::vector<Clock::duration> unknown(inputs, Clock::duration::zero());
    const auto expected = reference(streams, max_span);
    const auto in_stamp_order = online(streams, by_stamp(streams), unknown, max_span);
    SCOPED_TRACE("round " + std::to_string(round) + ", " + std::to_string(inputs) + " inputs");
    check_guarantees(streams, in_stamp_order, max_span);
    EXPECT_EQ(in_stamp_order, expected) << "the exhaustive reference finds other sets";
    total_sets += expected.size();
    for (int shuffle = 0; shuffle < 3; ++shuffle)
      EXPECT_EQ(online(streams, interleaving(random, streams), unknown, max_span), in_stamp_order)
          << "the sets depend on the arrival order across inputs";
  }
  EXPECT_GT(total_sets, 300u) << "the streams make sets to compare";
}

TEST(ApproximateTimeProperties, KnowingTheInputsIntervalsDecidesSoonerAndChangesNothing) {
  std::mt19937 random{7};
  std::size_t sooner = 0, later = 0;
  for (int round = 0; round < 60; ++round) {
    const std::size_t inputs = 2 + static_cast<std::size_t>(round % 3);
    auto streams = random_streams(random, inputs, inputs == 4 ? 10 : 16);
    // The least interval each input really keeps.
    std::vector<Clock::duration> intervals(inputs, Clock::duration::max());
    for (std::size_t i = 0; i < inputs; ++i)
      for (std::size_t k = 1; k < streams[i].size(); ++k) intervals[i] = std::min(intervals[i], streams[i][k] - streams[i][k - 1]);
    const std::vector<Clock::duration> unknown(inputs, Clock::duration::zero());
    std::size_t with = 0, without = 0;
    const auto order = by_stamp(streams);
    const auto known = online(streams, order, intervals, Clock::duration::max(), &with);
    const auto plain = online(streams, order, unknown, Clock::duration::max(), &without);
    SCOPED_TRACE("round " + std::to_string(round));
    EXPECT_EQ(known, plain) << "the bound changes when sets are decided, never which";
    EXPECT_GE(with, without) << "a bound never makes it decide later";
    sooner += with;
    later += without;
  }
  EXPECT_GT(sooner, later) << "over all rounds, the bounds let it decide sets sooner";
}

TEST(ApproximateTimeProperties, AnAgePenaltyPrefersEarlierSetsKeepsTheGuaranteesAndDecidesSooner) {
  std::mt19937 random{1126};
  std::size_t differ = 0, sooner = 0, later = 0;
  for (int round = 0; round < 90; ++round) {
    const std::size_t inputs = 2 + static_cast<std::size_t>(round % 3);
    const double penalty = round % 2 == 0 ? 0.5 : 2.0;  // exact in binary: the reference costs match to the nanosecond
    const auto streams = random_streams(random, inputs, inputs == 4 ? 10 : 16);
    // Half the rounds tell the matcher each input's least interval.
    std::vector<Clock::duration> intervals(inputs, Clock::duration::zero());
    if (round % 4 >= 2)
      for (std::size_t i = 0; i < inputs; ++i) {
        intervals[i] = Clock::duration::max();
        for (std::size_t k = 1; k < streams[i].size(); ++k) intervals[i] = std::min(intervals[i], streams[i][k] - streams[i][k - 1]);
      }
    const auto any = Clock::duration::max();
    std::size_t with = 0, without = 0;
    const auto order = by_stamp(streams);
    const auto penalised = online(streams, order, intervals, any, &with, penalty);
    const auto plain = online(streams, order, intervals, any, &without);
    SCOPED_TRACE("round " + std::to_string(round) + ", age penalty " + std::to_string(penalty));
    check_guarantees(streams, penalised, any);
    EXPECT_EQ(penalised, reference(streams, any, penalty)) << "the exhaustive reference finds other sets";
    EXPECT_EQ(online(streams, interleaving(random, streams), intervals, any, nullptr, penalty), penalised)
        << "the sets depend on the arrival order across inputs";
    differ += penalised != plain;
    sooner += with;
    later += without;
  }
  EXPECT_GT(differ, 0u) << "the penalty changes which sets are made";
  EXPECT_GT(sooner, later) << "over all rounds, the penalty lets it decide sets sooner";
}

}  // namespace
}  // namespace prime::test
