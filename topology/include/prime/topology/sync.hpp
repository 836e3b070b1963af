#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>
#include <deque>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <tuple>
#include <utility>

#include "prime/logic/sample.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/runtime.hpp"

namespace prime {

// How `sync` puts values of several sources together.
struct SyncPolicy {
  enum class Kind {
    latest_of_each,    // on each value of the first source, with the newest of every other
    exact_time,        // values whose stamps are equal
    approximate_time,  // values whose stamps lie within `tolerance` of each other
  };
  Kind kind;
  Clock::duration tolerance{0};
  // Values kept per source while waiting for a match; the oldest go first.
  std::size_t depth = 32;
};

inline constexpr SyncPolicy latest_of_each{SyncPolicy::Kind::latest_of_each};
inline constexpr SyncPolicy exact_time{SyncPolicy::Kind::exact_time};
constexpr SyncPolicy approximate_time(Clock::duration tolerance) {
  return {SyncPolicy::Kind::approximate_time, tolerance};
}

namespace detail {

// Matches the values of N sources by stamp (stamps rise per source) and
// publishes each match as a tuple. Every input's worker offers into it.
//
// Thread-safe.
template <class... Ts>
class Synchronizer {
 public:
  using Tuple = std::tuple<Ts...>;
  static constexpr std::size_t kInputs = sizeof...(Ts);

  // `depths`: how many values of each input may wait for a match.
  Synchronizer(SyncPolicy policy, std::array<std::size_t, kInputs> depths, LocalSource<Tuple> out)
      : policy_{policy}, depths_{depths}, out_{std::move(out)} {}

  template <std::size_t I>
  void offer(Sample<std::tuple_element_t<I, Tuple>>&& sample, std::stop_token stop) {
    std::scoped_lock lock{mutex_};  // held while publishing, so matches leave in order
    if (policy_.kind == SyncPolicy::Kind::latest_of_each) {
      std::get<I>(latest_) = std::move(sample);
      if constexpr (I == 0) publish_latest(stop, std::make_index_sequence<kInputs>{});
      return;
    }
    auto& queue = std::get<I>(queues_);
    if (queue.size() >= depths_[I]) queue.pop_front();
    queue.push_back(std::move(sample));
    publish_matches(stop, std::make_index_sequence<kInputs>{});
  }

 private:
  template <std::size_t... I>
  void publish_latest(std::stop_token& stop, std::index_sequence<I...>) {
    if (!(std::get<I>(latest_).has_value() && ...)) return;
    const auto stamp = std::get<0>(latest_)->stamp;
    out_.publish(Tuple{take_or_copy<I>()...}, stamp, stop);
  }
  // The first source's value is used once; the others stay for the next match.
  template <std::size_t I>
  auto take_or_copy() {
    if constexpr (I == 0) {
      auto value = std::move(std::get<0>(latest_)->value);
      std::get<0>(latest_).reset();
      return value;
    } else {
      return std::get<I>(latest_)->value;
    }
  }

  template <std::size_t... I>
  void publish_matches(std::stop_token& stop, std::index_sequence<I...>) {
    while ((!std::get<I>(queues_).empty() && ...)) {
      const std::array<Clock::time_point, kInputs> heads{std::get<I>(queues_).front().stamp...};
      const auto [lo, hi] = std::ranges::minmax_element(heads);
      if (*hi - *lo > policy_.tolerance) {
        // Nothing that comes later can be as close to the oldest head: drop it.
        const auto oldest = static_cast<std::size_t>(lo - heads.begin());
        ((I == oldest ? std::get<I>(queues_).pop_front() : void()), ...);
        continue;
      }
      // Within each queue, prefer a later value that is still no newer than the newest head.
      const auto newest = *hi;
      ((skip_to_closest(std::get<I>(queues_), newest)), ...);
      out_.publish(Tuple{take_front(std::get<I>(queues_))...}, newest, stop);
    }
  }
  template <class Q>
  static void skip_to_closest(Q& queue, Clock::time_point newest) {
    while (queue.size() >= 2 && queue[1].stamp <= newest) queue.pop_front();
  }
  template <class Q>
  static auto take_front(Q& queue) {
    auto value = std::move(queue.front().value);
    queue.pop_front();
    return value;
  }

