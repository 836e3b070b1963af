// The compiled side of a subscription's reader: its takes, holds, waits and
// reports, which the typed SubscriptionReader, View and Views of the public
// headers call. The engine itself is the Subscriber and its Cursor
// (detail/subscriber.hpp, detail/cursor.hpp), inlined here.
#include "prime/shm/subscriber_port.hpp"

#include <algorithm>

#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/subscriber.hpp"
#include "prime/shm/detail/topic.hpp"
#include "prime/topology/detail/wait.hpp"

namespace prime::shm::detail {

const std::string& name_of(const Topic& topic) noexcept { return topic.name(); }

TopicQos qos_of(const Topic& topic) noexcept { return topic.qos(); }

void hold_again(Subscriber* subscriber, std::uint32_t chunk) noexcept { subscriber->hold_again(chunk); }

void drop(Subscriber* subscriber, std::uint32_t chunk) noexcept { subscriber->drop(chunk); }

std::uint32_t views_of(const Subscriber* subscriber, std::uint32_t chunk) noexcept { return subscriber->views_of(chunk); }

void end_batch(Subscriber* subscriber, std::uint32_t index) noexcept { subscriber->end_batch(index); }

SubscriberPort::SubscriberPort(std::shared_ptr<Topic> topic, const SubscribeQos& qos,
                               std::weak_ptr<prime::detail::RuntimeState> runtime, bool observer)
    : subscriber_{Subscriber::create(std::move(topic), qos.history, observer)},
      payloads_{subscriber_->topic().places().chunks + kPayloadOffset, subscriber_->topic().places().stride},
      spin_{qos.spin},
      runtime_{std::move(runtime)} {}

SubscriberPort::~SubscriberPort() { subscriber_->abandon(); }

std::optional<Taken> SubscriberPort::try_take(bool report_damage) {
  if (subscriber_->at_budget()) {
    report_budget();
    return std::nullopt;
  }
  auto& cursor = subscriber_->cursor();
  auto taken = cursor.try_take();
  if (report_damage)
    if (auto damage = cursor.take_damage()) report(std::move(*damage));
  if (!taken) return std::nullopt;
  subscriber_->hold_taken(taken->chunk);
  budget_reported_ = false;
  return taken;
}

std::size_t SubscriberPort::room() const noexcept {
  return subscriber_->max_held() - std::min(subscriber_->held(), subscriber_->max_held());
}

std::size_t SubscriberPort::take_some(std::size_t max, std::vector<Taken>& out) {
  const auto from = out.size();
  const auto n = subscriber_->cursor().take_some(std::min(max, room()), out);
  subscriber_->hold_taken(std::span<const Taken>{out}.subspan(from));
  if (n > 0) budget_reported_ = false;
  return n;
}

std::optional<TakenSpan> SubscriberPort::take_span(std::size_t max, bool now) {
  if (now && subscriber_->at_budget()) {
    report_budget();
    return std::nullopt;
  }
  auto& cursor = subscriber_->cursor();
  const auto index = cursor.take_batch(std::min(max, room()), subscriber_->held());
  if (now)
    if (auto damage = cursor.take_damage()) report(std::move(*damage));
  if (!index) return std::nullopt;
  const auto& batch = cursor.batch(*index);
  subscriber_->hold_batch(batch.chunks.size());
  budget_reported_ = false;
  return TakenSpan{*index, batch.first, batch.chunks, batch.info};
}

std::optional<Error> SubscriberPort::why_nothing(Clock::time_point deadline, const std::stop_token& stop) {
  if (auto damage = subscriber_->cursor().take_damage()) return damage;
  const auto& name = subscriber_->topic().name();
  if (stop.stop_requested()) return Error{Errc::stopped, "source '" + name + "': stopped while waiting"};
  if (Clock::now() >= deadline) return Error{Errc::timeout, "source '" + name + "': nothing published in time"};
  return std::nullopt;
}

bool SubscriberPort::skip_to_newest() {
  auto& cursor = subscriber_->cursor();
  if (!cursor.ready()) {
    cursor.acknowledge_all();  // nothing new: the publisher may as well know it
    return false;
  }
  cursor.skip_to_newest();
  return true;
}

bool SubscriberPort::at_budget() const noexcept { return subscriber_->at_budget(); }

std::uint64_t SubscriberPort::lost() const noexcept { return subscriber_->cursor().lost(); }

void SubscriberPort::report_budget() {
  if (budget_reported_) return;
  budget_reported_ = true;
  report({Errc::held_limit, budget_message() + " (it reads on once one is released)"});
}

void SubscriberPort::report(Error error) {
  if (auto runtime = runtime_.lock()) runtime->report(std::move(error));
}

std::string SubscriberPort::budget_message() const {
  return "topic '" + subscriber_->topic().name() + "': a reader holds its max_held of " +
         std::to_string(subscriber_->max_held()) + " samples";
}

// Until a sample can be taken: first until the budget has room (a view
// released, perhaps on another thread), then until one is published —
// spinning for `spin_`, then asleep on the topic's futex. Ends early on
// `deadline` or a stop request.
std::expected<void, Error> SubscriberPort::wait(Clock::time_point deadline, const std::stop_token& stop) {
  using prime::detail::Waited;
  auto& cursor = subscriber_->cursor();
  auto& data = cursor.topic()->header().data;
  auto& released = subscriber_->released();
  // The stop flag is set before the callback rings, and a sleeper reads the
  // bell before it checks the flag: a stop is never slept through.
  std::stop_callback wake{stop, [&] {
                            data.ring_always();
                            released.ring_always();
                          }};
  auto stopped = [&] { return Error{Errc::stopped, "source '" + cursor.topic()->name() + "': stopped while waiting"}; };
  // What it has read is acknowledged before it waits: a `block` publisher
  // may be waiting for it.
  if (subscriber_->at_budget() || !cursor.ready()) cursor.acknowledge_all();
  if (subscriber_->at_budget()) {
    auto room = [&] { return !subscriber_->at_budget(); };
    auto sleep = [&](Clock::time_point until) {
      released.sleep_until(1, [&] { return room() || stop.stop_requested(); }, until);
    };
    const auto waited = prime::detail::spin_then_sleep(room, sleep, std::chrono::nanoseconds::zero(), deadline, stop);
    if (waited == Waited::stopped) return std::unexpected(stopped());
    if (waited == Waited::timeout) return std::unexpected(Error{Errc::held_limit, budget_message() + " until the deadline"});
  }
  auto sleep = [&](Clock::time_point until) { cursor.sleep_until([&] { return stop.stop_requested(); }, until); };
  const auto waited = prime::detail::spin_then_sleep([&] { return cursor.ready(); }, sleep, spin_, deadline, stop);
  if (waited == Waited::stopped) return std::unexpected(stopped());
  if (waited == Waited::timeout)
    return std::unexpected(Error{Errc::timeout, "source '" + cursor.topic()->name() + "': nothing published in time"});
  return {};
}

}  // namespace prime::shm::detail
