#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <stop_token>
#include <thread>
#include <utility>
#include <vector>

#include "prime/logic/sample.hpp"

// The paper's peer, Microsoft CCR, modelled in C++: services talk through
// ports, and a port's handler runs as a task on a dispatcher's thread pool.
//
//   post(port i) -> task in the dispatcher queue -> a pool thread runs handler i
//                -> post(port i+1) -> ...
//
// Written as CCR works, not to lose: a task carries its message by value (no
// allocation per hop, where CCR allocates a Task object), and locks are held
// only to touch the queues.
namespace prime::bench::ccr {

template <class T>
class Dispatcher;

// A queue of messages with at most one persistent receiver, like CCR's
// Port<T> under Arbiter.Receive(true, port, handler). With a receiver, a
// posted message becomes a task for the receiver's dispatcher; without one,
// it waits in the port for `receive_until`.
//
// Thread-safe.
template <class T>
class Port {
 public:
  Port() = default;
  Port(const Port&) = delete;
  Port& operator=(const Port&) = delete;

  void post(T value) {
    std::unique_lock lock{mutex_};
    if (dispatcher_) {
      Dispatcher<T>* dispatcher = dispatcher_;
      lock.unlock();
      dispatcher->enqueue(*this, std::move(value));
      return;
    }
    items_.push_back(std::move(value));
    lock.unlock();
    ready_.notify_one();
  }

  // Runs `handler` on `dispatcher` for every message posted from now on, and
  // for those already waiting.
  void receive_with(Dispatcher<T>& dispatcher, std::function<void(T)> handler) {
    std::deque<T> waiting;
    {
      std::scoped_lock lock{mutex_};
      handler_ = std::move(handler);
      dispatcher_ = &dispatcher;
      waiting.swap(items_);
    }
    for (auto& value : waiting) dispatcher.enqueue(*this, std::move(value));
  }

  // The next message, or nothing if none came before `deadline`.
  [[nodiscard]] std::optional<T> receive_until(Clock::time_point deadline) {
    std::unique_lock lock{mutex_};
    if (!ready_.wait_until(lock, deadline, [&] { return !items_.empty(); })) return std::nullopt;
    T value = std::move(items_.front());
    items_.pop_front();
    return value;
  }

 private:
  friend class Dispatcher<T>;
  void run(T value) const { handler_(std::move(value)); }  // on a dispatcher thread

  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<T> items_;
  std::function<void(T)> handler_;
  Dispatcher<T>* dispatcher_ = nullptr;
};

// CCR's Dispatcher with its DispatcherQueue: one task queue, a fixed pool of
// threads taking tasks from it. Destroying it drops the tasks not yet run and
// joins the threads, so it must go before the ports it serves.
//
// Thread-safe.
template <class T>
class Dispatcher {
 public:
  explicit Dispatcher(int threads) {
    for (int i = 0; i < threads; ++i) threads_.emplace_back([this](std::stop_token stop) { serve(stop); });
  }
  Dispatcher(const Dispatcher&) = delete;
  Dispatcher& operator=(const Dispatcher&) = delete;
  ~Dispatcher() {
    for (auto& t : threads_) t.request_stop();
    {
      std::scoped_lock lock{mutex_};  // no thread may miss the wake-up between its check and its wait
    }
    ready_.notify_all();
    threads_.clear();  // joins
  }

  void enqueue(Port<T>& port, T value) {
    {
      std::scoped_lock lock{mutex_};
      tasks_.push_back({&port, std::move(value)});
    }
    ready_.notify_one();
  }

 private:
  struct Task {
    Port<T>* port;
    T value;
  };

  void serve(const std::stop_token& stop) {
    while (true) {
      std::unique_lock lock{mutex_};
      ready_.wait(lock, [&] { return stop.stop_requested() || !tasks_.empty(); });
      if (stop.stop_requested()) return;
      Task task = std::move(tasks_.front());
      tasks_.pop_front();
      lock.unlock();
      task.port->run(std::move(task.value));
    }
  }

  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<Task> tasks_;
  std::vector<std::jthread> threads_;  // last member: the threads go first
};

}  // namespace prime::bench::ccr
