#pragma once

#include <algorithm>
#include <charconv>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <expected>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/qos.hpp"

namespace prime::optimus::detail {

// Appends one entry to a source's stream, atomically on the server:
//   n  the entry's sequence number (one more than the last entry's), so a
//      reader can count what trimming took from it;
//   t  the sensor stamp (steady clock, ns), d the encoded message;
//   x  for a `block` source, the readers this entry was dropped for
//      (",id,id,"), because they made no room in time.
// The stream is trimmed to exactly ARGV[1] entries. Mode ARGV[4]: "drop"
// appends; "wait" appends only if every registered reader has room and
// otherwise returns {0, full}; "force" appends and marks the full readers.
//   KEYS: stream, readers hash.  ARGV: maxlen, stamp, message, mode.
inline constexpr std::string_view kPublishScript = R"lua(
local n = 1
local last = redis.call('XREVRANGE', KEYS[1], '+', '-', 'COUNT', 1)
if #last > 0 then
  local previous = tonumber(last[1][2][2])
  if previous then n = previous + 1 end
end
local full = {}
if ARGV[4] ~= 'drop' then
  local readers = redis.call('HGETALL', KEYS[2])
  for i = 1, #readers, 2 do
    if string.sub(readers[i], 1, 1) == 'r' then
      local cursor, capacity = string.match(readers[i + 1], '^(%d+) (%d+)$')
      if cursor and n - tonumber(cursor) > tonumber(capacity) then full[#full + 1] = string.sub(readers[i], 2) end
    end
  end
  if #full > 0 and ARGV[4] == 'wait' then return {0, #full} end
end
if #full > 0 then
  for _, reader in ipairs(full) do redis.call('HINCRBY', KEYS[2], 'l' .. reader, 1) end
  redis.call('XADD', KEYS[1], 'MAXLEN', ARGV[1], '*', 'n', n, 't', ARGV[2], 'd', ARGV[3], 'x', ',' .. table.concat(full, ',') .. ',')
else
  redis.call('XADD', KEYS[1], 'MAXLEN', ARGV[1], '*', 'n', n, 't', ARGV[2], 'd', ARGV[3])
end
return {1, #full}
)lua";

inline std::int64_t stamp_ns(Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

template <class N>
bool parse_number(std::string_view text, N& out) {
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  return ec == std::errc{} && end == text.data() + text.size();
}

// What a source's handles, its readers and the listener that feeds it from an
// event share: where its stream is, its QoS, the core it reports to.
//
// Thread-safe.
class StreamState {
 public:
  StreamState(std::shared_ptr<Pool> pool, std::string name, Qos qos, std::weak_ptr<prime::detail::RuntimeState> runtime)
      : pool_{std::move(pool)},
        name_{std::move(name)},
        key_{stream_key(*pool_, name_)},
        readers_key_{detail::readers_key(*pool_, name_)},
        qos_{qos},
        runtime_{std::move(runtime)},
        maxlen_{std::to_string(stream_length(qos))} {
    if (qos_.capacity == 0)
      throw Failure{{Errc::limit_exceeded, "source '" + name_ + "': capacity must be at least 1"}};
  }

  // How many entries the stream keeps. drop_oldest: the capacity. block: as
  // many again (at least 64) beyond it, because a writer that gave up on a
  // stuck reader still appends, and must not trim away what that reader was
  // holding; a reader stuck for longer loses its oldest, counted.
  static std::size_t stream_length(const Qos& qos) {
    return qos.overflow == Overflow::block ? qos.capacity + std::max<std::size_t>(qos.capacity, 64) : qos.capacity;
  }

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] const std::string& key() const noexcept { return key_; }
  [[nodiscard]] const std::string& readers_key() const noexcept { return readers_key_; }
  [[nodiscard]] const Qos& qos() const noexcept { return qos_; }
  [[nodiscard]] const std::weak_ptr<prime::detail::RuntimeState>& runtime() const noexcept { return runtime_; }
  [[nodiscard]] Pool& pool() const noexcept { return *pool_; }

  void report(Error error) const {
    if (auto r = runtime_.lock()) r->report(std::move(error));
  }

  // Appends one encoded message. Under the block policy, waits (polling, with
  // backoff) until every registered reader has room or `block_timeout` has
  // passed; then appends anyway, marks the value as dropped for the readers
  // that are still full, and reports it.
  std::expected<void, Error> publish(std::string_view message, Clock::time_point stamp) {
    auto lease = pool_->acquire();
    if (!lease) return std::unexpected(named(lease.error()));
    auto& c = **lease;
    c.set_timeout(command_timeout());
    const auto t = std::to_string(stamp_ns(stamp));
    if (qos_.overflow == Overflow::drop_oldest) {
      auto done = run_script(c, {maxlen_, t, message, "drop"});
      if (!done) return std::unexpected(std::move(done.error()));
      return {};
    }
    const auto give_up = Clock::now() + qos_.block_timeout;
    auto pause = std::chrono::microseconds{50};
    while (true) {
      const bool late = Clock::now() >= give_up;
      auto done = run_script(c, {maxlen_, t, message, late ? "force" : "wait"});
      if (!done) return std::unexpected(std::move(done.error()));
      if (done->first) {
        if (done->second > 0)
          report({Errc::overflow, "source '" + name_ + "': " + std::to_string(done->second) +
                                      " reader(s) made no room within " + std::to_string(qos_.block_timeout.count()) +
                                      " ms (block policy); the value was dropped for them"});
        return {};
      }
      std::this_thread::sleep_for(std::min<Clock::duration>(pause, give_up - Clock::now()));
      pause = std::min(pause * 2, std::chrono::microseconds{2000});
    }
  }

  // Appends many encoded messages in one round trip (drop_oldest semantics:
  // a batch never waits for readers).
  std::expected<void, Error> publish_all(std::span<const std::pair<std::string, Clock::time_point>> messages) {
    auto lease = pool_->acquire();
    if (!lease) return std::unexpected(named(lease.error()));
    auto& c = **lease;
    c.set_timeout(command_timeout());
    const auto sha = script_sha(c);
    if (!sha) return std::unexpected(std::move(sha.error()));
    std::vector<std::string> stamps;
    stamps.reserve(messages.size());
    for (const auto& [message, stamp] : messages) {
      stamps.push_back(std::to_string(stamp_ns(stamp)));
      c.append({"EVALSHA", *sha, "2", key_, readers_key_, maxlen_, stamps.back(), message, "drop"});
    }
    std::optional<Error> first_error;
    for (std::size_t i = 0; i < messages.size(); ++i) {
      auto r = c.reply();
      if (!r) return std::unexpected(named(r.error()));
      if (is_error(**r) && !first_error) first_error = server_error(**r, "source '" + name_ + "': publishing");
    }
    if (first_error) {
      forget_script();
      return std::unexpected(*first_error);
    }
    return {};
  }

  [[nodiscard]] std::chrono::microseconds command_timeout() const {
    return std::chrono::duration_cast<std::chrono::microseconds>(pool_->options().connect_timeout);
  }

  [[nodiscard]] Error named(const Error& e) const { return {e.code, "source '" + name_ + "': " + e.message}; }

  // Keeps the event listener that feeds this source for as long as the source lives.
  void feed_from(prime::Connection upstream) { upstream_ = std::move(upstream); }

 private:
  using ScriptResult = std::pair<bool, long long>;

  std::expected<std::string, Error> script_sha(Connection& c) {
    {
      std::scoped_lock lock{mutex_};
      if (!sha_.empty()) return sha_;
    }
    auto loaded = c.command({"SCRIPT", "LOAD", kPublishScript});
    if (!loaded) return std::unexpected(named(loaded.error()));
    if (is_error(**loaded)) return std::unexpected(server_error(**loaded, "source '" + name_ + "': loading its script"));
    std::scoped_lock lock{mutex_};
    sha_ = std::string{text(**loaded)};
    return sha_;
  }
  void forget_script() {
    std::scoped_lock lock{mutex_};
    sha_.clear();
  }

  // EVALSHA, loading the script again when the server lost it (a restart).
  std::expected<ScriptResult, Error> run_script(Connection& c, std::initializer_list<std::string_view> argv) {
    for (int attempt = 0; attempt < 2; ++attempt) {
      auto sha = script_sha(c);
      if (!sha) return std::unexpected(std::move(sha.error()));
      std::vector<std::string_view> args{"EVALSHA", *sha, "2", key_, readers_key_};
      args.insert(args.end(), argv.begin(), argv.end());
      auto r = c.command(args);
      if (!r) return std::unexpected(named(r.error()));
      if (is_error(**r)) {
        if (text(**r).starts_with("NOSCRIPT") && attempt == 0) {
          forget_script();
          continue;
        }
        return std::unexpected(server_error(**r, "source '" + name_ + "': publishing"));
      }
      const auto& reply = **r;
      if (reply.type != REDIS_REPLY_ARRAY || reply.elements != 2)
        return std::unexpected(Error{Errc::type_mismatch, "source '" + name_ + "': an unexpected script reply"});
      return ScriptResult{reply.element[0]->integer == 1, reply.element[1]->integer};
    }
    return std::unexpected(Error{Errc::unreachable, "source '" + name_ + "': the server keeps losing its script"});
  }

  const std::shared_ptr<Pool> pool_;
  const std::string name_;
  const std::string key_;
  const std::string readers_key_;
  const Qos qos_;
  const std::weak_ptr<prime::detail::RuntimeState> runtime_;
  const std::string maxlen_;
  std::mutex mutex_;
  std::string sha_;
  prime::Connection upstream_;  // last member: disconnects before the rest goes
};

// One reader of a source's stream, with its own cursor. Values come in
// batches (one round trip for up to `capacity` values). Under drop_oldest a
// batch is the newest `capacity` unread values, and what was skipped or
// trimmed away is counted from the gaps in the sequence numbers; under block
// the reader registers its cursor so writers wait for it.
//
// Not thread-safe (one thread at a time, as every Reader).
template <class T>
class StreamReader final : public Reader<T>::Impl {
 public:
  StreamReader(std::shared_ptr<StreamState> state, const Qos& qos)
      : state_{std::move(state)}, qos_{qos}, block_{qos.overflow == Overflow::block} {
    if (qos_.capacity == 0)
      throw Failure{{Errc::limit_exceeded, "source '" + state_->name() + "': capacity must be at least 1"}};
    const auto id = state_->pool().process_id() + "." + std::to_string(state_->pool().next_id());
    reader_field_ = "r" + id;
    lost_field_ = "l" + id;
    capacity_ = std::to_string(std::min(qos_.capacity, state_->qos().capacity));
    auto lease = state_->pool().acquire();
    if (!lease) throw Failure{state_->named(lease.error())};
    auto& c = **lease;
    c.set_timeout(state_->command_timeout());
    auto last = c.command({"XREVRANGE", state_->key(), "+", "-", "COUNT", "1"});
    if (!last) throw Failure{state_->named(last.error())};
    if (is_error(**last)) throw Failure{server_error(**last, "source '" + state_->name() + "': subscribing")};
    if ((**last).type == REDIS_REPLY_ARRAY && (**last).elements == 1) {
      const auto& entry = *(**last).element[0];
      if (entry.type == REDIS_REPLY_ARRAY && entry.elements == 2) {
        cursor_ = std::string{text(*entry.element[0])};
        if (auto n = field(*entry.element[1], "n")) parse_number(*n, seq_);
      }
    }
    if (block_) {
      auto registered = c.command({"HSET", state_->readers_key(), reader_field_, progress()});
      if (!registered) throw Failure{state_->named(registered.error())};
    }
  }
  StreamReader(const StreamReader&) = delete;
  StreamReader& operator=(const StreamReader&) = delete;

  ~StreamReader() override {
    if (!block_) return;
    if (auto lease = state_->pool().acquire()) {
      (*lease)->set_timeout(state_->command_timeout());
      (void)(*lease)->command({"HDEL", state_->readers_key(), reader_field_, lost_field_});
    }
  }

  std::optional<Sample<T>> try_read() override {
    if (cache_.empty()) {
      if (auto fetched = fetch(); !fetched) state_->report(fetched.error());
    }
    return pop();
  }

  std::expected<Sample<T>, Error> read_until(Clock::time_point deadline, std::stop_token stop) override {
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

  [[nodiscard]] std::uint64_t lost() const override {
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

 private:
  std::optional<Sample<T>> pop() {
    if (cache_.empty()) return std::nullopt;
    auto sample = std::move(cache_.front());
    cache_.pop_front();
    return sample;
  }

  std::string progress() const { return std::to_string(seq_) + " " + capacity_; }
  Error stopped() const { return {Errc::stopped, "source '" + state_->name() + "': the reader was stopped"}; }
  Error timed_out() const { return {Errc::timeout, "source '" + state_->name() + "': no value before the deadline"}; }

  static std::optional<std::string_view> field(const redisReply& fields, std::string_view name) {
    if (fields.type != REDIS_REPLY_ARRAY) return std::nullopt;
    for (std::size_t i = 0; i + 1 < fields.elements; i += 2)
      if (text(*fields.element[i]) == name) return text(*fields.element[i + 1]);
    return std::nullopt;
  }

  // Without waiting: the unread values (drop_oldest: the newest `capacity`
  // of them; block: the oldest `capacity`), into the cache.
  std::expected<void, Error> fetch() {
    auto lease = state_->pool().acquire();
    if (!lease) return std::unexpected(state_->named(lease.error()));
    auto& c = **lease;
    c.set_timeout(state_->command_timeout());
    const std::string after = cursor_ == "0-0" ? std::string{"-"} : "(" + cursor_;
    if (block_) {
      c.append({"HSET", state_->readers_key(), reader_field_, progress()});
      c.append({"XRANGE", state_->key(), after, "+", "COUNT", capacity_});
    } else {
      c.append({"XREVRANGE", state_->key(), "+", after, "COUNT", capacity_});
    }
    if (block_) {
      auto registered = c.reply();
      if (!registered) return std::unexpected(state_->named(registered.error()));
    }
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
    if (block_) c.append({"HSET", state_->readers_key(), reader_field_, progress()});
    c.append({"XREAD", "COUNT", capacity_, "BLOCK", ms, "STREAMS", state_->key(), cursor_});
    if (!c.flush()) return std::unexpected(state_->named(Error{Errc::unreachable, "redis at " + c.url() + ": connection lost"}));
    if (block_) {
      auto registered = c.reply();
      if (!registered) return std::unexpected(state_->named(registered.error()));
    }
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
    if (is_nil(**got) || (**got).type != REDIS_REPLY_ARRAY || (**got).elements != 1) return {};
    const auto& stream = *(**got).element[0];
    if (stream.type == REDIS_REPLY_ARRAY && stream.elements == 2) take(*stream.element[1], false);
    return {};
  }

  // Takes a reply's entries (newest first when `reversed`) into the cache.
  void take(const redisReply& entries, bool reversed) {
    if (entries.type != REDIS_REPLY_ARRAY) return;
    const auto n = entries.elements;
    for (std::size_t k = 0; k < n; ++k) {
      const auto& entry = *entries.element[reversed ? n - 1 - k : k];
      if (entry.type != REDIS_REPLY_ARRAY || entry.elements != 2) continue;
      const auto id = text(*entry.element[0]);
      const auto& fields = *entry.element[1];
      cursor_ = std::string{id};
      std::uint64_t seq = 0;
      const auto n_field = field(fields, "n");
      const auto t_field = field(fields, "t");
      const auto d_field = field(fields, "d");
      std::int64_t ns = 0;
      if (!n_field || !parse_number(*n_field, seq) || !t_field || !parse_number(*t_field, ns) || !d_field) {
        ++lost_;
        state_->report({Errc::type_mismatch, "source '" + state_->name() + "': entry " + std::string{id} + " of '" +
                                                 state_->key() + "' is not a Prime entry; skipped"});
        continue;
      }
      if (seq > seq_ + 1) lost_ += seq - seq_ - 1;  // trimmed away, or skipped for the newest
      // seq <= seq_: the stream began again (a server restart): nothing to count.
      seq_ = seq;
      if (block_) {
        if (auto skipped = field(fields, "x"); skipped && skipped->find("," + reader_field_.substr(1) + ",") != std::string_view::npos)
          continue;  // dropped for this reader by a writer it kept waiting; counted by the writer
      }
      auto value = decode_message<T>(*d_field, "source '" + state_->name() + "', key '" + state_->key() + "'");
      if (!value) {
        ++lost_;
        state_->report(value.error());
        continue;
      }
      cache_.push_back(Sample<T>{std::move(*value), Clock::time_point{std::chrono::nanoseconds{ns}}});
    }
  }

  // Sleeps until `until`; false when a stop request ended it.
  bool pause(Clock::time_point until, std::stop_token stop) {
    std::mutex m;
    std::condition_variable_any cv;
    std::unique_lock lock{m};
    cv.wait_until(lock, stop, until, [] { return false; });
    return !stop.stop_requested();
  }

  std::shared_ptr<StreamState> state_;  // a reader keeps its source (and what feeds it) alive
  const Qos qos_;
  const bool block_;
  std::string reader_field_;
  std::string lost_field_;
  std::string capacity_;
  std::string cursor_ = "0-0";
  std::uint64_t seq_ = 0;
  std::uint64_t lost_ = 0;
  std::deque<Sample<T>> cache_;
};

}  // namespace prime::optimus::detail
