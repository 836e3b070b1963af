#pragma once

#include <atomic>
#include <concepts>
#include <memory>
#include <mutex>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/logic/reader.hpp"
#include "prime/topology/detail/queue.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/qos.hpp"

namespace prime {

namespace detail {

// Fans each published value out to every reader's own bounded queue. One
// reader gets the value moved; several share it (SharedSample): the last
// reader to take it gets it moved and the others copy it when they read it,
// so the publisher never copies, n readers make n - 1 copies, and a large
// value is not copied for readers that drop it.
//
// Thread-safe: publish, attach and detach may run concurrently.
template <class T>
class Hub {
 public:
  Hub(std::string name, Qos qos, std::weak_ptr<RuntimeState> runtime)
      : name_{std::move(name)}, qos_{qos}, runtime_{std::move(runtime)} {
    validate(qos_, name_);
  }

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] const Qos& qos() const noexcept { return qos_; }
  [[nodiscard]] const std::weak_ptr<RuntimeState>& runtime() const noexcept { return runtime_; }

  // Returns how many readers it went to.
  std::size_t publish(Sample<T>&& sample, std::stop_token stop) {
    auto readers = snapshot();
    const auto n = readers->size();
    if (n == 0) return 0;
    if constexpr (std::copy_constructible<T>) {
      if (n > 1) {
        auto last = SharedSample<T>::share(std::move(sample), n);
        for (std::size_t i = 0; i + 1 < n; ++i) deliver(*(*readers)[i], last.claim(), stop);
        deliver(*readers->back(), std::move(last), stop);
        return n;
      }
    }
    deliver(*readers->back(), std::move(sample), stop);
    return n;
  }

  // A look without the lock: a reader attaching now may or may not count.
  [[nodiscard]] std::size_t readers() const noexcept { return count_.load(std::memory_order_relaxed); }

  [[nodiscard]] std::shared_ptr<Queue<T>> attach(const Qos& qos) {
    validate(qos, name_);
    auto queue = std::make_shared<Queue<T>>(qos);
    std::scoped_lock lock{mutex_};
    if (!std::copy_constructible<T> && !readers_->empty())
      throw Failure{{Errc::invalid_argument, "source '" + name_ + "' carries a move-only type: it can have one reader only"}};
    auto next = std::make_shared<List>(*readers_);
    next->push_back(queue);
    readers_ = std::move(next);
    count_.store(readers_->size(), std::memory_order_relaxed);
    return queue;
  }

  void detach(const Queue<T>* queue) {
    std::scoped_lock lock{mutex_};
    auto next = std::make_shared<List>(*readers_);
    std::erase_if(*next, [queue](const auto& q) { return q.get() == queue; });
    readers_ = std::move(next);
    count_.store(readers_->size(), std::memory_order_relaxed);
  }

  // Keeps `upstream` connected for as long as this hub lives, beside any other.
  void feed_from(Connection upstream) {
    std::scoped_lock lock{mutex_};
    upstreams_.push_back(std::move(upstream));
  }

 private:
  using List = std::vector<std::shared_ptr<Queue<T>>>;

  std::shared_ptr<const List> snapshot() {
    std::scoped_lock lock{mutex_};
    return readers_;
  }

  void deliver(Queue<T>& queue, typename Queue<T>::Entry&& entry, std::stop_token stop) {
    if (queue.push(std::move(entry), std::move(stop)) != Queue<T>::Pushed::timed_out) return;
    if (auto runtime = runtime_.lock())
      runtime->report({Errc::overflow, "source '" + name_ + "': a reader made no room within " +
                                           std::to_string(qos_.block_timeout.count()) +
                                           " ms (block policy); the value was dropped for that reader"});
  }

  const std::string name_;
  const Qos qos_;
  const std::weak_ptr<RuntimeState> runtime_;
  std::mutex mutex_;
  std::shared_ptr<const List> readers_ = std::make_shared<const List>();
  std::atomic<std::size_t> count_ = 0;  // readers_->size(), for a look without the lock
  std::vector<Connection> upstreams_;  // last member: disconnects before the rest goes
};

template <class T>
class QueueReader final : public Reader<T>::Impl {
 public:
  QueueReader(std::shared_ptr<Hub<T>> hub, const Qos& qos) : hub_{std::move(hub)}, queue_{hub_->attach(qos)} {}
  ~QueueReader() override {
    queue_->close();
    hub_->detach(queue_.get());
  }
  QueueReader(const QueueReader&) = delete;
  QueueReader& operator=(const QueueReader&) = delete;

