// A recording's samples, released in stamp order on a clock of their own.
#include "prime/record/detail/timeline.hpp"

#include <algorithm>

#include "prime/record/mcap_reader.hpp"
#include "prime/record/prime_metadata.hpp"

namespace prime::record::detail {

Timeline::Timeline(std::string path)
    : path_{std::move(path)},
      reader_{std::make_unique<McapReader>(path_)},
      steady_to_unix_{steady_to_unix_ns(reader_->summary(), path_)} {}

Timeline::~Timeline() = default;

std::size_t Timeline::add(const std::string& topic, const std::string& type, std::size_t size) {
  std::scoped_lock lock{mutex_};
  if (started_) throw Failure{{Errc::invalid_argument, "replay of '" + path_ + "': topic '" + topic + "' added after it started"}};
  const auto& s = reader_->summary();
  const auto channel = std::ranges::find(s.channels, topic, [](const auto& c) { return c.second.topic; });
  if (channel == s.channels.end()) throw Failure{{Errc::not_found, "recording '" + path_ + "' has no topic '" + topic + "'"}};
  const auto recorded = recorded_type(s, channel->second);
  if (recorded != type)
    throw Failure{{Errc::type_mismatch, "recording '" + path_ + "': topic '" + topic + "' was recorded as " + recorded +
                                            ", not " + type}};
  Topic t{topic, {}, {}, {}};
  const auto id = channel->first;
  const auto codec = recorded_codec(channel->second, size, path_);
  const auto what = "recording '" + path_ + "': a sample of '" + topic + "'";
  reader_->for_each_message([&](const Message& m) {
    if (m.channel_id != id) return;
    auto bytes = codec ? codec->decode(m.data, what) : m.data;
    if (bytes.size() != size)
      throw Failure{{Errc::damaged, what + " is " + std::to_string(bytes.size()) + " bytes, not the " + std::to_string(size) + " of " + type}};
    t.samples.push_back(std::move(bytes));
    t.stamps.push_back(Clock::time_point{std::chrono::nanoseconds{static_cast<std::int64_t>(m.log_time) - steady_to_unix_}});
  });
  topics_.push_back(std::move(t));
  return topics_.size() - 1;
}

std::size_t Timeline::join(std::size_t slot) {
  std::scoped_lock lock{mutex_};
  // From the first of its samples not yet done with: all, before the start.
  std::size_t from = started_ ? topics_[slot].samples.size() : 0;
  if (started_)
    for (std::size_t e = at_; e < order_.size(); ++e)
      if (order_[e].slot == slot) {
        from = order_[e].index;
        break;
      }
  readers_.push_back({slot, from, from, true});
  topics_[slot].readers.push_back(readers_.size() - 1);
  return readers_.size() - 1;
}

void Timeline::leave(std::size_t reader) {
  std::scoped_lock lock{mutex_};
  readers_[reader].active = false;
  auto& list = topics_[readers_[reader].slot].readers;
  std::erase(list, reader);
  advance();
  moved_.notify_all();
}

void Timeline::start() {
  std::scoped_lock lock{mutex_};
  if (started_) return;
  started_ = true;
  for (std::size_t s = 0; s < topics_.size(); ++s)
    for (std::size_t i = 0; i < topics_[s].samples.size(); ++i) order_.push_back({topics_[s].stamps[i], s, i});
  // By stamp; equal stamps in the order of their topics' adding, then their own.
  std::ranges::stable_sort(order_, {}, &Entry::stamp);
  advance();
  moved_.notify_all();
}

bool Timeline::finished() {
  std::scoped_lock lock{mutex_};
  return started_ && at_ >= order_.size();
}

std::string Timeline::waiting_for() {
  std::scoped_lock lock{mutex_};
  if (!started_) return "its start";
  if (at_ >= order_.size()) return "nothing: every sample is taken";
  const auto& e = order_[at_];
  const auto& t = topics_[e.slot];
  std::string text = "sample " + std::to_string(e.index) + " of '" + t.name + "' (" + std::to_string(at_) + " of " +
                     std::to_string(order_.size()) + " in all): ";
  if (t.readers.empty()) return text + "no reader of '" + t.name + "'";
  for (const auto r : t.readers)
    text += "a reader given " + std::to_string(readers_[r].taken) + ", done with " + std::to_string(readers_[r].finished) + "; ";
  return text;
}

void Timeline::advance() {
  // Entry at_ is done when its topic has readers and each has come back
  // after taking it.
  while (at_ < order_.size()) {
    const auto& e = order_[at_];
    const auto& readers = topics_[e.slot].readers;
    if (readers.empty()) return;
    if (!std::ranges::all_of(readers, [&](std::size_t r) { return readers_[r].finished > e.index; })) return;
    ++at_;
  }
}

std::optional<Timeline::Released> Timeline::next(std::size_t reader, Clock::time_point deadline, const std::stop_token& stop) {
  // A stop wakes the wait. The callback takes the lock, so it cannot slip
  // between a look and the wait; it is made before the lock is taken and
  // ends after it is let go, as it may run (and lock) at once.
  std::stop_callback wake{stop, [this] {
                            std::scoped_lock relock{mutex_};
                            moved_.notify_all();
                          }};
  std::unique_lock lock{mutex_};
  auto& r = readers_[reader];  // a deque: joins do not move it
  if (r.finished < r.taken) {  // it is back: done with what it took
    r.finished = r.taken;
    advance();
    moved_.notify_all();
  }
  auto& topic = topics_[r.slot];
  auto released = [&] {
    return started_ && at_ < order_.size() && order_[at_].slot == r.slot && order_[at_].index == r.taken;
  };
  const auto until = std::min(deadline, Clock::now() + std::chrono::hours{24 * 365});  // a wait the clock can add
  while (!released()) {
    if (stop.stop_requested()) throw Failure{{Errc::stopped, "replay of '" + topic.name + "': stopped while waiting"}};
    if (moved_.wait_until(lock, until) == std::cv_status::timeout && !released()) return std::nullopt;
  }
  const auto i = r.taken++;
  return Released{topic.samples[i], topic.stamps[i]};
}

}  // namespace prime::record::detail
