#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <expected>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/subscriber.hpp"
#include "prime/shm/message.hpp"
#include "prime/shm/qos.hpp"
#include "prime/shm/view.hpp"
#include "prime/shm/views.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/detail/wait.hpp"
#include "prime/topology/graph.hpp"

namespace prime::shm {

// One subscriber of a topic, with its own cursor and slot: the Reader a
// subscription gives. It holds at most the topic's max_held samples at once
// (views alive, copies counting once): past that, try_read() gives nothing
// (and says so once on core.errors()), and the waiting reads wait for a view
// to be released, failing with Errc::held_limit at their deadline.
template <Message T>
class SubscriptionReader final : public Reader<View<T>>::Impl {
 public:
  // `feed`: what publishes into the topic for a source made from an event,
  // kept while anyone reads it.
  SubscriptionReader(std::shared_ptr<detail::Topic> topic, SubscribeQos qos,
                     std::weak_ptr<prime::detail::RuntimeState> runtime, bool observer = false,
                     std::shared_ptr<const void> feed = {})
      : subscriber_{detail::Subscriber::create(std::move(topic), qos.history, observer)},
        spin_{qos.spin},
        runtime_{std::move(runtime)},
        feed_{std::move(feed)} {}

  // Damage found in the ring (Errc::damaged) goes to core.errors(): the
  // sample it names is passed over.
  std::optional<Sample<View<T>>> try_read() override {
    auto taken = take();
    if (auto damage = subscriber_->cursor().take_damage()) report(std::move(*damage));
    return taken;
  }

  std::expected<Sample<View<T>>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    while (true) {  // a sample overwritten between the wait and the take sends it back to waiting
      if (auto ready = wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
      if (auto sample = take()) return std::move(*sample);
      if (auto why = why_nothing(deadline, stop)) return std::unexpected(std::move(*why));
    }
  }

