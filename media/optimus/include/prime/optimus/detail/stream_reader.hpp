#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <expected>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <string_view>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "prime/optimus/detail/stream_protocol.hpp"
#include "prime/optimus/detail/stream_writer.hpp"
#include "prime/optimus/stream.hpp"
#include "prime/topology/qos.hpp"

// The reading side of a source's stream.

namespace prime::optimus::detail {

// One reader of a source's stream, with its own cursor. Values come in
// batches (one round trip for up to `capacity` values). Under drop_oldest a
// batch is the newest `capacity` unread values, and what was skipped or
// trimmed away is counted from the gaps in the sequence numbers; under block
// the reader registers its cursor so writers wait for it. Its messages stay
// encoded: the typed reader (source.hpp) decodes them.
//
// Not thread-safe (one thread at a time, as every Reader).
class StreamReader {
 public:
  StreamReader(std::shared_ptr<StreamState> state, const Qos& qos)
      : state_{std::move(state)}, qos_{qos}, block_{qos.overflow == Overflow::block} {
    validate(qos_, state_->name());
    reader_id_ = state_->pool().process_id() + "." + std::to_string(state_->pool().next_id());
    reader_field_ = reader_field(reader_id_);
    lost_field_ = lost_field(reader_id_);
    lease_key_ = lease_key(state_->readers_key(), reader_id_);
    capacity_ = std::to_string(std::min(qos_.capacity, state_->qos().capacity));
    auto lease = state_->pool().acquire();
    if (!lease) throw Failure{state_->named(lease.error())};
    auto& c = **lease;
    c.set_timeout(state_->command_timeout());
    auto last = c.command({"XREVRANGE", state_->key(), "+", "-", "COUNT", "1"});
    if (!last) throw Failure{state_->named(last.error())};
    if (is_error(**last)) throw Failure{server_error(**last, "source '" + state_->name() + "': subscribing")};
    if ((**last).is_array() && (**last).size() == 1) {
      if (const auto entry = stream_entry((**last)[0])) {
        cursor_ = std::string{entry->id};
        if (const auto id = entry_id(entry->id)) last_ = *id;
      }
    }
    if (block_) {
      if (auto swept = state_->sweep_readers(c); !swept) throw Failure{swept.error()};
      register_progress(c);
      if (auto registered = registration_replies(c); !registered) throw Failure{registered.error()};
    }
  }
  StreamReader(const StreamReader&) = delete;
  StreamReader& operator=(const StreamReader&) = delete;

  ~StreamReader() {
    if (!block_) return;
    if (auto lease = state_->pool().acquire()) {
      (*lease)->set_timeout(state_->command_timeout());
      (void)(*lease)->command({"HDEL", state_->readers_key(), reader_field_, lost_field_});
      (void)(*lease)->command({"DEL", lease_key_});
    }
  }

  std::optional<Message> try_read() {
    if (cache_.empty()) {
      if (auto fetched = fetch(); !fetched) state_->report(fetched.error());
    }
    return pop();
  }

  std::expected<Message, Error> read_until(Clock::time_point deadline, std::stop_token stop) {
    while (true) {
      if (auto value = pop()) return std::move(*value);
      if (stop.stop_requested()) return std::unexpected(stopped());
      auto fetched = fetch();
      if (fetched && !cache_.empty()) continue;
      const auto now = Clock::now();
      if (!fetched) {
        if (now >= deadline) return std::unexpected(std::move(fetched.error()));
        if (!pause(std::min(deadline, now + std::chrono::milliseconds{50}), stop)) return std::unexpected(stopped());
        continue;
      }
      if (now >= deadline) return std::unexpected(timed_out());
      auto waited = wait(std::min<Clock::duration>(deadline - now, kWaitSlice), stop);
      if (stop.stop_requested()) return std::unexpected(stopped());
      if (!waited) {
        if (Clock::now() >= deadline) return std::unexpected(std::move(waited.error()));
        if (!pause(std::min(deadline, Clock::now() + std::chrono::milliseconds{50}), stop)) return std::unexpected(stopped());
      }
    }
  }

  [[nodiscard]] std::uint64_t lost() const {
    std::uint64_t dropped = 0;
    if (block_) {
      if (auto lease = state_->pool().acquire()) {
        (*lease)->set_timeout(state_->command_timeout());
        if (auto r = (*lease)->command({"HGET", state_->readers_key(), lost_field_}); r && !is_nil(**r))
          parse_number(text(**r), dropped);
      }
    }
    return lost_ + dropped;
  }

  // A message that did not decode: counted as lost, and said.
  void refuse(Error why) {
    ++lost_;
    state_->report(std::move(why));
  }

 private:
  std::optional<Message> pop() {
    if (cache_.empty()) return std::nullopt;
    auto sample = std::move(cache_.front());
    cache_.pop_front();
    return sample;
  }

  std::string progress() const { return reader_progress(last_.seq, capacity_); }

