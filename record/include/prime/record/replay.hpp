#pragma once

#include <chrono>
#include <cstring>
#include <expected>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/sample.hpp"
#include "prime/record/detail/timeline.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/qos.hpp"

namespace prime::record {

template <class T>
class ReplaySource;

// A recording played into this process's chains on a clock of its own
// (virtual time): its samples are released in the order of their stamps,
// each once every reader of its topic has come back for the next after the
// one before it. Sources made from it are taken by chains, `sync` and
// collectors like any other; a chain on them sees the recorded
// interleaving, the same on every run, with no timing in it. Each sample
// carries its recorded stamp (steady_clock, as it was published).
//
//   record::Replay replay{core, "drive.mcap"};
//   auto lidar = replay.source<Scan>("sensors/lidar");
//   auto odom = replay.source<Odometry>("sensors/odom");
//   auto plans = sync(approximate_time(), lidar, odom) | plan;   // link first
//   replay.start();                                                // then play
//
// A sample waits for at least one reader of its topic: every source made
// must be read. Copies share the recording. Thread-safe.
class Replay {
 public:
  template <class Core>
  Replay(Core& core, std::string file)
      : timeline_{std::make_shared<detail::Timeline>(std::move(file))}, runtime_{core.runtime()} {}

  // Topic `topic` of the recording as a source of T, before start().
  // Throws Failure: Errc::not_found (no such topic), type_mismatch (it was
  // recorded as another type), invalid_argument (after start()).
  template <class T>
  [[nodiscard]] ReplaySource<T> source(const std::string& topic) const {
    static_assert(std::is_trivially_copyable_v<T>, "prime::record: a recorded sample is the bytes of a trivially copyable type");
    const auto slot = timeline_->add(topic, Fingerprint::of<T>().describe(), sizeof(T));
    return ReplaySource<T>{timeline_, slot, topic, runtime_};
  }

  // Plays: from now on samples are released.
  void start() const { timeline_->start(); }
  // Whether every sample has been released and taken, and its readers
  // have come back for more (so whatever they did with it is done).
  [[nodiscard]] bool finished() const { return timeline_->finished(); }
  // What it waits for now, in words (a source made and never read, say).
  [[nodiscard]] std::string waiting_for() const { return timeline_->waiting_for(); }

 private:
  std::shared_ptr<detail::Timeline> timeline_;
  std::weak_ptr<prime::detail::RuntimeState> runtime_;
};

namespace detail {

template <class T>
class ReplayReader final : public Reader<T>::Impl {
 public:
  ReplayReader(std::shared_ptr<Timeline> timeline, std::size_t slot)
      : timeline_{std::move(timeline)}, me_{timeline_->join(slot)} {}
  ~ReplayReader() override { timeline_->leave(me_); }

  std::optional<Sample<T>> try_read() override { return take(Clock::now(), {}); }
  std::expected<Sample<T>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
    try {
      if (auto s = take(deadline, stop)) return std::move(*s);
    } catch (const Failure& f) {
      return std::unexpected(f.error());
    }
    return std::unexpected(Error{Errc::timeout, "replay of '" + timeline_->path() + "': nothing released in time"});
  }
  // One sample a read, though more are asked for: the reader comes back
  // between samples, so the next of any topic is released only once it is
  // done with this one.
  std::expected<std::size_t, Error> read_some(std::vector<Sample<T>>& out, std::size_t max, Clock::time_point deadline,
                                              std::stop_token stop) override {
    if (max == 0) return 0;
    auto one = read_until(deadline, std::move(stop));
    if (!one) return std::unexpected(std::move(one.error()));
    out.push_back(std::move(*one));
    return 1;
  }
  void read_latest(std::optional<Sample<T>>& latest) override {
    if (auto s = try_read()) latest = std::move(s);
  }
  [[nodiscard]] std::uint64_t lost() const override { return 0; }  // a replay waits for its readers: none is lost

 private:
  std::optional<Sample<T>> take(Clock::time_point deadline, const std::stop_token& stop) {
    const auto released = timeline_->next(me_, deadline, stop);
    if (!released) return std::nullopt;
    T value;
    std::memcpy(static_cast<void*>(&value), released->bytes.data(), sizeof(T));
    return Sample<T>{value, released->stamp};
  }
  std::shared_ptr<Timeline> timeline_;
  std::size_t me_;
};

}  // namespace detail

// One topic of a recording as a Source of T (Replay::source).
template <class T>
class ReplaySource {
 public:
  using value_type = T;

  [[nodiscard]] Reader<T> subscribe() const {
    return Reader<T>{std::make_unique<detail::ReplayReader<T>>(timeline_, slot_)};
  }
  [[nodiscard]] const std::string& name() const noexcept { return *name_; }
  // A replay waits for its readers: nothing is dropped, and no value pins memory.
  [[nodiscard]] Qos qos() const noexcept { return {.capacity = 64, .overflow = Overflow::block}; }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] std::weak_ptr<prime::detail::RuntimeState> runtime() const noexcept { return runtime_; }

 private:
  friend class Replay;
  ReplaySource(std::shared_ptr<detail::Timeline> timeline, std::size_t slot, const std::string& topic,
               std::weak_ptr<prime::detail::RuntimeState> runtime)
      : timeline_{std::move(timeline)},
        slot_{slot},
        name_{std::make_shared<const std::string>(topic)},
        graph_{std::make_shared<const Graph>(Graph::node(topic, "source", "replay"))},
        runtime_{std::move(runtime)} {}

  std::shared_ptr<detail::Timeline> timeline_;
  std::size_t slot_;
  std::shared_ptr<const std::string> name_;
  std::shared_ptr<const Graph> graph_;
  std::weak_ptr<prime::detail::RuntimeState> runtime_;
};

// One topic of a recording, played at once: `replay(core, "drive.mcap",
// "sensors/lidar")` is a Source of T. As with a live source, a chain
// linked to it gives its outputs to the readers it has by then: to see
// every output of a chain on a recording, use a Replay and start() it
// once the chain's readers are subscribed.
template <class T, class Core>
[[nodiscard]] ReplaySource<T> replay(Core& core, const std::string& file, const std::string& topic) {
  const Replay recording{core, file};
  auto source = recording.template source<T>(topic);
  recording.start();
  return source;
}

}  // namespace prime::record
