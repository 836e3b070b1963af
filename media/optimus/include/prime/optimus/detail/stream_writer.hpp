#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <expected>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "prime/optimus/detail/stream_protocol.hpp"
#include "prime/optimus/stream.hpp"
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/qos.hpp"

// The writing side of a source's stream: StreamState appends to it as
// stream_protocol.hpp says. Every handle of a source can
// publish, so this is also what the handles share; a reader
// (stream_reader.hpp) holds it to keep its source, and what feeds it, alive.

namespace prime::optimus::detail {

// A batch of a StreamingPublisher sent and not yet answered: the connection
// it went on (kept from batch to batch), its messages (sent again if
// refused) and the epoch it appends in.
struct InFlight {
  std::optional<Pool::Lease> lease;
  std::vector<Message> batch;
  std::uint64_t epoch = 0;
};

// What a source's handles, its readers and the listener that feeds it from an
// event share: where its stream is, its QoS, the core it reports to.
//
// Thread-safe.
class StreamState {
 public:
  StreamState(std::shared_ptr<Pool> pool, std::string name, Qos qos, std::weak_ptr<prime::detail::RuntimeState> runtime)
      : pool_{std::move(pool)},
        name_{std::move(name)},
        key_{stream_key(pool_->domain(), name_)},
        readers_key_{detail::readers_key(pool_->domain(), name_)},
        qos_{qos},
        runtime_{std::move(runtime)},
        maxlen_{std::to_string(stream_length(qos))} {
    validate(qos_, name_);
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
    if (auto fits = c.fits(message.size(), [] { return "a message"; }); !fits) return std::unexpected(named(fits.error()));
    c.set_timeout(command_timeout());
    const auto t = std::to_string(stamp_ns(stamp));
    if (qos_.overflow == Overflow::drop_oldest) {
      auto done = run_script(c, {maxlen_, t, message, kAppendDrop});
      if (!done) return std::unexpected(std::move(done.error()));
      return {};
    }
    const auto give_up = deadline_after(qos_.block_timeout);
    auto pause = std::chrono::microseconds{50};
    while (true) {
      const bool late = Clock::now() >= give_up;
      auto done = run_script(c, {maxlen_, t, message, late ? kAppendForce : kAppendWait});
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
  // a batch never waits for readers): one XADD each, in the stream's epoch,
  // numbered by the server, then one XTRIM, pipelined. No script: the
  // server appends as it does for any client.
  // The server refuses an append when the stream is gone (NOMKSTREAM:
  // deleted, or lost in a restart), or has a later epoch than this writer
  // knew (another writer began one, or an entry not Prime's came in); then
  // what it refused goes again, in order, in a new epoch or the later one.
  std::expected<void, Error> publish_all(std::span<const Message> messages) {
    auto lease = pool_->acquire();
    if (!lease) return std::unexpected(named(lease.error()));
    auto& c = **lease;
    if (auto fits = fit(c, messages); !fits) return fits;
    c.set_timeout(command_timeout());
    return append_all(c, messages);
  }

  // Sends `batch` after the one in flight, then reads that one's replies: the
  // server appends one batch while the caller encodes and sends the next.
  // `batch` is then in flight, and what is returned is the outcome of the
  // one before. If the server refused some of that one (a new epoch), this
  // one is answered too, and what both refused goes again, in order, as in
  // publish_all. After an error nothing is in flight, but for a batch with
  // a message longer than the server takes: that one is refused before it
  // is sent, and the one before stays in flight.
  std::expected<void, Error> stream(InFlight& f, std::vector<Message> batch) {
    if (batch.empty()) return {};
    if (!f.lease) {
      auto lease = pool_->acquire();
      if (!lease) return std::unexpected(named(lease.error()));
      f.lease.emplace(std::move(*lease));
      (**f.lease).set_timeout(command_timeout());
    }
    auto& c = **f.lease;
    if (auto fits = fit(c, batch); !fits) return fits;  // the batch in flight stays so
    std::optional<Epoch> epoch;
    if (const auto known = known_epoch(); known && (f.batch.empty() || *known == f.epoch)) {
      epoch = Epoch{*known, false};
    } else {
      // Learning the epoch takes commands, whose replies would come after
      // those of the batch in flight: that one is answered first. So it is
      // when another handle saw the stream go on in a later epoch: were this
      // batch appended there, what the server refused of the one in flight
      // would go again after it.
      if (auto before = settle(f); !before) return not_sent(f, before.error(), batch.size());
      auto learned = stream_epoch(c);
      if (!learned) return not_sent(f, learned.error(), batch.size());
      epoch = *learned;
    }
    send(c, batch, *epoch);
    if (!f.batch.empty()) {
      auto before = answers(c, f.batch.size(), f.epoch);
      if (!before) return lost(f, before.error(), f.batch.size() + batch.size(), "the last two batches");
      if (!before->refused.empty() || before->failed) {
        auto now = answers(c, batch.size(), epoch->epoch);
        if (!now) return lost(f, now.error(), f.batch.size() + batch.size(), "the last two batches");
        if (before->failed || now->failed) {
          f.batch.clear();
          return std::unexpected(before->failed ? *before->failed : *now->failed);
        }
        std::vector<Message> again;
        for (const auto i : before->refused) again.push_back(std::move(f.batch[i]));
        for (const auto i : now->refused) again.push_back(std::move(batch[i]));
        f.batch.clear();
        return append_again(f, again);
      }
    }
    f.batch = std::move(batch);
    f.epoch = epoch->epoch;
    return {};
  }

  // Reads the replies of the batch in flight (StreamingPublisher::flush),
  // sending again what the server refused. Nothing is in flight after.
  std::expected<void, Error> settle(InFlight& f) {
    if (f.batch.empty()) return {};
    auto& c = **f.lease;
    auto got = answers(c, f.batch.size(), f.epoch);
    if (!got) return lost(f, got.error(), f.batch.size(), "the last batch");
    auto batch = std::move(f.batch);
    f.batch.clear();
    if (got->failed) return std::unexpected(*got->failed);
    std::vector<Message> again;
    for (const auto i : got->refused) again.push_back(std::move(batch[i]));
    return append_again(f, again);
  }

  // Strikes the readers whose leases ran out from the readers hash, as a
  // writer waiting for readers does: for a `block` reader subscribing, so
  // that a source whose writers never wait keeps no dead readers either.
  std::expected<void, Error> sweep_readers(Connection& c) {
    auto done = run_script(c, {maxlen_, "0", "", kSweepOnly});
    if (!done) return std::unexpected(std::move(done.error()));
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

  // The epoch a batch appends in, and whether it begins the stream (so the
  // appends may create it).
  struct Epoch {
    std::uint64_t epoch;
    bool begins;
  };
  static constexpr int kAppendAttempts = 4;
  static constexpr std::size_t kFlushEvery = 16;  // appends sent together in a batch

  // What the server answered to a batch: the appends it refused (indices
  // into the batch, in order), and the first other error it gave.
  struct Answers {
    std::vector<std::size_t> refused;
    std::optional<Error> failed;
  };

  // Whether every message of a batch goes to the server in one piece: else
  // none is sent, and the error names the first that does not.
  std::expected<void, Error> fit(const Connection& c, std::span<const Message> messages) const {
    for (std::size_t i = 0; i < messages.size(); ++i) {
      auto fits = c.fits(messages[i].first.size(), [&] {
        return "value " + std::to_string(i + 1) + " of a batch of " + std::to_string(messages.size());
      });
      if (!fits) return std::unexpected(named(fits.error()));
    }
    return {};
  }

  // Appends all of `messages` on `c`, sending what the server refuses again
  // (at most kAppendAttempts times), in order, in the epoch it learns.
  std::expected<void, Error> append_all(Connection& c, std::span<const Message> messages) {
    std::vector<Message> again;
    int attempts = 0;
    for (auto pending = messages; !pending.empty(); pending = again) {
      if (++attempts > kAppendAttempts)
        return std::unexpected(Error{Errc::iteration_limit, "source '" + name_ + "': the server refused " +
                                                            std::to_string(pending.size()) + " appends " +
                                                            std::to_string(kAppendAttempts) + " times: its stream keeps changing"});
      auto epoch = stream_epoch(c);
      if (!epoch) return std::unexpected(std::move(epoch.error()));
      send(c, pending, *epoch);
      auto got = answers(c, pending.size(), epoch->epoch);
      if (!got) return std::unexpected(named(got.error()));
      if (got->failed) return std::unexpected(*got->failed);
      std::vector<Message> refused;
      for (const auto i : got->refused) refused.push_back(pending[i]);
      again = std::move(refused);
    }
    return {};
  }

  // Queues one append per message in `epoch` (which may create the stream if
  // it begins it), then one XTRIM, and sends them: kFlushEvery at a time, so
  // the server appends the first while the next are written out. (A failure
  // to send shows in the replies.)
  void send(Connection& c, std::span<const Message> messages, const Epoch& epoch) {
    const auto id = append_id(epoch.epoch);
    std::size_t queued = 0;
    for (const auto& [message, stamp] : messages) {
      const auto t = std::to_string(stamp_ns(stamp));
      if (epoch.begins)
        c.append({"XADD", key_, id, "t", t, "d", message});
      else
        c.append({"XADD", key_, "NOMKSTREAM", id, "t", t, "d", message});
      if (++queued % kFlushEvery == 0) c.flush();
    }
    c.append({"XTRIM", key_, "MAXLEN", maxlen_});
    c.flush();
  }

  // Reads the replies to a batch of `count` appends sent in `epoch`, and its
  // XTRIM's. A refusal makes the next batch learn the epoch again.
  std::expected<Answers, Error> answers(Connection& c, std::size_t count, std::uint64_t epoch) {
    Answers got;
    for (std::size_t i = 0; i < count; ++i) {
      auto r = c.reply();
      if (!r) return std::unexpected(std::move(r.error()));
      if (is_nil(**r)) {
        got.refused.push_back(i);
        forget_epoch(epoch);  // the stream is gone
      } else if (is_error(**r) && text(**r).find("equal or smaller") != std::string_view::npos) {
        got.refused.push_back(i);
        forget_epoch();  // the stream went on in a later epoch
      } else if (is_error(**r) && !got.failed) {
        got.failed = server_error(**r, "source '" + name_ + "': publishing");
      }
    }
    auto trimmed = c.reply();
    if (!trimmed) return std::unexpected(std::move(trimmed.error()));
    return got;
  }

  // A StreamingPublisher's appends refused from the batches in flight, sent
  // again: then nothing is in flight. A connection that failed meanwhile is
  // not kept.
  std::expected<void, Error> append_again(InFlight& f, std::span<const Message> refused) {
    auto done = append_all(**f.lease, refused);
    if (!done && (**f.lease).broken()) f.lease.reset();
    return done;
  }

  // The connection of a StreamingPublisher failed with its batches unanswered:
  // nothing is in flight after, and the next batch takes another connection.
  std::unexpected<Error> lost(InFlight& f, const Error& e, std::size_t values, std::string_view which) {
    f.batch.clear();
    f.lease.reset();
    return std::unexpected(Error{e.code, "source '" + name_ + "': " + e.message + "; the " + std::to_string(values) +
                                             " values of " + std::string{which} + " may not all have been appended"});
  }
  // ...or failed before a batch of `values` was sent.
  std::unexpected<Error> not_sent(InFlight& f, const Error& e, std::size_t values) {
    f.batch.clear();
    f.lease.reset();
    return std::unexpected(Error{e.code, e.message + "; a batch of " + std::to_string(values) + " values was not sent"});
  }

  // The epoch the stream is in, as this writer last saw it.
  std::optional<std::uint64_t> known_epoch() {
    std::scoped_lock lock{mutex_};
    return epoch_;
  }

  // The stream's epoch as this writer last saw it; else its last entry's;
  // else (no stream, or it is gone) a new one, at the server's time.
  std::expected<Epoch, Error> stream_epoch(Connection& c) {
    std::optional<std::uint64_t> gone;
    {
      std::scoped_lock lock{mutex_};
      if (epoch_) return Epoch{*epoch_, false};
      gone = gone_epoch_;
    }
    if (!gone) {
      auto last = c.command({"XREVRANGE", key_, "+", "-", "COUNT", "1"});
      if (!last) return std::unexpected(named(last.error()));
      if (is_error(**last)) return std::unexpected(server_error(**last, "source '" + name_ + "': publishing"));
      if ((**last).is_array() && (**last).size() == 1)
        if (const auto entry = stream_entry((**last)[0]))
          if (const auto id = entry_id(entry->id)) {
            std::scoped_lock lock{mutex_};
            epoch_ = id->epoch;
            return Epoch{id->epoch, false};
          }
    }
    auto time = c.command({"TIME"});
    if (!time) return std::unexpected(named(time.error()));
    auto epoch = epoch_from_time(**time);
    if (!epoch) return std::unexpected(Error{Errc::type_mismatch, "source '" + name_ + "': an unexpected reply to TIME"});
    if (gone) epoch = std::max(*epoch, *gone + 1);
    std::scoped_lock lock{mutex_};
    epoch_ = *epoch;
    gone_epoch_.reset();
    return Epoch{*epoch, true};
  }
  // The next batch learns the stream's epoch again, or (`gone`: the stream
  // of that epoch is gone) begins the stream in a later one.
  void forget_epoch(std::optional<std::uint64_t> gone = std::nullopt) {
    std::scoped_lock lock{mutex_};
    epoch_.reset();
    if (gone) gone_epoch_ = gone;
  }

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
      args.push_back(lease_prefix_);
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
      if (!reply.is_array() || reply.size() != 2)
        return std::unexpected(Error{Errc::type_mismatch, "source '" + name_ + "': an unexpected script reply"});
      return ScriptResult{reply[0].integer() == 1, reply[1].integer()};
    }
    return std::unexpected(Error{Errc::unreachable, "source '" + name_ + "': the server keeps losing its script"});
  }

  const std::shared_ptr<Pool> pool_;
  const std::string name_;
  const std::string key_;
  const std::string readers_key_;
  const std::string lease_prefix_{lease_prefix(readers_key_)};
  const Qos qos_;
  const std::weak_ptr<prime::detail::RuntimeState> runtime_;
  const std::string maxlen_;
  std::mutex mutex_;
  std::string sha_;  // SHA1 of kPublishScript once loaded
  std::optional<std::uint64_t> epoch_;       // what publish_all appends in, once known
  std::optional<std::uint64_t> gone_epoch_;  // the epoch of a stream found gone
  prime::Connection upstream_;  // last member: disconnects before the rest goes
};

}  // namespace prime::optimus::detail