  // A `block` reader's registration, sent before each read or wait: its
  // lease renewed (writers strike a reader whose lease ran out: it died, or
  // stopped reading), then how far it has read. In that order, so a writer
  // never finds the progress without the lease.
  void register_progress(Connection& c) const {
    static const std::string lease_ms = std::to_string(kReaderLease.count());
    c.append({"SET", lease_key_, "1", "PX", lease_ms});
    c.append({"HSET", state_->readers_key(), reader_field_, progress()});
  }
  // Their two replies; an error names the source. A progress field that is
  // new after the first says a writer struck this reader (it read nothing
  // for kReaderLease, its room used up): writers did not wait for it meanwhile, and the count
  // of what they dropped for it went with its fields. Said, not hidden.
  std::expected<void, Error> registration_replies(Connection& c) {
    for (int i = 0; i < 2; ++i) {
      auto registered = c.reply();
      if (!registered) return std::unexpected(state_->named(registered.error()));
      if (is_error(**registered))
        return std::unexpected(server_error(**registered, "source '" + state_->name() + "': registering a block reader"));
      if (i == 1 && registered_ && (**registered).is_integer() && (**registered).integer() == 1)
        state_->report({Errc::overflow, "source '" + state_->name() + "': a block reader read nothing for " +
                                            std::to_string(kReaderLease.count()) +
                                            " ms with its room used up and was taken for gone; registered again, it may have lost values not counted by lost()"});
    }
    registered_ = true;
    return {};
  }
  Error stopped() const { return {Errc::stopped, "source '" + state_->name() + "': the reader was stopped"}; }
  Error timed_out() const { return {Errc::timeout, "source '" + state_->name() + "': no value before the deadline"}; }

  // Without waiting: the unread values (drop_oldest: the newest `capacity`
  // of them; block: the oldest `capacity`), into the cache.
  std::expected<void, Error> fetch() {
    auto lease = state_->pool().acquire();
    if (!lease) return std::unexpected(state_->named(lease.error()));
    auto& c = **lease;
    c.set_timeout(state_->command_timeout());
    const std::string after = cursor_ == "0-0" ? std::string{"-"} : "(" + cursor_;
    if (block_) {
      register_progress(c);
      c.append({"XRANGE", state_->key(), after, "+", "COUNT", capacity_});
    } else {
      c.append({"XREVRANGE", state_->key(), "+", after, "COUNT", capacity_});
    }
    if (block_)
      if (auto registered = registration_replies(c); !registered) return registered;
    auto entries = c.reply();
    if (!entries) return std::unexpected(state_->named(entries.error()));
    if (is_error(**entries)) return std::unexpected(server_error(**entries, "source '" + state_->name() + "': reading"));
    take(**entries, !block_);
    return {};
  }

  // Waits up to `timeout` for a value to arrive; a stop request ends it at once.
  std::expected<void, Error> wait(Clock::duration timeout, std::stop_token stop) {
    auto lease = state_->pool().acquire();
    if (!lease) return std::unexpected(state_->named(lease.error()));
    auto& c = **lease;
    const auto block_for = std::chrono::duration_cast<std::chrono::milliseconds>(timeout);
    const auto ms = std::to_string(std::max<std::int64_t>(block_for.count(), 1));
    c.set_timeout(std::chrono::duration_cast<std::chrono::microseconds>(block_for) + kSocketMargin);
    StopGuard guard{c, stop};
    if (block_) register_progress(c);
    c.append({"XREAD", "COUNT", capacity_, "BLOCK", ms, "STREAMS", state_->key(), cursor_});
    if (!c.flush()) return std::unexpected(state_->named(Error{Errc::unreachable, "redis at " + c.url() + ": connection lost"}));
    if (block_)
      if (auto registered = registration_replies(c); !registered) return registered;
    if (!guard.begin_blocking()) {
      lease->discard();
      return {};
    }
    auto got = c.reply();
    guard.end_blocking();
    if (!got) {
      if (stop.stop_requested()) lease->discard();
      return std::unexpected(state_->named(got.error()));
    }
    if (is_error(**got)) return std::unexpected(server_error(**got, "source '" + state_->name() + "': waiting"));
    if (is_nil(**got) || !(**got).is_array() || (**got).size() != 1) return {};
    const auto stream = (**got)[0];
    if (stream.is_array() && stream.size() == 2) take(stream[1], false);
    return {};
  }

  // Takes a reply's entries (newest first when `reversed`) into the cache.
  void take(ReplyRef entries, bool reversed) {
    if (!entries.is_array()) return;
    const auto n = entries.size();
    for (std::size_t k = 0; k < n; ++k) {
      const auto entry = stream_entry(entries[reversed ? n - 1 - k : k]);
      if (!entry) continue;
      cursor_ = std::string{entry->id};
      if (const auto id = entry_id(entry->id)) {
        // What trimming took, or what was skipped for the newest: a gap in
        // the epoch, or the entries of a new one (the stream began again)
        // before this.
        const auto before = id->epoch == last_.epoch ? last_.seq : 0;
        if (id->seq > before + 1) lost_ += id->seq - before - 1;
        last_ = *id;
      }
      const auto fields = entry_fields(entry->fields);
      if (!fields) {
        ++lost_;
        state_->report({Errc::type_mismatch, "source '" + state_->name() + "': entry " + std::string{entry->id} + " of '" +
                                                 state_->key() + "' is not a Prime entry; skipped"});
        continue;
      }
      if (block_ && fields->dropped_for_reader(reader_id_))
        continue;  // dropped for this reader by a writer it kept waiting; counted by the writer
      cache_.emplace_back(std::string{fields->message}, Clock::time_point{std::chrono::nanoseconds{fields->stamp_ns}});
    }
  }

  std::shared_ptr<StreamState> state_;  // a reader keeps its source (and what feeds it) alive
  const Qos qos_;
  const bool block_;
  std::string reader_id_;
  std::string reader_field_;
  std::string lost_field_;
  std::string lease_key_;
  std::string capacity_;
  std::string cursor_ = "0-0";
  bool registered_ = false;  // a `block` reader, once it has registered
  EntryId last_;  // of the last entry read (or the newest when subscribing)
  std::uint64_t lost_ = 0;
  std::deque<Message> cache_;
};

}  // namespace prime::optimus::detail
