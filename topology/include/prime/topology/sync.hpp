#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <type_traits>
#include <vector>
#include <stop_token>
#include <string>
#include <tuple>
#include <utility>

#include "prime/logic/sample.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/approximate_time.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/runtime.hpp"

namespace prime {

// The most sources one sync takes.
inline constexpr std::size_t kMaxSyncInputs = 8;
// latest_of_each fired by a value of any input, not of one chosen input.
inline constexpr int kAnyInput = -1;

// How `sync` puts values of several sources together.
struct SyncPolicy {
  enum class Kind {
    latest_of_each,    // on each value of the trigger input(s), with the newest of every other
    exact_time,        // values whose stamps are equal
    within_tolerance,  // values whose stamps lie within `tolerance` of each other, greedily
    approximate_time,  // the adaptive, provably best matching (see detail/approximate_time.hpp)
  };
  Kind kind;
  Clock::duration tolerance{0};
  // Values kept per source while waiting for a match; the oldest go first.
  std::size_t depth = 32;
  // approximate_time: its options (see ApproximateTime).
  Clock::duration max_span = Clock::duration::max();
  std::array<Clock::duration, kMaxSyncInputs> min_interval{};
  double age_penalty = 0;
  // latest_of_each: the input whose values make sets, or kAnyInput.
  int trigger = 0;
};

inline constexpr SyncPolicy latest_of_each{SyncPolicy::Kind::latest_of_each};
// latest_of_each made by each value of `input` (0 is the first source), or of any input (kAnyInput).
constexpr SyncPolicy latest_of_each_on(int input) {
  SyncPolicy p{SyncPolicy::Kind::latest_of_each};
  p.trigger = input;
  return p;
}
inline constexpr SyncPolicy exact_time{SyncPolicy::Kind::exact_time};
// The greedy matcher: values within `tolerance`, closest first.
constexpr SyncPolicy within_tolerance(Clock::duration tolerance) {
  return {SyncPolicy::Kind::within_tolerance, tolerance};
}

struct ApproximateTime {
  // Sets wider than this are never made.
  Clock::duration max_span = Clock::duration::max();
  // Per input, the least interval between its values (0: not known): lets
  // a set be decided before the next values arrive, lowering latency.
  std::array<Clock::duration, kMaxSyncInputs> min_interval{};
  // 0: each set has the least span. p > 0: a later set must be narrower by
  // p × how much later it starts to be preferred, so sets come sooner.
  double age_penalty = 0;
  // Values kept per input while waiting for a match.
  std::size_t depth = 32;
};
// The adaptive matcher of ROS's ApproximateTime, written from its
// guarantees: no tolerance needed; each value used at most once; sets do not
// cross; sets are contiguous; each set has the least span among the sets
// contiguous to the one before; what is made depends only on the stamps, not
// on the order values arrive in across inputs.
constexpr SyncPolicy approximate_time(ApproximateTime options = {}) {
  SyncPolicy p{SyncPolicy::Kind::approximate_time};
  p.max_span = options.max_span;
  p.min_interval = options.min_interval;
  p.age_penalty = options.age_penalty;
  p.depth = options.depth;
  return p;
}

// What sync gives: a tuple of one value of each source, with each one's
// stamp, so a chain can check or use the skew of a set. It is a std::tuple
// (std::get, structured bindings, and converts to one).
template <class... Ts>
struct Synced : std::tuple<Ts...> {
  using std::tuple<Ts...>::tuple;
  std::array<Clock::time_point, sizeof...(Ts)> stamps{};

  template <std::size_t I>
  [[nodiscard]] Clock::time_point stamp() const noexcept {
    return stamps[I];
  }
  // The newest stamp of the set less the oldest.
  [[nodiscard]] Clock::duration skew() const noexcept {
    const auto [lo, hi] = std::ranges::minmax(stamps);
    return hi - lo;
  }
};

namespace detail {

// The values of one input waiting for a match: a ring of `capacity`, made
// once, so that a sync in steady state allocates nothing (a std::deque
// takes and frees a node every few values).
template <class T>
class WaitingValues {
 public:
  explicit WaitingValues(std::size_t capacity = 1) : slots_(std::max<std::size_t>(capacity, 1)) {}

  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  [[nodiscard]] bool empty() const noexcept { return size_ == 0; }
  [[nodiscard]] Sample<T>& operator[](std::size_t i) noexcept { return *slots_[(head_ + i) % slots_.size()]; }
  [[nodiscard]] const Sample<T>& operator[](std::size_t i) const noexcept { return *slots_[(head_ + i) % slots_.size()]; }
  [[nodiscard]] Sample<T>& front() noexcept { return (*this)[0]; }
  // Adds a value at the back; there must be room (size() < capacity).
  void push_back(Sample<T>&& sample) {
    slots_[(head_ + size_) % slots_.size()].emplace(std::move(sample));
    ++size_;
  }
  void pop_front() noexcept {
    slots_[head_].reset();
    head_ = (head_ + 1) % slots_.size();
    --size_;
  }

