#pragma once

#include <functional>
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

// A reader of a shared-memory topic that gives each sample as a value: the
// view is copied out and released as it is read, so a component's chain
// holds no slot of the topic, whatever it keeps.
template <class T>
class CopyingReader final : public Reader<T>::Impl {
 public:
  explicit CopyingReader(Reader<shm::View<T>> views) : views_{std::move(views)} {}

  std::optional<Sample<T>> try_read() override {
    auto view = views_.try_read();
    if (!view) return std::nullopt;
    return copy(*view);
  }
  std::expected<Sample<T>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    auto view = views_.read_until(deadline, std::move(stop));
    if (!view) return std::unexpected(std::move(view.error()));
    return copy(*view);
  }
  std::expected<std::size_t, Error> read_some(std::vector<Sample<T>>& out, std::size_t max, Clock::time_point deadline,
                                              std::stop_token stop) override {
    batch_.clear();
    auto n = views_.read_some(batch_, max, deadline, std::move(stop));
    if (!n) return n;
    out.reserve(out.size() + batch_.size());
    for (const auto& view : batch_) out.push_back(copy(view));
    batch_.clear();  // releases the views
    return n;
  }
  [[nodiscard]] std::uint64_t lost() const override { return views_.lost(); }

 private:
  static Sample<T> copy(const Sample<shm::View<T>>& view) { return {*view.value, view.stamp}; }

  Reader<shm::View<T>> views_;
  std::vector<Sample<shm::View<T>>> batch_;
};

}  // namespace detail

// A topic a component subscribes to: a source of values, to link chains to
// (`input | local.chain(f)`), sync or collect. Each reader reads where the
// placement put the publisher, in its own thread: a buffer the publisher
// fills in this process, a shared-memory topic (each sample copied out as
// it is read), or a Redis stream. Copies are handles to the same input.
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

}  // namespace prime::system