  std::optional<Sample<T>> try_read() override { return queue_->try_pop(); }

  std::expected<Sample<T>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    auto got = queue_->pop_until(deadline, std::move(stop));
    if (!got) return std::unexpected(failure(got.error()));
    return std::move(*got);
  }

  std::expected<std::size_t, Error> read_some(std::vector<Sample<T>>& out, std::size_t max,
                                              Clock::time_point deadline, std::stop_token stop) override {
    auto got = queue_->pop_some(out, max, deadline, std::move(stop));
    if (!got) return std::unexpected(failure(got.error()));
    return *got;
  }

  [[nodiscard]] std::uint64_t lost() const override { return queue_->lost(); }

 private:
  Error failure(Errc code) const {
    return {code, "source '" + hub_->name() + "': " +
                      (code == Errc::stopped ? "the reader was stopped" : "no value before the deadline")};
  }

  std::shared_ptr<Hub<T>> hub_;  // a reader keeps its source alive
  std::shared_ptr<Queue<T>> queue_;
};

}  // namespace detail

// An in-process source: a bounded buffer per reader, filled by an Event, by a
// worker running a linked chain, or by `publish`. Copies are handles to the
// same source. It is the medium-independent way values move between threads
// in one process, so every medium's linked sources end in one.
//
// Thread-safe.
template <class T>
class LocalSource {
 public:
  using value_type = T;

  LocalSource(std::string name, Qos qos, std::weak_ptr<detail::RuntimeState> runtime, Graph graph)
      : hub_{std::make_shared<detail::Hub<T>>(std::move(name), qos, std::move(runtime))},
        graph_{std::make_shared<const Graph>(std::move(graph))} {}

  // A new reader that sees every value published from now on.
  [[nodiscard]] Reader<T> subscribe() const { return subscribe(hub_->qos()); }
  [[nodiscard]] Reader<T> subscribe(const Qos& qos) const {
    return Reader<T>{std::make_unique<detail::QueueReader<T>>(hub_, qos)};
  }

  // Hands a value to every reader, as the source's producer would. `stop`
  // ends a wait for room under the block policy.
  void publish(T value, Clock::time_point stamp = Clock::now(), std::stop_token stop = {}) const {
    hub_->publish(Sample<T>{std::move(value), stamp}, std::move(stop));
  }

  // Feeds this source from an event (as well as from what feeds it already)
  // until the source is gone.
  void feed_from(Event<T>& event) const {
    hub_->feed_from(event.connect([weak = std::weak_ptr<detail::Hub<T>>{hub_}](Sample<T>&& s) {
      if (auto hub = weak.lock()) hub->publish(std::move(s), {});
    }));
  }

  // Feeds this source from the errors its core's workers report, telling
  // the core how many readers each one reached (with none, it goes to stderr).
  void feed_from_reports(detail::RuntimeState& runtime) const
    requires std::same_as<T, Error>
  {
    hub_->feed_from(runtime.errors().connect([weak = std::weak_ptr<detail::Hub<T>>{hub_}](Sample<T>&& s) {
      if (auto hub = weak.lock()) detail::RuntimeState::delivered(hub->publish(std::move(s), {}));
    }));
  }

  // How many readers it has now: whether a value would go anywhere.
  [[nodiscard]] std::size_t readers() const { return hub_->readers(); }

  [[nodiscard]] const std::string& name() const noexcept { return hub_->name(); }
  [[nodiscard]] const Qos& qos() const noexcept { return hub_->qos(); }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const std::weak_ptr<detail::RuntimeState>& runtime() const noexcept { return hub_->runtime(); }

 private:
  std::shared_ptr<detail::Hub<T>> hub_;
  std::shared_ptr<const Graph> graph_;
};

}  // namespace prime
