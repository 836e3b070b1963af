#pragma once

#include <algorithm>
#include <array>
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
#include "prime/topology/detail/runtime_state.hpp"
#include "prime/topology/qos.hpp"

// The writing side of a source's stream: StreamState appends to it with the
// publish script of stream_protocol.hpp. Every handle of a source can
// publish, so this is also what the handles share; a reader
// (stream_reader.hpp) holds it to keep its source, and what feeds it, alive.

namespace prime::optimus::detail {

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
    c.set_timeout(command_timeout());
    const auto t = std::to_string(stamp_ns(stamp));
    if (qos_.overflow == Overflow::drop_oldest) {
      auto done = run_script(c, {maxlen_, t, message, kAppendDrop});
      if (!done) return std::unexpected(std::move(done.error()));
      return {};
    }
    const auto give_up = Clock::now() + qos_.block_timeout;
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
  // a batch never waits for readers): calls of the batch script, each
  // appending up to kBatchEntries, pipelined. A call the server refused
  // because it lost the script (a restart) appended nothing: it is sent
  // again, the others are not.
  std::expected<void, Error> publish_all(std::span<const std::pair<std::string, Clock::time_point>> messages) {
    auto lease = pool_->acquire();
    if (!lease) return std::unexpected(named(lease.error()));
    auto& c = **lease;
    c.set_timeout(command_timeout());
    std::vector<std::span<const std::pair<std::string, Clock::time_point>>> calls;
    for (std::size_t i = 0; i < messages.size(); i += kBatchEntries)
      calls.push_back(messages.subspan(i, std::min(kBatchEntries, messages.size() - i)));
    std::vector<std::string> stamps;
    std::vector<std::string_view> args;
    for (int attempt = 0; attempt < 2 && !calls.empty(); ++attempt) {
      const auto sha = script_sha(c, Script::batch);
      if (!sha) return std::unexpected(std::move(sha.error()));
      for (const auto& call : calls) {
        stamps.clear();
        stamps.reserve(call.size());  // no reallocation: args holds views of these
        args.assign({"EVALSHA", *sha, "1", key_, maxlen_});
        for (const auto& [message, stamp] : call) {
          stamps.push_back(std::to_string(stamp_ns(stamp)));
          args.push_back(stamps.back());
          args.push_back(message);
        }
        c.append(args);
      }
      std::vector<std::span<const std::pair<std::string, Clock::time_point>>> again;
      std::optional<Error> first_error;
      for (const auto& call : calls) {
        auto r = c.reply();
        if (!r) return std::unexpected(named(r.error()));
        if (!is_error(**r)) continue;
        if (text(**r).starts_with("NOSCRIPT"))
          again.push_back(call);
        else if (!first_error)
          first_error = server_error(**r, "source '" + name_ + "': publishing");
      }
      if (first_error) return std::unexpected(*first_error);
      if (!again.empty()) forget_script(Script::batch);
      calls = std::move(again);
    }
    if (!calls.empty())
      return std::unexpected(Error{Errc::unreachable, "source '" + name_ + "': the server keeps losing its script"});
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

  enum class Script { one, batch };  // kPublishScript, kPublishBatchScript

  std::expected<std::string, Error> script_sha(Connection& c, Script which = Script::one) {
    auto& sha = shas_[static_cast<std::size_t>(which)];
    {
      std::scoped_lock lock{mutex_};
      if (!sha.empty()) return sha;
    }
    auto loaded = c.command({"SCRIPT", "LOAD", which == Script::one ? kPublishScript : kPublishBatchScript});
    if (!loaded) return std::unexpected(named(loaded.error()));
    if (is_error(**loaded)) return std::unexpected(server_error(**loaded, "source '" + name_ + "': loading its script"));
    std::scoped_lock lock{mutex_};
    sha = std::string{text(**loaded)};
    return sha;
  }
  void forget_script(Script which = Script::one) {
    std::scoped_lock lock{mutex_};
    shas_[static_cast<std::size_t>(which)].clear();
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
  std::array<std::string, 2> shas_;  // SHA1 of each script once loaded, by Script
  prime::Connection upstream_;  // last member: disconnects before the rest goes
};

}  // namespace prime::optimus::detail
