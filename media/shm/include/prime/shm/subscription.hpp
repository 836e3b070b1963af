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
#include "prime/shm/subscriber_port.hpp"
#include "prime/shm/message.hpp"
#include "prime/shm/qos.hpp"
#include "prime/shm/view.hpp"
#include "prime/shm/views.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/runtime_state.hpp"
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
      : port_{std::move(topic), qos, std::move(runtime), observer}, feed_{std::move(feed)} {}

  // Damage found in the ring (Errc::damaged) goes to core.errors(): the
  // sample it names is passed over.
  std::optional<Sample<View<T>>> try_read() override {
    auto taken = port_.try_take(true);
    if (!taken) return std::nullopt;
    return sample(*taken);
  }

  std::expected<Sample<View<T>>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    while (true) {  // a sample overwritten between the wait and the take sends it back to waiting
      if (auto ready = port_.wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
      if (auto taken = port_.try_take(false)) return sample(*taken);
      if (auto why = port_.why_nothing(deadline, stop)) return std::unexpected(std::move(*why));
    }
  }

  std::expected<std::size_t, Error> read_some(std::vector<Sample<View<T>>>& out, std::size_t max,
                                              Clock::time_point deadline, std::stop_token stop) override {
    if (max == 0) return 0;
    while (true) {
      if (auto ready = port_.wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
      // Each view holds its slot: a batch is at most what the budget has left.
      // Taken in one step (one store of the cursor), then made views.
      // Room in `out` and `taken_` first: from the take on, nothing may throw.
      const auto most = std::min(max, port_.room());
      out.reserve(out.size() + most);
      taken_.clear();
      taken_.reserve(most);
      const auto n = port_.take_some(most, taken_);
      for (const auto& t : taken_) out.push_back(sample(t));
      if (n > 0) return n;
      if (auto why = port_.why_nothing(deadline, stop)) return std::unexpected(std::move(*why));
    }
  }

  // Up to `max` samples taken at once as a batch (Views), waiting as
  // read_some does: at most what the budget has left.
  std::expected<Views<T>, Error> read_views(std::size_t max, Clock::time_point deadline, std::stop_token stop) {
    if (max == 0) return Views<T>{};
    while (true) {
      if (auto ready = port_.wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
      if (auto taken = port_.take_span(max, false)) return views(*taken);
      if (auto why = port_.why_nothing(deadline, stop)) return std::unexpected(std::move(*why));
    }
  }
  // What is published now, up to `max`: an empty batch when nothing is (or
  // the budget is spent, which is reported once, as try_read does).
  Views<T> try_read_views(std::size_t max) {
    if (auto taken = port_.take_span(max, true)) return views(*taken);
    return {};
  }

  // The newest sample, skipping what is older. At its budget the reader
  // lets go of the one it keeps first, so a collector costs one sample of
  // the budget; but not while a copy of it lives elsewhere (a chain still
  // reading it): letting go would free nothing, and the newest could not
  // be read. The one it keeps then stays, and the budget is reported as
  // try_read() reports it.
  void read_latest(std::optional<Sample<View<T>>>& latest) override {
    if (!port_.skip_to_newest()) return;
    if (port_.at_budget() && latest && latest->value.only_view()) latest.reset();
    if (auto s = try_read()) latest = std::move(s);
  }

  [[nodiscard]] std::uint64_t lost() const override { return port_.lost(); }

 private:
  Sample<View<T>> sample(const detail::Taken& taken) const noexcept {
    return {View<T>{port_.subscriber(), port_.payloads()[taken.chunk], taken},
            Clock::time_point{Clock::duration{taken.info.stamp}}};
  }
  Views<T> views(const detail::TakenSpan& taken) const noexcept {
    return Views<T>{port_.subscriber(), port_.payloads(), taken};
  }

  detail::SubscriberPort port_;
  std::shared_ptr<const void> feed_;
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

  [[nodiscard]] const std::string& name() const noexcept { return detail::name_of(*state_->topic); }
  [[nodiscard]] Qos qos() const noexcept {
    const auto topic = detail::qos_of(*state_->topic);
    return {.capacity = topic.capacity,
            .overflow = topic.overflow,
            .block_timeout = topic.block_timeout,
            .spin = state_->qos.spin,
            .max_held = topic.max_held};
  }
  [[nodiscard]] TopicQos topic_qos() const noexcept { return detail::qos_of(*state_->topic); }
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