 private:
  std::vector<std::optional<Sample<T>>> slots_;
  std::size_t head_ = 0;
  std::size_t size_ = 0;
};

// Matches the values of N sources by stamp (stamps rise per source) and
// publishes each match as a tuple. Every input's worker offers into it.
//
// Thread-safe.
template <class... Ts>
class Synchronizer {
 public:
  using Tuple = Synced<Ts...>;
  static constexpr std::size_t kInputs = sizeof...(Ts);
  static_assert(kInputs <= kMaxSyncInputs, "prime::sync takes at most kMaxSyncInputs sources");
  static_assert(kMaxSyncInputs <= ApproximateMatch::kMaxInputs);

  // `depths`: how many values of each input may wait for a match.
  Synchronizer(SyncPolicy policy, std::array<std::size_t, kInputs> depths, LocalSource<Tuple> out)
      : policy_{policy},
        depths_{depths},
        out_{std::move(out)},
        queues_{waiting(depths, std::make_index_sequence<kInputs>{})} {
    earliest_next_.fill(Clock::time_point::min());
    for (std::size_t i = 0; i < kInputs; ++i) stamps_[i].reserve(depths[i]);
  }

  template <std::size_t I>
  void offer(Sample<std::tuple_element_t<I, std::tuple<Ts...>>>&& sample, std::stop_token stop) {
    std::scoped_lock lock{mutex_};  // held while publishing, so matches leave in order
    if (policy_.kind == SyncPolicy::Kind::latest_of_each) {
      const auto stamp = sample.stamp;
      std::get<I>(latest_) = std::move(sample);
      if (policy_.trigger == kAnyInput || policy_.trigger == static_cast<int>(I))
        publish_latest(stamp, stop, std::make_index_sequence<kInputs>{});
      return;
    }
    earliest_next_[I] = sample.stamp + policy_.min_interval[I];
    auto& queue = std::get<I>(queues_);
    if (queue.size() >= depths_[I]) queue.pop_front();
    queue.push_back(std::move(sample));
    if (policy_.kind == SyncPolicy::Kind::approximate_time)
      publish_approximate(stop, std::make_index_sequence<kInputs>{});
    else
      publish_matches(stop, std::make_index_sequence<kInputs>{});
  }

 private:
  template <std::size_t... I>
  static std::tuple<WaitingValues<Ts>...> waiting(const std::array<std::size_t, kInputs>& depths, std::index_sequence<I...>) {
    return {WaitingValues<Ts>{depths[I]}...};
  }

  template <std::size_t... I>
  void publish_latest(Clock::time_point stamp, std::stop_token& stop, std::index_sequence<I...>) {
    if (!(std::get<I>(latest_).has_value() && ...)) return;
    const std::array<Clock::time_point, kInputs> stamps{std::get<I>(latest_)->stamp...};
    Tuple set{take_or_copy<I>()...};
    set.stamps = stamps;
    out_.publish(std::move(set), stamp, stop);
  }
  // One chosen trigger's value is used once; every other value stays for
  // the next set (all stay when any input triggers).
  template <std::size_t I>
  auto take_or_copy() {
    if constexpr (std::is_move_constructible_v<std::tuple_element_t<I, std::tuple<Ts...>>>) {
      if (policy_.trigger == static_cast<int>(I)) {
        auto value = std::move(std::get<I>(latest_)->value);
        std::get<I>(latest_).reset();
        return value;
      }
    }
    return std::get<I>(latest_)->value;
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
      Tuple set{take_front<I>()...};
      set.stamps = taken_;
      out_.publish(std::move(set), newest, stop);
    }
  }

  template <std::size_t... I>
  void publish_approximate(std::stop_token& stop, std::index_sequence<I...>) {
    while (true) {
      ((stamps_of(std::get<I>(queues_), stamps_[I])), ...);
      const std::array<std::span<const Clock::time_point>, kInputs> spans{std::span<const Clock::time_point>{stamps_[I]}...};
      const auto match = match_approximate(spans, earliest_next_, policy_.max_span, policy_.age_penalty);
      if (match.kind == ApproximateMatch::Kind::wait) return;
      if (match.kind == ApproximateMatch::Kind::drop_oldest) {
        ((I == match.input ? std::get<I>(queues_).pop_front() : void()), ...);
        continue;
      }
      ((drop_front(std::get<I>(queues_), match.picks[I])), ...);
      Tuple set{take_front<I>()...};
      set.stamps = taken_;
      out_.publish(std::move(set), *std::ranges::max_element(taken_), stop);
    }
  }

