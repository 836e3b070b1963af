#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <expected>
#include <memory>
#include <mutex>
#include <optional>
#include <ostream>
#include <span>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/ring.hpp"
#include "prime/shm/publisher.hpp"
#include "prime/shm/qos.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/graph.hpp"

namespace prime::shm {

namespace detail {

// One reader's state in this process: its cursor and how many views of each
// chunk are out. A chunk's hold in shared memory (the subscriber's bit) goes
// when its last view does. Views own this jointly with the reader.
class Subscriber {
 public:
  Subscriber(std::shared_ptr<Topic> topic, std::size_t history)
      : cursor_{std::move(topic), history},
        views_{std::make_unique<std::atomic<std::uint32_t>[]>(cursor_.topic()->header().chunk_count)} {}

  [[nodiscard]] Cursor& cursor() noexcept { return cursor_; }
  [[nodiscard]] const Topic& topic() const noexcept { return *cursor_.topic(); }
  void hold(std::uint32_t chunk) noexcept { views_[chunk].fetch_add(1, std::memory_order_relaxed); }
  void drop(std::uint32_t chunk) noexcept {
    if (views_[chunk].fetch_sub(1, std::memory_order_acq_rel) == 1) cursor_.release(chunk);
  }

 private:
  Cursor cursor_;
  std::unique_ptr<std::atomic<std::uint32_t>[]> views_;
};

}  // namespace detail

// A sample read in place in the topic's shared memory: no copy is made, and
// the publisher does not reuse its slot while any view of it lives. Copies
// share the slot. Converts to `const T&`, so a chain taking T (or const T&)
// links after a subscription.
//
// Thread-safe: views of one sample may live and die on any threads.
template <Message T>
class View {
 public:
  View(const View& other) noexcept : owner_{other.owner_}, chunk_{other.chunk_}, seq_{other.seq_} {
    if (owner_) owner_->hold(chunk_);
  }
  View(View&& other) noexcept
      : owner_{std::move(other.owner_)}, chunk_{other.chunk_}, seq_{other.seq_} {}
  View& operator=(View other) noexcept {
    std::swap(owner_, other.owner_);
    std::swap(chunk_, other.chunk_);
    std::swap(seq_, other.seq_);
    return *this;
  }
  ~View() {
    if (owner_) owner_->drop(chunk_);
  }

  [[nodiscard]] const T& operator*() const noexcept requires(!std::is_same_v<T, Bytes>) { return *get(); }
  [[nodiscard]] const T* operator->() const noexcept requires(!std::is_same_v<T, Bytes>) { return get(); }
  [[nodiscard]] const T* get() const noexcept requires(!std::is_same_v<T, Bytes>) {
    return std::launder(reinterpret_cast<const T*>(owner_->topic().payload(chunk_)));
  }
  operator const T&() const noexcept requires(!std::is_same_v<T, Bytes>) { return *get(); }  // NOLINT

  // The bytes of a raw byte topic's message.
  [[nodiscard]] std::span<const std::byte> bytes() const noexcept {
    return {owner_->topic().payload(chunk_), static_cast<std::size_t>(owner_->topic().chunk(chunk_).size)};
  }
  // Its place in the topic: 0 for the first sample ever published.
  [[nodiscard]] std::uint64_t sequence() const noexcept { return seq_; }

  friend bool operator==(const View& a, const T& b) requires(!std::is_same_v<T, Bytes>) && std::equality_comparable<T>
  {
    return *a == b;
  }
  friend std::ostream& operator<<(std::ostream& out, const View& v) requires requires(std::ostream& o, const T& t) { o << t; }
  {
    return out << *v;
  }

 private:
  template <Message>
  friend class SubscriptionReader;
  View(std::shared_ptr<detail::Subscriber> owner, std::uint32_t chunk, std::uint64_t seq)
      : owner_{std::move(owner)}, chunk_{chunk}, seq_{seq} {
    owner_->hold(chunk_);
  }

  std::shared_ptr<detail::Subscriber> owner_;
  std::uint32_t chunk_;
  std::uint64_t seq_;
};

// One subscriber of a topic, with its own cursor: the Reader a subscription gives.
template <Message T>
class SubscriptionReader final : public Reader<View<T>>::Impl {
 public:
  SubscriptionReader(std::shared_ptr<detail::Topic> topic, SubscribeQos qos)
      : subscriber_{std::make_shared<detail::Subscriber>(std::move(topic), qos.history)}, spin_{qos.spin} {}