  std::expected<std::size_t, Error> read_some(std::vector<Sample<View<T>>>& out, std::size_t max,
                                              Clock::time_point deadline, std::stop_token stop) override {
    if (max == 0) return 0;
    while (true) {
      if (auto ready = wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
      // Each view holds its slot: a batch is at most what the budget has left.
      // Taken in one step (one store of the cursor), then made views.
      // Room in `out` and `taken_` first: from the take on, nothing may throw.
      const auto room = subscriber_->max_held() - std::min(subscriber_->held(), subscriber_->max_held());
      out.reserve(out.size() + std::min(max, room));
      taken_.clear();
      taken_.reserve(std::min(max, room));
      const auto n = subscriber_->cursor().take_some(std::min(max, room), taken_);
      subscriber_->hold_taken(taken_);
      for (const auto& t : taken_) out.push_back(sample(View<T>{subscriber_.get(), t, typename View<T>::Held{}}));
      if (n > 0) {
        budget_reported_ = false;
        return n;
      }
      if (auto why = why_nothing(deadline, stop)) return std::unexpected(std::move(*why));
    }
  }

  // Up to `max` samples taken at once as a batch (Views), waiting as
  // read_some does: at most what the budget has left.
  std::expected<Views<T>, Error> read_views(std::size_t max, Clock::time_point deadline, std::stop_token stop) {
    if (max == 0) return Views<T>{};
    while (true) {
      if (auto ready = wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
      if (auto views = take_views(max); !views.empty()) return views;
      if (auto why = why_nothing(deadline, stop)) return std::unexpected(std::move(*why));
    }
  }
  // What is published now, up to `max`: an empty batch when nothing is (or
  // the budget is spent, which is reported once, as try_read does).
  Views<T> try_read_views(std::size_t max) {
    if (subscriber_->at_budget()) {
      report_budget();
      return {};
    }
    auto views = take_views(max);
    if (auto damage = subscriber_->cursor().take_damage()) report(std::move(*damage));
    return views;
  }

  // The newest sample, skipping what is older. At its budget the reader
  // lets go of the one it keeps first, so a collector costs one sample of
  // the budget; but not while a copy of it lives elsewhere (a chain still
  // reading it): letting go would free nothing, and the newest could not
  // be read. The one it keeps then stays, and the budget is reported as
  // try_read() reports it.
  void read_latest(std::optional<Sample<View<T>>>& latest) override {
    auto& cursor = subscriber_->cursor();
    if (!cursor.ready()) {
      cursor.acknowledge_all();  // nothing new: the publisher may as well know it
      return;
    }
    cursor.skip_to_newest();
    if (subscriber_->at_budget() && latest && latest->value.only_view()) latest.reset();
    if (auto s = try_read()) latest = std::move(s);
  }

  [[nodiscard]] std::uint64_t lost() const override { return subscriber_->cursor().lost(); }

 private:
  std::optional<Sample<View<T>>> take() {
    if (subscriber_->at_budget()) {
      report_budget();
      return std::nullopt;
    }
    auto taken = subscriber_->cursor().try_take();
    if (!taken) return std::nullopt;
    budget_reported_ = false;
    return sample(View<T>{subscriber_.get(), *taken});
  }

  Views<T> take_views(std::size_t max) {
    const auto room = subscriber_->max_held() - std::min(subscriber_->held(), subscriber_->max_held());
    const auto index = subscriber_->cursor().take_batch(std::min(max, room), subscriber_->held());
    if (!index) return {};
    subscriber_->hold_batch(subscriber_->cursor().batch(*index).chunks.size());
    budget_reported_ = false;
    return Views<T>{subscriber_.get(), *index};
  }

  static Sample<View<T>> sample(View<T> view) {
    const auto stamp = view.stamp();
    return {std::move(view), stamp};
  }

  // Why a take found nothing though a wait said a sample was out, if that
  // ends the read: damage in the ring, a stop, or the deadline (a wait
  // returns at once while the ring's entry says a sample is out). Nothing:
  // a sample overwritten meanwhile, and the read waits again.
  std::optional<Error> why_nothing(Clock::time_point deadline, const std::stop_token& stop) {
    if (auto damage = subscriber_->cursor().take_damage()) return damage;
    const auto& name = subscriber_->topic().name();
    if (stop.stop_requested()) return Error{Errc::stopped, "source '" + name + "': stopped while waiting"};
    if (Clock::now() >= deadline) return Error{Errc::timeout, "source '" + name + "': nothing published in time"};
    return std::nullopt;
  }

  void report_budget() {
    if (budget_reported_) return;
    budget_reported_ = true;
    report({Errc::held_limit, budget_message() + " (it reads on once one is released)"});
  }
  void report(Error error) {
    if (auto runtime = runtime_.lock()) runtime->report(std::move(error));
  }
  std::string budget_message() const {
    return "topic '" + subscriber_->topic().name() + "': a reader holds its max_held of " +
           std::to_string(subscriber_->max_held()) + " samples";
  }

  // Until a sample can be taken: first until the budget has room (a view
  // released, perhaps on another thread), then until one is published —
  // spinning for `spin_`, then asleep on the topic's futex. Ends early on
  // `deadline` or a stop request.
  std::expected<void, Error> wait(Clock::time_point deadline, const std::stop_token& stop) {
    using prime::detail::Waited;
    auto& cursor = subscriber_->cursor();
    auto& data = cursor.topic()->header().data;
    auto& released = subscriber_->released();
    // The stop flag is set before the callback rings, and a sleeper reads the
    // bell before it checks the flag: a stop is never slept through.
    std::stop_callback wake{stop, [&] {
                              data.ring_always();
                              released.ring_always();
                            }};
    auto stopped = [&] { return Error{Errc::stopped, "source '" + cursor.topic()->name() + "': stopped while waiting"}; };
    // What it has read is acknowledged before it waits: a `block` publisher
    // may be waiting for it.
    if (subscriber_->at_budget() || !cursor.ready()) cursor.acknowledge_all();
    if (subscriber_->at_budget()) {
      auto room = [&] { return !subscriber_->at_budget(); };
      auto sleep = [&](Clock::time_point until) {
        released.sleep_until(1, [&] { return room() || stop.stop_requested(); }, until);
      };
      const auto waited = prime::detail::spin_then_sleep(room, sleep, std::chrono::nanoseconds::zero(), deadline, stop);
      if (waited == Waited::stopped) return std::unexpected(stopped());
      if (waited == Waited::timeout) return std::unexpected(Error{Errc::held_limit, budget_message() + " until the deadline"});
    }
    auto sleep = [&](Clock::time_point until) { cursor.sleep_until([&] { return stop.stop_requested(); }, until); };
    const auto waited = prime::detail::spin_then_sleep(prime::detail::yielding([&] { return cursor.ready(); }), sleep, spin_, deadline, stop);
    if (waited == Waited::stopped) return std::unexpected(stopped());
    if (waited == Waited::timeout)
      return std::unexpected(Error{Errc::timeout, "source '" + cursor.topic()->name() + "': nothing published in time"});
    return {};
  }

  detail::SubscriberOwner subscriber_;
  std::chrono::microseconds spin_;
  std::weak_ptr<prime::detail::RuntimeState> runtime_;
  std::shared_ptr<const void> feed_;
  bool budget_reported_ = false;
  std::vector<detail::Taken> taken_;  // read_some's scratch
};

// A subscriber that reads in batches (Views): the cheapest way to drain a
// high-rate topic in place. It has its own cursor and slot of the topic,
// like a Reader. Move-only; one thread at a time reads.
template <Message T>
class BatchReader {
 public:
  explicit BatchReader(std::unique_ptr<SubscriptionReader<T>> reader) : reader_{std::move(reader)} {}

  // Up to `max` samples, once at least one is published; fails with
  // Errc::timeout at `deadline`, Errc::stopped on a stop request, and
  // Errc::held_limit when the batches out hold max_held until then.
  std::expected<Views<T>, Error> read(std::size_t max, Clock::time_point deadline, std::stop_token stop = {}) {
    return reader_->read_views(max, deadline, std::move(stop));
  }
  // Up to `max` samples published now; empty when none is.
  [[nodiscard]] Views<T> try_read(std::size_t max) { return reader_->try_read_views(max); }
  // Samples overwritten before this reader took them (drop_oldest, or
  // while a `block` publisher passed it over).
  [[nodiscard]] std::uint64_t lost() const { return reader_->lost(); }

 private:
  std::unique_ptr<SubscriptionReader<T>> reader_;
};

// A topic seen as a source of the topology: `subscription | chain`,
// `collector` and `sync` take it like any other source. Each subscribe() is
// a subscriber of its own, with its own cursor and slot of the topic (so a
// link, a collector and each input of a sync each take one). Copies share
// what they hold.
template <Message T>
class Subscription {
 public:
  using value_type = View<T>;

  // `feed`: what publishes into the topic, for a source made from an event
  // (Core::source); it lasts while the subscription or any reader does.
  Subscription(std::shared_ptr<detail::Topic> topic, SubscribeQos qos, std::weak_ptr<prime::detail::RuntimeState> runtime,
               Graph graph, std::shared_ptr<const void> feed = {})
      : state_{std::make_shared<const State>(
            State{std::move(topic), qos, std::move(runtime), std::move(graph), std::move(feed)})} {}

  [[nodiscard]] Reader<View<T>> subscribe() const {
    return Reader<View<T>>{
        std::make_unique<SubscriptionReader<T>>(state_->topic, state_->qos, state_->runtime, false, state_->feed)};
  }
  // A reader with its own spin. A reader reads the topic's ring, so its
  // capacity and overflow are the topic's; a capacity of 0 is refused as
  // everywhere.
  [[nodiscard]] Reader<View<T>> subscribe(const Qos& qos) const {
    validate(qos, name());
    auto own = state_->qos;
    own.spin = qos.spin;
    return Reader<View<T>>{std::make_unique<SubscriptionReader<T>>(state_->topic, own, state_->runtime, false, state_->feed)};
  }

  // A subscriber of its own that reads in batches.
  [[nodiscard]] BatchReader<T> batches() const {
    return BatchReader<T>{
        std::make_unique<SubscriptionReader<T>>(state_->topic, state_->qos, state_->runtime, false, state_->feed)};
  }

  [[nodiscard]] const std::string& name() const noexcept { return state_->topic->name(); }
  [[nodiscard]] Qos qos() const noexcept {
    const auto topic = state_->topic->qos();
    return {.capacity = topic.capacity,
            .overflow = topic.overflow,
            .block_timeout = topic.block_timeout,
            .spin = state_->qos.spin,
            .max_held = topic.max_held};
  }
  [[nodiscard]] TopicQos topic_qos() const noexcept { return state_->topic->qos(); }
  [[nodiscard]] const Graph& graph() const noexcept { return state_->graph; }
  [[nodiscard]] std::weak_ptr<prime::detail::RuntimeState> runtime() const noexcept { return state_->runtime; }

 private:
  struct State {
    std::shared_ptr<detail::Topic> topic;
    SubscribeQos qos;
    std::weak_ptr<prime::detail::RuntimeState> runtime;
    Graph graph;
    std::shared_ptr<const void> feed;
  };
  std::shared_ptr<const State> state_;
};

static_assert(Source<Subscription<int>>);

}  // namespace prime::shm