  // The queue's stamps into `stamps`, whose memory stays for the next time.
  template <class Q>
  static void stamps_of(const Q& queue, std::vector<Clock::time_point>& stamps) {
    stamps.clear();
    for (std::size_t i = 0; i < queue.size(); ++i) stamps.push_back(queue[i].stamp);
  }
  template <class Q>
  static void drop_front(Q& queue, std::size_t n) {
    for (std::size_t k = 0; k < n; ++k) queue.pop_front();
  }
  template <class Q>
  static void skip_to_closest(Q& queue, Clock::time_point newest) {
    while (queue.size() >= 2 && queue[1].stamp <= newest) queue.pop_front();
  }
  template <std::size_t I>
  auto take_front() {
    auto& queue = std::get<I>(queues_);
    auto value = std::move(queue.front().value);
    taken_[I] = queue.front().stamp;
    queue.pop_front();
    return value;
  }

  const SyncPolicy policy_;
  const std::array<std::size_t, kInputs> depths_;
  LocalSource<Tuple> out_;
  std::mutex mutex_;
  std::tuple<std::optional<Sample<Ts>>...> latest_;
  std::tuple<WaitingValues<Ts>...> queues_;
  std::array<Clock::time_point, kInputs> earliest_next_{};  // where each input's next value could lie at the earliest
  std::array<Clock::time_point, kInputs> taken_{};          // the stamps of the set being made
  std::array<std::vector<Clock::time_point>, kInputs> stamps_;  // approximate_time: each queue's stamps, for the matcher
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
    if (b.smallest != 0) b.queued_sets = std::max<std::size_t>(1, b.smallest > 2 ? (b.smallest - 2) / 4 : 0);
    return b;
  }

  // How many values of an input may wait for a match.
  [[nodiscard]] std::size_t depth(std::size_t wanted, const Qos& qos, const std::string& sync,
                                  const std::string& source) const {
    if (qos.max_held == 0) return wanted;
    const auto others = 2 + queued_sets;  // one being read, one the reader holds, those queued for it
    if (qos.max_held <= others)
      throw Failure{{Errc::invalid_argument,
                     sync + ": source '" + source + "' lets a reader hold " + std::to_string(qos.max_held) +
                         " values (max_held); a sync needs at least " + std::to_string(others + 1) +
                         ": one waiting for a match, one being read, " + std::to_string(queued_sets) +
                         " in the sets queued for its reader, one in the set that reader holds"}};
    return std::min(wanted, qos.max_held - others);
  }
  // The QoS of the sync's own output: its reader may hold what the inputs' may.
  [[nodiscard]] Qos output(Qos qos) const {
    qos.max_held = smallest;
    if (queued_sets != 0) qos.capacity = std::min(qos.capacity, queued_sets);
    return qos;
  }
};

template <class... S, std::size_t... I>
auto start_sync(SyncPolicy policy, std::index_sequence<I...>, const S&... sources) {
  using Tuple = Synced<typename S::value_type...>;
  const auto& first = std::get<0>(std::forward_as_tuple(sources...));
  auto runtime = first.runtime().lock();
  if (!runtime) throw Failure{{Errc::stopped, "sync: the core that owns source '" + first.name() + "' is gone"}};
  std::string name = "sync(";
  ((name += (I == 0 ? "" : ", ") + sources.name()), ...);
  name += ")";
  if (policy.depth == 0 && policy.kind != SyncPolicy::Kind::latest_of_each)
    throw Failure{{Errc::invalid_argument, name + ": a depth of 0 keeps no value to match (at least 1)"}};
  const auto budget = SyncBudget::of({sources.qos().max_held...});
  const std::array<std::size_t, sizeof...(S)> depths{budget.depth(policy.depth, sources.qos(), name, sources.name())...};
  Graph graph = Graph::sequence(Graph::parallel({&sources.graph()...}), Graph::node(name, "sync", runtime->medium()));
  LocalSource<Tuple> out{name, budget.output(first.qos()), first.runtime(), std::move(graph)};
  auto matcher = std::make_shared<Synchronizer<typename S::value_type...>>(policy, depths, out);
  (spawn_reader(sources.runtime(), sources.subscribe(), name + " input '" + sources.name() + "'",
                [matcher](auto&& sample, std::stop_token stop) {
                  matcher->template offer<I>(std::move(sample), std::move(stop));
                }),
   ...);
  return out;
}

}  // namespace detail

// A source of tuples (Synced: a std::tuple with each part's stamp), one
// value of each source per tuple, put together by timestamp as `policy`
// says: how asynchronous sensors meet a synchronous chain. One worker per
// input source; the sample's stamp is the newest of its parts (for
// latest_of_each, the triggering value's).
template <Source... S>
  requires(sizeof...(S) >= 2)
[[nodiscard]] auto sync(SyncPolicy policy, const S&... sources) {
  return detail::start_sync(policy, std::index_sequence_for<S...>{}, sources...);
}

}  // namespace prime

template <class... Ts>
struct std::tuple_size<prime::Synced<Ts...>> : std::integral_constant<std::size_t, sizeof...(Ts)> {};
template <std::size_t I, class... Ts>
struct std::tuple_element<I, prime::Synced<Ts...>> : std::tuple_element<I, std::tuple<Ts...>> {};
