#pragma once

#include <chrono>
#include <concepts>
#include <cstddef>
#include <algorithm>
#include <deque>
#include <iterator>
#include <expected>
#include <memory>
#include <mutex>
#include <stop_token>
#include <string>
#include <type_traits>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/runtime.hpp"
#include "prime/topology/sync.hpp"

namespace prime {

// How `interpolate_at` pairs each value of a trigger source with another
// source's value at the trigger's stamp.
struct Interpolation {
  std::size_t depth = 64;  // values of each source kept while waiting (fewer when they pin memory)
  // The widest gap between the two values interpolated between: beyond it
  // the value is an error, not a guess.
  Clock::duration max_gap = Clock::duration::max();
};

namespace detail {

// A value as interpolation sees it: a shared-memory view reads through to
// its message; anything else is itself.
template <class V>
const auto& plain(const V& v) {
  if constexpr (requires { *v; } && !std::is_arithmetic_v<V>) return *v;
  else return v;
}
template <class V>
using plain_t = std::remove_cvref_t<decltype(plain(std::declval<const V&>()))>;

// `before` + (`after` − `before`) × `fraction`: numbers as they are (in
// double, so an unsigned value that goes down does not wrap around), other
// types by an `interpolate(before, after, fraction)` found next to them.
template <class T>
T interpolated(const T& before, const T& after, double fraction) {
  if constexpr (std::is_floating_point_v<T>) {
    return static_cast<T>(before + (after - before) * fraction);
  } else if constexpr (std::is_arithmetic_v<T>) {
    const auto from = static_cast<double>(before);
    return static_cast<T>(from + (static_cast<double>(after) - from) * fraction);
  } else {
    return interpolate(before, after, fraction);
  }
}

template <class A, class V>
class Interpolator {
 public:
  using Value = std::expected<plain_t<V>, Error>;
  using Set = Synced<A, Value>;

  // `trigger_depth`, `other_depth`: how many values of each may wait.
  Interpolator(std::string other_name, Interpolation options, std::size_t trigger_depth, std::size_t other_depth,
               LocalSource<Set> out)
      : other_name_{std::move(other_name)},
        options_{options},
        trigger_depth_{trigger_depth},
        other_depth_{other_depth},
        out_{std::move(out)} {}

  void offer_trigger(Sample<A>&& sample, std::stop_token stop) {
    std::scoped_lock lock{mutex_};
    pending_.push_back(std::move(sample));
    resolve(stop);
  }
  void offer_other(Sample<V>&& sample, std::stop_token stop) {
    std::scoped_lock lock{mutex_};
    others_.push_back(std::move(sample));
    while (others_.size() > other_depth_) others_.pop_front();
    resolve(stop);
  }

 private:
  // Answers the waiting triggers that can be answered now, oldest first.
  void resolve(std::stop_token& stop) {
    while (!pending_.empty()) {
      const auto t = pending_.front().stamp;
      const auto after = std::find_if(others_.begin(), others_.end(), [t](const auto& s) { return s.stamp >= t; });
      if (after == others_.end()) {  // the other source has not passed t yet
        if (pending_.size() <= trigger_depth_) return;
        emit(error("no value of '" + other_name_ + "' after this stamp came while " + std::to_string(trigger_depth_) +
                   " values of the trigger waited"), stop);
        continue;
      }
      if (after->stamp == t) {
        emit(Value{plain(after->value)}, stop);
        continue;
      }
      if (after == others_.begin()) {
        emit(error("its stamp lies before the oldest value of '" + other_name_ + "' kept: out of range"), stop);
        continue;
      }
      const auto before = std::prev(after);
      const auto gap = after->stamp - before->stamp;
      if (gap > options_.max_gap) {
        emit(error("the values of '" + other_name_ + "' around its stamp are " +
                   std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(gap).count()) +
                   " ms apart, more than max_gap"), stop);
        continue;
      }
      const double fraction = std::chrono::duration<double>(t - before->stamp) / std::chrono::duration<double>(gap);
      emit(Value{interpolated(plain(before->value), plain(after->value), fraction)}, stop);
      others_.erase(others_.begin(), before);  // triggers rise: what lies before is never needed again
    }
  }

  static Value error(std::string why) { return std::unexpected(Error{Errc::no_data, std::move(why)}); }

  void emit(Value value, std::stop_token& stop) {
    auto trigger = std::move(pending_.front());
    pending_.pop_front();
    Set set{std::move(trigger.value), std::move(value)};
    set.stamps = {trigger.stamp, trigger.stamp};
    out_.publish(std::move(set), trigger.stamp, stop);
  }

  const std::string other_name_;
  const Interpolation options_;
  const std::size_t trigger_depth_, other_depth_;
  LocalSource<Set> out_;
  std::mutex mutex_;
  std::deque<Sample<A>> pending_;
  std::deque<Sample<V>> others_;
};

}  // namespace detail

// A source of Synced<A, std::expected<B, Error>>: each value of `trigger`
// with `other` interpolated at its stamp (odometry at the lidar's stamp).
// B is other's value type (a shared-memory view's message); numbers
// interpolate linearly, other types by an `interpolate(before, after,
// fraction)` of their own. A stamp outside what `other` brackets, or across
// a gap wider than `options.max_gap`, gives an error value
// (Errc::no_data), never a guess; a trigger waits for a value of `other` at
// or after its stamp. Like sync, it keeps within the values a shared-memory
// topic lets one reader hold (Qos::max_held).
template <Source Trigger, Source Other>
[[nodiscard]] auto interpolate_at(const Trigger& trigger, const Other& other, Interpolation options = {}) {
  using A = typename Trigger::value_type;
  using V = typename Other::value_type;
  using Matcher = detail::Interpolator<A, V>;
  auto runtime = trigger.runtime().lock();
  if (!runtime) throw Failure{{Errc::stopped, "interpolate_at: the core that owns source '" + trigger.name() + "' is gone"}};
  const std::string name = "interpolate(" + other.name() + " at " + trigger.name() + ")";
  Graph graph = Graph::sequence(Graph::parallel({&trigger.graph(), &other.graph()}), Graph::node(name, "sync", runtime->medium()));
  const auto budget = detail::SyncBudget::of({trigger.qos().max_held, other.qos().max_held});
  LocalSource<typename Matcher::Set> out{name, budget.output(trigger.qos()), trigger.runtime(), std::move(graph)};
  auto matcher = std::make_shared<Matcher>(other.name(), options, budget.depth(options.depth, trigger.qos(), name, trigger.name()),
                                           budget.depth(options.depth, other.qos(), name, other.name()), out);
  detail::spawn_reader(trigger.runtime(), trigger.subscribe(), name + " input '" + trigger.name() + "'",
                       [matcher](Sample<A>&& s, std::stop_token stop) { matcher->offer_trigger(std::move(s), std::move(stop)); });
  detail::spawn_reader(other.runtime(), other.subscribe(), name + " input '" + other.name() + "'",
                       [matcher](Sample<V>&& s, std::stop_token stop) { matcher->offer_other(std::move(s), std::move(stop)); });
  return out;
}

}  // namespace prime
