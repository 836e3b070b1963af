#pragma once

#include <functional>
#include <type_traits>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/reader.hpp"
#include "prime/shm/view.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/qos.hpp"

namespace prime::system {

namespace detail {

// A reader of From that gives each sample as convert(value): a view copied
// out of shared memory as it is read (so the chain holds no slot of the
// topic), a view or a value made shareable, as an input wants it.
template <class From, class Convert>
class ConvertingReader final : public Reader<std::invoke_result_t<Convert&, From&&>>::Impl {
 public:
  using To = std::invoke_result_t<Convert&, From&&>;
  ConvertingReader(Reader<From> from, Convert convert) : from_{std::move(from)}, convert_{std::move(convert)} {}

  std::optional<Sample<To>> try_read() override {
    auto got = from_.try_read();
    if (!got) return std::nullopt;
    return converted(std::move(*got));
  }
  std::expected<Sample<To>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    auto got = from_.read_until(deadline, std::move(stop));
    if (!got) return std::unexpected(std::move(got.error()));
    return converted(std::move(*got));
  }
  std::expected<std::size_t, Error> read_some(std::vector<Sample<To>>& out, std::size_t max, Clock::time_point deadline,
                                              std::stop_token stop) override {
    batch_.clear();
    auto n = from_.read_some(batch_, max, deadline, std::move(stop));
    if (!n) return n;
    out.reserve(out.size() + batch_.size());
    for (auto& got : batch_) out.push_back(converted(std::move(got)));
    batch_.clear();
    return n;
  }
  [[nodiscard]] std::uint64_t lost() const override { return from_.lost(); }

 private:
  Sample<To> converted(Sample<From>&& got) { return {convert_(std::move(got.value)), got.stamp}; }

  Reader<From> from_;
  Convert convert_;
  std::vector<Sample<From>> batch_;
};

template <class From, class Convert>
Reader<std::invoke_result_t<Convert&, From&&>> converting(Reader<From> from, Convert convert) {
  return Reader<std::invoke_result_t<Convert&, From&&>>{
      std::make_unique<ConvertingReader<From, Convert>>(std::move(from), std::move(convert))};
}

// A view of shared memory copied out as a value.
template <class T>
Reader<T> copied_out(Reader<shm::View<T>> views) {
  return converting(std::move(views), [](shm::View<T>&& view) { return T{*view}; });
}
// A view of shared memory shared in place: it holds its slot for as long
// as a copy of the pointer lives.
template <class T>
Reader<std::shared_ptr<const T>> shared_in_place(Reader<shm::View<T>> views) {
  return converting(std::move(views), [](shm::View<T>&& view) {
    auto held = std::make_shared<shm::View<T>>(std::move(view));
    return std::shared_ptr<const T>{held, held->get()};
  });
}
// A value of its own (received from Redis, say) made shareable.
template <class T>
Reader<std::shared_ptr<const T>> shared_values(Reader<T> values) {
  return converting(std::move(values), [](T&& value) { return std::make_shared<const T>(std::move(value)); });
}

}  // namespace detail

// A topic a component subscribes to: a source of values, to link chains to
// (`input | local.chain(f)`), sync or collect. Each reader reads where the
// placement put the publisher, in its own thread: a buffer the publisher
// fills in this process, a shared-memory topic, or a Redis stream. Copies
// are handles to the same input. T is the message (Context::input: each
// reader gets a value of its own), or std::shared_ptr<const M> (Context::
// shared_input: every reader shares one, in place in shared memory).
template <class T>
class Input {
 public:
  using value_type = T;
  using Open = std::function<Reader<T>(const Qos&)>;

  Input(std::string name, Qos qos, std::weak_ptr<prime::detail::RuntimeState> runtime, Graph graph, Open open)
      : state_{std::make_shared<const State>(State{std::move(name), qos, std::move(runtime), std::move(graph), std::move(open)})} {}

  // A new reader that sees every value published from now on.
  [[nodiscard]] Reader<T> subscribe() const { return state_->open(state_->qos); }
  [[nodiscard]] Reader<T> subscribe(const Qos& qos) const { return state_->open(qos); }

  [[nodiscard]] const std::string& name() const noexcept { return state_->name; }
  [[nodiscard]] const Qos& qos() const noexcept { return state_->qos; }
  [[nodiscard]] const Graph& graph() const noexcept { return state_->graph; }
  [[nodiscard]] const std::weak_ptr<prime::detail::RuntimeState>& runtime() const noexcept { return state_->runtime; }

 private:
  struct State {
    std::string name;
    Qos qos;
    std::weak_ptr<prime::detail::RuntimeState> runtime;
    Graph graph;
    Open open;
  };
  std::shared_ptr<const State> state_;
};

namespace detail {

// An input given its source from outside the plan (Harness::feed_from): how
// to read it, and its QoS, which the input takes on (a recording's blocks,
// so nothing downstream drops what it replays).
template <class T>
struct FedInput {
  typename Input<T>::Open open;
  Qos qos;
};

}  // namespace detail

}  // namespace prime::system
