#pragma once

#include <functional>
#include <iostream>
#include <mutex>
#include <stop_token>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/topology/detail/quiet_threads.hpp"

namespace prime::detail {

// What a Core shares with the sources and workers it made: the worker
// threads, and the channel their errors go to. Sources hold it weakly, so a
// destroyed Core is noticed instead of kept alive.
//
// Thread-safe.
class RuntimeState {
 public:
  explicit RuntimeState(std::string medium) : medium_{std::move(medium)} {}
  RuntimeState(const RuntimeState&) = delete;
  RuntimeState& operator=(const RuntimeState&) = delete;
  ~RuntimeState() { stop(); }

  [[nodiscard]] const std::string& medium() const noexcept { return medium_; }

  void spawn(std::move_only_function<void(std::stop_token)> work) {
    std::scoped_lock lock{mutex_};
    if (stopping_) throw Failure{{Errc::stopped, medium_ + " core is shutting down: no new worker"}};
    with_signals_blocked([&] {
      workers_.emplace_back([work = std::move(work)](std::stop_token stop) mutable {
        become_worker(stop);
        work(std::move(stop));
      });
    });
  }

  // On a worker's thread, its stop token; elsewhere one that never stops. A
  // chain a worker runs waits with it (a fork's publish, a repeat's read),
  // so stopping the core ends those waits too.
  [[nodiscard]] static std::stop_token worker_stop() noexcept { return worker_stop_; }
  // Makes this thread a worker that `stop` stops (spawn's are; a medium's
  // own threads that run chains say so here).
  static void become_worker(std::stop_token stop) noexcept { worker_stop_ = std::move(stop); }

  // Goes to every reader of the core's error sources; with none, to stderr,
  // so an error is never lost in silence. An error about handing an error on
  // (an error source of the block policy whose reader made no room) goes to
  // stderr too: handed on, it would wait for that same reader again, and
  // report again, without end.
  void report(Error error) {
    thread_local bool reporting = false;
    if (reporting || errors_.listener_count() == 0) return print(error);
    reporting = true;
    struct Done {
      ~Done() { reporting = false; }
    } const done;
    delivered_ = 0;
    errors_.emit(error);
    if (delivered_ == 0) print(error);  // error sources, but no reader of any
  }

  [[nodiscard]] Event<Error>& errors() noexcept { return errors_; }
  // An error source took the error being reported to this many readers
  // (called on the reporting thread, from within report's emit).
  static void delivered(std::size_t readers) noexcept { delivered_ += readers; }

  // Stops every worker and joins it. Idempotent; must not be called from a worker.
  void stop() {
    std::vector<std::jthread> workers;
    {
      std::scoped_lock lock{mutex_};
      stopping_ = true;
      workers.swap(workers_);
    }
    for (auto& w : workers) w.request_stop();
    workers.clear();  // joins
  }

 private:
  void print(const Error& error) const { std::cerr << "prime [" << medium_ << "] " << error.describe() << '\n'; }

  static inline thread_local std::size_t delivered_ = 0;  // by the report under way on this thread
  static inline thread_local std::stop_token worker_stop_;
  const std::string medium_;
  std::mutex mutex_;
  bool stopping_ = false;
  std::vector<std::jthread> workers_;
  Event<Error> errors_;
};

}  // namespace prime::detail