  std::optional<Sample<View<T>>> try_read() override {
    auto taken = subscriber_->cursor().try_take();
    if (!taken) return std::nullopt;
    return sample(*taken);
  }

  std::expected<Sample<View<T>>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    while (true) {  // a sample overwritten between the wait and the take sends it back to waiting
      if (auto ready = wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
      if (auto sample = try_read()) return std::move(*sample);
    }
  }

  std::expected<std::size_t, Error> read_some(std::vector<Sample<View<T>>>& out, std::size_t max,
                                              Clock::time_point deadline, std::stop_token stop) override {
    if (auto ready = wait(deadline, stop); !ready) return std::unexpected(std::move(ready.error()));
    // Each view holds its slot: a batch is at most what a subscriber may hold.
    const auto most = std::min<std::size_t>(max, subscriber_->topic().header().max_held);
    std::size_t n = 0;
    for (; n < std::max<std::size_t>(most, 1); ++n) {
      auto taken = subscriber_->cursor().try_take();
      if (!taken) break;
      out.push_back(sample(*taken));
    }
    return n;
  }

  [[nodiscard]] std::uint64_t lost() const override { return subscriber_->cursor().lost(); }

 private:
  Sample<View<T>> sample(const detail::Taken& taken) {
    const auto stamp = Clock::time_point{Clock::duration{subscriber_->topic().chunk(taken.chunk).stamp}};
    return {View<T>{subscriber_, taken.chunk, taken.seq}, stamp};
  }

  // Until something is unread: spinning for `spin_`, then asleep on the
  // topic's futex. Ends early on `deadline` or a stop request.
  std::expected<void, Error> wait(Clock::time_point deadline, const std::stop_token& stop) {
    auto& cursor = subscriber_->cursor();
    if (cursor.ready()) return {};
    const auto spin_until = std::min(deadline, Clock::now() + spin_);
    while (Clock::now() < spin_until) {
      for (int i = 0; i < 64; ++i)  // a clock read costs more than a look at the ring
        if (cursor.ready()) return {};
    }
    auto ready = [&] { return cursor.available(); };
    auto& bell = cursor.topic()->header().data;
    std::stop_callback wake{stop, [&bell] {
                              bell.word.fetch_add(1);
                              detail::futex_wake_all(bell.word);
                            }};
    // The stop flag is set before the callback rings, and a sleeper reads the
    // bell before it checks the flag: a stop is never slept through.
    auto ready_or_stopped = [&] { return ready() || stop.stop_requested(); };
    while (true) {
      if (stop.stop_requested())
        return std::unexpected(Error{Errc::stopped, "source '" + cursor.topic()->name() + "': stopped while waiting"});
      if (bell.sleep_until(ready_or_stopped, deadline) && !stop.stop_requested()) return {};
      if (Clock::now() >= deadline)
        return std::unexpected(Error{Errc::timeout, "source '" + cursor.topic()->name() + "': nothing published in time"});
    }
  }

  std::shared_ptr<detail::Subscriber> subscriber_;
  std::chrono::microseconds spin_;
};

// A topic seen as a source of the topology: `subscription | chain`,
// `collector` and `sync` take it like any other source. Each subscribe()
// is a new subscriber with its own cursor. Copies share what they hold.
template <Message T>
class Subscription {
 public:
  using value_type = View<T>;

  Subscription(std::shared_ptr<detail::Topic> topic, SubscribeQos qos, std::weak_ptr<prime::detail::RuntimeState> runtime,
               Graph graph)
      : state_{std::make_shared<const State>(State{std::move(topic), qos, std::move(runtime), std::move(graph)})} {}

  [[nodiscard]] Reader<View<T>> subscribe() const {
    return Reader<View<T>>{std::make_unique<SubscriptionReader<T>>(state_->topic, state_->qos)};
  }

  [[nodiscard]] const std::string& name() const noexcept { return state_->topic->name(); }
  [[nodiscard]] Qos qos() const noexcept {
    const auto topic = state_->topic->qos();
    return {.capacity = topic.capacity, .overflow = topic.overflow, .block_timeout = topic.block_timeout, .spin = state_->qos.spin};
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
  };
  std::shared_ptr<const State> state_;
};

static_assert(Source<Subscription<int>>);

}  // namespace prime::shm