  const SyncPolicy policy_;
  const std::array<std::size_t, kInputs> depths_;
  LocalSource<Tuple> out_;
  std::mutex mutex_;
  std::tuple<std::optional<Sample<Ts>>...> latest_;
  std::tuple<std::deque<Sample<Ts>>...> queues_;
};

// A sync of sources whose values pin memory (a shared-memory topic's views
// pin its slots: Qos::max_held) holds no more of each than its reader may:
// besides the values waiting for a match, one being read, the sets queued
// for the sync's reader and the set that reader holds. The queue for the
// reader takes a quarter of the smallest budget (at least one set: a slow
// reader then sees the newest sets), the matching the rest.
struct SyncBudget {
  std::size_t queued_sets;  // 0: no input pins memory
  std::size_t smallest;     // the smallest max_held among the inputs

  static SyncBudget of(std::initializer_list<std::size_t> max_held) {
    SyncBudget b{0, 0};
    for (const auto held : max_held)
      if (held != 0) b.smallest = b.smallest == 0 ? held : std::min(b.smallest, held);
    if (b.smallest != 0) b.queued_sets = std::max<std::size_t>(1, (b.smallest - 2) / 4);
    return b;
  }

  // How many values of an input may wait for a match.
  [[nodiscard]] std::size_t depth(const SyncPolicy& policy, const Qos& qos, const std::string& sync,
                                  const std::string& source) const {
    if (qos.max_held == 0) return policy.depth;
    const auto others = 2 + queued_sets;  // one being read, one the reader holds, those queued for it
    if (qos.max_held <= others)
      throw Failure{{Errc::limit_exceeded,
                     sync + ": source '" + source + "' lets a reader hold " + std::to_string(qos.max_held) +
                         " values (max_held); a sync needs at least " + std::to_string(others + 1) +
                         ": one waiting for a match, one being read, " + std::to_string(queued_sets) +
                         " in the sets queued for its reader, one in the set that reader holds"}};
    return std::min(policy.depth, qos.max_held - others);
  }
};

template <class... S, std::size_t... I>
auto start_sync(SyncPolicy policy, std::index_sequence<I...>, const S&... sources) {
  using Tuple = std::tuple<typename S::value_type...>;
  const auto& first = std::get<0>(std::forward_as_tuple(sources...));
  auto runtime = first.runtime().lock();
  if (!runtime) throw Failure{{Errc::stopped, "sync: the core that owns source '" + first.name() + "' is gone"}};
  std::string name = "sync(";
  ((name += (I == 0 ? "" : ", ") + sources.name()), ...);
  name += ")";
  const auto budget = SyncBudget::of({sources.qos().max_held...});
  const std::array<std::size_t, sizeof...(S)> depths{budget.depth(policy, sources.qos(), name, sources.name())...};
  Qos out_qos = first.qos();
  out_qos.max_held = budget.smallest;
  if (budget.queued_sets != 0) out_qos.capacity = std::min(out_qos.capacity, budget.queued_sets);
  Graph graph = Graph::sequence(Graph::parallel({&sources.graph()...}), Graph::node(name, "sync", runtime->medium()));
  LocalSource<Tuple> out{name, out_qos, first.runtime(), std::move(graph)};
  auto matcher = std::make_shared<Synchronizer<typename S::value_type...>>(policy, depths, out);
  (spawn_reader(sources.runtime(), sources.subscribe(), name + " input '" + sources.name() + "'",
                [matcher](auto&& sample, std::stop_token stop) {
                  matcher->template offer<I>(std::move(sample), std::move(stop));
                }),
   ...);
  return out;
}

}  // namespace detail

// A source of tuples, one value of each source per tuple, put together by
// timestamp as `policy` says: how asynchronous sensors meet a synchronous
// chain. One worker per input source; the tuple carries the newest stamp of
// its parts (for latest_of_each, the first source's).
template <Source... S>
  requires(sizeof...(S) >= 2)
[[nodiscard]] auto sync(SyncPolicy policy, const S&... sources) {
  return detail::start_sync(policy, std::index_sequence_for<S...>{}, sources...);
}

}  // namespace prime
