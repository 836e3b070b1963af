#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <memory>
#include <stop_token>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/logic/reader.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/qos.hpp"

namespace prime {

// What every Core has, whatever its medium: the workers it started, in-process
// sources made from events, and the channel worker errors go to. Destroying it
// stops and joins every worker it started.
//
// Thread-safe.
class Runtime {
 public:
  explicit Runtime(std::string medium) : state_{std::make_shared<detail::RuntimeState>(std::move(medium))} {}
  Runtime(const Runtime&) = delete;
  Runtime& operator=(const Runtime&) = delete;
  ~Runtime() { state_->stop(); }

  // A source of what `event` raises from now on. The event may be destroyed
  // before or after the source.
  template <class T>
  [[nodiscard]] LocalSource<T> source(Event<T>& event, std::string name = "source", Qos qos = {}) {
    LocalSource<T> source{name, qos, state_, Graph::node(name, "source", state_->medium())};
    source.feed_from(event);
    return source;
  }

  // Every error a worker of this core reports: a user block that threw, a
  // reader that made no room in time. An error no reader of an errors source
  // takes (none made, or none subscribed) goes to stderr.
  [[nodiscard]] LocalSource<Error> errors(Qos qos = {.capacity = 256}) {
    LocalSource<Error> source{"errors", qos, state_, Graph::node("errors", "source", state_->medium())};
    source.feed_from_reports(*state_);
    return source;
  }

  // Stops and joins every worker now; linking afterwards throws.
  void stop() { state_->stop(); }

  [[nodiscard]] std::string_view medium() const noexcept { return state_->medium(); }
  [[nodiscard]] std::weak_ptr<detail::RuntimeState> runtime() const noexcept { return state_; }

 private:
  std::shared_ptr<detail::RuntimeState> state_;
};

namespace detail {

// Runs `on_sample(sample, stop)` for every value `reader` gets, in a worker of
// `runtime`, until that runtime stops. What `on_sample` throws is reported
// under `what`, and the worker goes on with the next value; so is what
// taking a value throws (its copy for this reader), which loses that value.
template <class T, class F>
void spawn_reader(const std::weak_ptr<RuntimeState>& runtime, Reader<T> reader, std::string what,
                  F on_sample) {
  auto owner = runtime.lock();
  if (!owner) throw Failure{{Errc::stopped, what + ": the core that owns the source is gone"}};
  owner->spawn([runtime, reader = std::move(reader), what = std::move(what),
                on_sample = std::move(on_sample)](std::stop_token stop) mutable {
    constexpr std::size_t kBatch = 64;  // values taken per wake-up when the source is busy
    std::vector<Sample<T>> batch;
    batch.reserve(kBatch);
    auto report = [&](const std::string& why) {
      if (auto r = runtime.lock()) r->report({Errc::block_failed, what + ": " + why});
    };
    // A read that fails for another reason than the stop (damaged shared
    // memory, say) is reported, once while it repeats, and read again after
    // a pause that grows to 100 ms: a damaged source neither ends the chain
    // nor spins a core.
    std::string last_failure;
    auto pause = std::chrono::milliseconds{1};
    while (true) {
      batch.clear();
      try {
        auto read = reader.read_some(batch, kBatch, Clock::time_point::max(), stop);
        if (!read) {
          if (stop.stop_requested() || read.error().code == Errc::stopped) return;
          if (read.error().message != last_failure) {
            last_failure = read.error().message;
            if (auto r = runtime.lock()) r->report(read.error());
          }
          std::mutex m;
          std::condition_variable_any cv;
          std::unique_lock lock{m};
          cv.wait_for(lock, stop, pause, [] { return false; });
          pause = std::min(pause * 2, std::chrono::milliseconds{100});
          continue;
        }
        last_failure.clear();
        pause = std::chrono::milliseconds{1};
      } catch (const std::exception& e) {
        report(std::string{"a value could not be taken (lost to this reader): "} + e.what());
      } catch (...) {
        report("a value could not be taken (lost to this reader): an exception of unknown type");
      }
      for (auto& sample : batch) {
        if (stop.stop_requested()) return;
        try {
          on_sample(std::move(sample), stop);
        } catch (const std::exception& e) {
          if (stop.stop_requested()) return;  // a wait in the chain ended by the stop: no error
          report(e.what());
        } catch (...) {
          if (stop.stop_requested()) return;
          report("an exception of unknown type");
        }
      }
    }
  });
}

}  // namespace detail

}  // namespace prime
