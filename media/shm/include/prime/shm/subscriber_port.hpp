#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <memory>
#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/payloads.hpp"
#include "prime/shm/qos.hpp"
#include "prime/topology/detail/runtime_state.hpp"

namespace prime::shm::detail {

class Topic;       // a topic's segment, mapped (compiled in libprime_shm)
class Subscriber;  // one reader's holds and cursor (compiled in libprime_shm)

// A sample's size and stamp, as read when it was taken.
struct TakenInfo {
  std::uint64_t size;
  std::int64_t stamp;
};

// A sample taken by a subscriber: its chunk, held by the subscriber's bit
// until released.
struct Taken {
  std::uint32_t chunk;
  std::uint64_t seq;
  TakenInfo info;
};

// Samples taken together for a batch of views: consecutive sequences from
// `first`, each chunks[i] described by info[i]; batch `index` of its
// subscriber, unchanged while it is out.
struct TakenSpan {
  std::uint32_t index;
  std::uint64_t first;
  std::span<const std::uint32_t> chunks;
  std::span<const TakenInfo> info;
};

// What a subscription shows of its topic (compiled in libprime_shm).
[[nodiscard]] const std::string& name_of(const Topic& topic) noexcept;
[[nodiscard]] TopicQos qos_of(const Topic& topic) noexcept;

// What views do to the samples they hold, on any thread (compiled in
// libprime_shm): a copy of a view holds its chunk again; a view, or a
// batch, let go of.
void hold_again(Subscriber* subscriber, std::uint32_t chunk) noexcept;
void drop(Subscriber* subscriber, std::uint32_t chunk) noexcept;
[[nodiscard]] std::uint32_t views_of(const Subscriber* subscriber, std::uint32_t chunk) noexcept;
void end_batch(Subscriber* subscriber, std::uint32_t index) noexcept;

// The non-template side of a subscription's reader, compiled in
// libprime_shm: its subscriber (cursor, slot, holds), its waits and the
// errors it reports. It holds at most the topic's max_held samples at
// once: past that, takes give nothing (said once on core.errors()).
//
// One thread at a time takes; views end on any thread.
class SubscriberPort {
 public:
  SubscriberPort(std::shared_ptr<Topic> topic, const SubscribeQos& qos, std::weak_ptr<prime::detail::RuntimeState> runtime,
                 bool observer);
  SubscriberPort(const SubscriberPort&) = delete;
  SubscriberPort& operator=(const SubscriberPort&) = delete;
  ~SubscriberPort();  // the subscriber lives on while views hold its samples

  [[nodiscard]] Subscriber* subscriber() const noexcept { return subscriber_; }
  [[nodiscard]] const Payloads& payloads() const noexcept { return payloads_; }

  // One sample published now, held for its first view; none when nothing
  // is, or the budget is spent (reported once). Damage found in the ring
  // is reported when `report_damage` (else why_nothing gives it).
  std::optional<Taken> try_take(bool report_damage);
  // Up to `max` samples published now, at most what the budget has left,
  // taken in one step and held for their first views; appended to `out`,
  // which has room for them (nothing here allocates or throws after the
  // take). Returns how many.
  std::size_t take_some(std::size_t max, std::vector<Taken>& out);
  // The budget's room left: what take_some may take at most.
  [[nodiscard]] std::size_t room() const noexcept;
  // Up to `max` samples published now as a batch, counted against the
  // budget until it ends (end_batch); none when nothing is. Damage is
  // reported, and a spent budget (once), when `now`: a try_read, which
  // does not wait first.
  std::optional<TakenSpan> take_span(std::size_t max, bool now);

  // Until a sample can be taken: first until the budget has room, then
  // until one is published, spinning for the QoS's spin, then asleep.
  // Errc::timeout or held_limit at `deadline`, Errc::stopped on `stop`.
  std::expected<void, Error> wait(Clock::time_point deadline, const std::stop_token& stop);
  // Why a take found nothing though a wait said a sample was out, if that
  // ends the read: damage, a stop, the deadline. None: the sample was
  // overwritten meanwhile, and the read waits again.
  std::optional<Error> why_nothing(Clock::time_point deadline, const std::stop_token& stop);

  // For a reader of the latest: moves on to the newest sample if one is
  // out (whether one is), acknowledging what it read if none is.
  bool skip_to_newest();
  [[nodiscard]] bool at_budget() const noexcept;
  [[nodiscard]] std::uint64_t lost() const noexcept;

 private:
  void report_budget();
  void report(Error error);
  [[nodiscard]] std::string budget_message() const;

  Subscriber* subscriber_;
  Payloads payloads_;
  std::chrono::microseconds spin_;
  std::weak_ptr<prime::detail::RuntimeState> runtime_;
  bool budget_reported_ = false;
};

}  // namespace prime::shm::detail
