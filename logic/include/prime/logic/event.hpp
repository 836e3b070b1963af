#pragma once

#include <concepts>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <utility>
#include <vector>

#include "prime/logic/sample.hpp"

namespace prime {

// Ends a subscription when destroyed. Move-only; safe to outlive what it
// connects to (disconnecting from something already gone does nothing).
class Connection {
 public:
  Connection() = default;
  explicit Connection(std::function<void()> disconnect) : disconnect_{std::move(disconnect)} {}
  Connection(Connection&& other) noexcept : disconnect_{std::exchange(other.disconnect_, {})} {}
  Connection& operator=(Connection&& other) noexcept {
    if (this != &other) {
      disconnect();
      disconnect_ = std::exchange(other.disconnect_, {});
    }
    return *this;
  }
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  ~Connection() { disconnect(); }

  void disconnect() {
    if (auto fn = std::exchange(disconnect_, {})) fn();
  }

 private:
  std::function<void()> disconnect_;
};

// What a driver raises: `lidar.emit(scan)`. An Event buffers nothing itself;
// each medium that makes a source of it connects a listener that does.
//
// Thread-safe: emit, connect and disconnect may run concurrently from any
// threads. A listener disconnected while an emit is under way may still see
// that one value.
template <class T>
class Event {
 public:
  using Listener = std::function<void(Sample<T>&&)>;

  Event() : state_{std::make_shared<State>()} {}
  Event(Event&&) noexcept = default;
  Event& operator=(Event&&) noexcept = default;
  Event(const Event&) = delete;
  Event& operator=(const Event&) = delete;

  void emit(T value) { emit(std::move(value), Clock::now()); }

  // For drivers that know when the sensor took the value (a hardware stamp).
  void emit(T value, Clock::time_point stamp) {
    if (!state_) return;  // moved-from
    auto listeners = state_->snapshot();
    const auto n = listeners->size();
    for (std::size_t i = 0; i + 1 < n; ++i) {
      if constexpr (std::copy_constructible<T>) (*(*listeners)[i].fn)(Sample<T>{value, stamp});
    }
    if (n > 0) (*listeners->back().fn)(Sample<T>{std::move(value), stamp});
  }

  // A move-only T can have one listener only: each further one would need a copy.
  [[nodiscard]] Connection connect(Listener listener) {
    const auto id = state_->add(std::move(listener));
    return Connection{[weak = std::weak_ptr<State>{state_}, id] {
      if (auto state = weak.lock()) state->remove(id);
    }};
  }

  [[nodiscard]] std::size_t listener_count() const { return state_ ? state_->snapshot()->size() : 0; }

 private:
  struct Entry {
    std::uint64_t id;
    std::shared_ptr<Listener> fn;
  };
  using List = std::vector<Entry>;

  // Copy-on-write list: emitters take a snapshot and never hold the lock while
  // calling out, so a slow listener cannot stall connect or disconnect.
  struct State {
    std::mutex mutex;
    std::shared_ptr<const List> list = std::make_shared<const List>();
    std::uint64_t next_id = 0;

    std::shared_ptr<const List> snapshot() {
      std::scoped_lock lock{mutex};
      return list;
    }
    std::uint64_t add(Listener fn) {
      std::scoped_lock lock{mutex};
      if (!std::copy_constructible<T> && !list->empty())
        throw std::logic_error{"prime::Event: a move-only type can have one listener only"};
      auto next = std::make_shared<List>(*list);
      next->push_back({next_id, std::make_shared<Listener>(std::move(fn))});
      list = std::move(next);
      return next_id++;
    }
    void remove(std::uint64_t id) {
      std::scoped_lock lock{mutex};
      auto next = std::make_shared<List>(*list);
      std::erase_if(*next, [id](const Entry& e) { return e.id == id; });
      list = std::move(next);
    }
  };

  std::shared_ptr<State> state_;
};

}  // namespace prime
