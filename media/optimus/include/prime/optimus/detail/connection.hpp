#pragma once

#include <hiredis/hiredis.h>
#include <pthread.h>
#include <sys/socket.h>
#include <sys/time.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <csignal>
#include <cstring>
#include <ctime>
#include <expected>
#include <functional>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/optimus/detail/escape.hpp"
#include "prime/optimus/options.hpp"

namespace prime::optimus::detail {

// Where a server is, parsed from "tcp://[user[:password]@]host:port" or
// "unix:///path". User and password are %-escaped in the URL (a '@' in a
// password is %40).
struct Endpoint {
  bool unix_socket = false;
  std::string host{};  // tcp
  int port = 0;        // tcp
  std::string path{};  // unix
  std::optional<std::string> username{};  // tcp, from the URL
  std::optional<std::string> password{};
  std::string shown{};  // the URL as errors show it: no password
};

// `url` with its password (if any) as "***": what messages may show.
inline std::string without_password(std::string_view url) {
  if (!url.starts_with("tcp://")) return std::string{url};
  const auto at = url.rfind('@');
  if (at == std::string_view::npos) return std::string{url};
  const auto colon = url.find(':', 6);
  if (colon == std::string_view::npos || colon > at) return std::string{url};
  return std::string{url.substr(0, colon)} + ":***" + std::string{url.substr(at)};
}

inline std::expected<Endpoint, Error> parse_url(std::string_view url) {
  const auto bad = [&](std::string_view why) {
    return std::unexpected(Error{Errc::unreachable, "optimus: bad server URL '" + without_password(url) + "' (" +
                                                        std::string{why} +
                                                        "); expected tcp://[user:password@]host:port or unix:///path"});
  };
  if (url.starts_with("unix://")) {
    Endpoint e{.unix_socket = true, .path = std::string{url.substr(7)}, .shown = std::string{url}};
    if (e.path.empty() || e.path.front() != '/') return bad("the socket path must be absolute");
    return e;
  }
  if (!url.starts_with("tcp://")) return bad("unknown scheme");
  Endpoint e{.shown = without_password(url)};
  auto rest = url.substr(6);
  if (const auto at = rest.rfind('@'); at != std::string_view::npos) {
    const auto userinfo = rest.substr(0, at);
    const auto colon = userinfo.find(':');
    e.username = unescaped(userinfo.substr(0, colon));
    e.password = colon == std::string_view::npos ? std::optional<std::string>{""} : unescaped(userinfo.substr(colon + 1));
    if (!e.username || !e.password) return bad("a bad %-escape in the user or password");
    rest = rest.substr(at + 1);
  }
  const auto colon = rest.rfind(':');
  if (colon == std::string_view::npos || colon == 0) return bad("no host:port");
  e.host = std::string{rest.substr(0, colon)};
  if (e.host.size() > 2 && e.host.front() == '[' && e.host.back() == ']') e.host = e.host.substr(1, e.host.size() - 2);
  const auto port = rest.substr(colon + 1);
  const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), e.port);
  if (ec != std::errc{} || end != port.data() + port.size() || e.port <= 0 || e.port > 65535)
    return bad("the port must be a number in 1..65535");
  return e;
}

// Who to AUTH as: the options' user and password, or the URL's; none when
// neither gives any. Redis's AUTH always takes a password (a user created
// `nopass` takes any), so a user without one is an error, not a connection
// made without AUTH; and so are credentials given twice.
struct Credentials {
  std::string username;
  std::string password;
};
inline std::expected<std::optional<Credentials>, Error> credentials(const Options& options, const Endpoint& endpoint) {
  const auto wrong = [&](const std::string& why) {
    return std::unexpected(Error{Errc::unreachable, "redis at " + endpoint.shown + ": " + why});
  };
  const bool in_options = !options.username.empty() || !options.password.empty();
  if (in_options && (endpoint.username || endpoint.password))
    return wrong("credentials given both in the URL and in the options; give them once");
  Credentials c = in_options ? Credentials{options.username, options.password}
                             : Credentials{endpoint.username.value_or(""), endpoint.password.value_or("")};
  if (c.password.empty() && !c.username.empty())
    return wrong("a user '" + c.username + "' without a password; Redis's AUTH takes a password (any, for a nopass user)");
  if (c.password.empty()) return std::optional<Credentials>{};
  return std::optional<Credentials>{std::move(c)};
}

struct ReplyDeleter {
  void operator()(redisReply* r) const noexcept { freeReplyObject(r); }
};
using Reply = std::unique_ptr<redisReply, ReplyDeleter>;

struct ContextDeleter {
  void operator()(redisContext* c) const noexcept { redisFree(c); }
};

inline timeval to_timeval(std::chrono::microseconds d) {
  if (d < std::chrono::microseconds{1000}) d = std::chrono::microseconds{1000};
  return timeval{static_cast<time_t>(d.count() / 1'000'000), static_cast<suseconds_t>(d.count() % 1'000'000)};
}

// A write on a socket whose peer has gone (a server killed, a connection shut
// down by a stop) raises SIGPIPE, which ends the process unless handled, and
// hiredis writes with write(2), which cannot be told not to. So while one of
// these lives, SIGPIPE is blocked in this thread, and one a write raised is
// taken back when it ends: the write fails with EPIPE, which the connection
// reports as an error like any other.
class NoSigpipe {
 public:
  NoSigpipe() noexcept {
    sigemptyset(&pipe_);
    sigaddset(&pipe_, SIGPIPE);
    sigset_t pending;
    sigpending(&pending);
    already_pending_ = sigismember(&pending, SIGPIPE) == 1;  // not ours to take
    pthread_sigmask(SIG_BLOCK, &pipe_, &before_);
  }
  NoSigpipe(const NoSigpipe&) = delete;
  NoSigpipe& operator=(const NoSigpipe&) = delete;
  ~NoSigpipe() {
    if (!already_pending_) {
      sigset_t pending;
      sigpending(&pending);
      const timespec now{};
      if (sigismember(&pending, SIGPIPE) == 1) sigtimedwait(&pipe_, nullptr, &now);
    }
    pthread_sigmask(SIG_SETMASK, &before_, nullptr);
  }

 private:
  sigset_t pipe_{};
  sigset_t before_{};
  bool already_pending_ = false;
};

// A command's words. Views: the strings must outlive the call.
using Args = std::initializer_list<std::string_view>;

// The longest string a server takes in one piece where it does not say
// (Redis's default proto-max-bulk-len, 512 MiB).
inline constexpr std::size_t kDefaultMaxBulk = std::size_t{512} << 20;
// The longest a message may be whatever the server takes: a service's
// envelope (envelope.hpp) gives its payload a 32-bit length.
inline constexpr std::size_t kMaxEnvelope = 0xffffffffu;

// One connection to the server. Not thread-safe: hiredis contexts are not, so
// each thread uses its own (see Pool). After an I/O error it is `broken()` and
// must be dropped: a reply may be half read.
class Connection {
 public:
  static std::expected<Connection, Error> open(const Options& options, const Endpoint& endpoint) {
    const auto& url = endpoint.shown;
    auto auth = credentials(options, endpoint);
    if (!auth) return std::unexpected(std::move(auth.error()));
    const auto tv = to_timeval(options.connect_timeout);
    std::unique_ptr<redisContext, ContextDeleter> ctx{
        endpoint.unix_socket ? redisConnectUnixWithTimeout(endpoint.path.c_str(), tv)
                             : redisConnectWithTimeout(endpoint.host.c_str(), endpoint.port, tv)};
    if (!ctx) return std::unexpected(Error{Errc::unreachable, "redis at " + url + ": out of memory"});
    if (ctx->err)
      return std::unexpected(Error{Errc::unreachable, "redis at " + url + " is unreachable: " + ctx->errstr});
    Connection c{std::move(ctx), url};
    if (!c.set_timeout(options.connect_timeout))
      return std::unexpected(Error{Errc::unreachable, "redis at " + url + ": cannot set a socket timeout"});
    if (const auto& who = *auth) {
      auto reply = who->username.empty() ? c.command({"AUTH", who->password})
                                         : c.command({"AUTH", who->username, who->password});
      if (!reply) return std::unexpected(std::move(reply.error()));
      if ((*reply)->type == REDIS_REPLY_ERROR)
        return std::unexpected(Error{Errc::unreachable, "redis at " + url + " refused AUTH" +
                                                            (who->username.empty() ? "" : " as '" + who->username + "'") +
                                                            ": " + std::string{(*reply)->str, (*reply)->len}});
    }
    return c;
  }

  Connection(Connection&&) noexcept = default;
  Connection& operator=(Connection&&) noexcept = default;

  // Bounds every blocking read and write on the socket from now on.
  bool set_timeout(std::chrono::microseconds timeout) {
    if (timeout == timeout_) return true;
    if (redisSetTimeout(ctx_.get(), to_timeval(timeout)) != REDIS_OK) return false;
    timeout_ = timeout;
    return true;
  }

  // Queues a command; nothing is sent until a reply is asked for. Written
  // out here (an array of bulk strings), not by hiredis's own formatting
  // (docs/performance.md: "Commands formatted by Optimus").
  // A command with a string longer than the server takes is not sent: the
  // server would drop the connection. It breaks this one instead, and the
  // reply says why (callers check a message with fits() before that).
  void append(std::span<const std::string_view> args) {
    ++pending_;
    unsent_ = true;
    for (const auto a : args)
      if (a.size() > max_bulk_) {
        oversized_ = a.size();
        broken_ = true;
      }
    if (broken_) return;  // nothing more is sent on it
    command_.clear();
    put_length('*', args.size());
    for (const auto a : args) {
      put_length('$', a.size());
      command_.append(a);
      command_.append("\r\n");
    }
    if (redisAppendFormattedCommand(ctx_.get(), command_.data(), command_.size()) != REDIS_OK) broken_ = true;
  }
  void append(Args args) { append(std::span<const std::string_view>{args.begin(), args.size()}); }

  // The next queued command's reply (sending what is queued first). An error
  // reply from the server is a reply, not an Error: callers judge it.
  std::expected<Reply, Error> reply() {
    if (pending_ > 0) --pending_;
    if (broken_) return std::unexpected(io_error());
    void* raw = nullptr;
    std::optional<NoSigpipe> writing;  // redisGetReply sends what is queued first
    if (std::exchange(unsent_, false)) writing.emplace();
    if (redisGetReply(ctx_.get(), &raw) != REDIS_OK || raw == nullptr) {
      broken_ = true;
      return std::unexpected(io_error());
    }
    return Reply{static_cast<redisReply*>(raw)};
  }

  std::expected<Reply, Error> command(std::span<const std::string_view> args) {
    append(args);
    return reply();
  }
  std::expected<Reply, Error> command(Args args) { return command(std::span<const std::string_view>{args.begin(), args.size()}); }

  // Sends what is queued, without reading anything back.
  bool flush() {
    if (broken_) return false;
    unsent_ = false;
    const NoSigpipe writing;
    int done = 0;
    while (!done) {
      if (redisBufferWrite(ctx_.get(), &done) != REDIS_OK) {
        broken_ = true;
        return false;
      }
    }
    return true;
  }

  // Reads and drops the replies of commands queued but not yet read.
  bool drain() {
    while (pending_ > 0)
      if (!reply()) return false;
    return true;
  }

  // Asks the server for the longest string it takes in one piece (its
  // proto-max-bulk-len), which fits() goes by from then on; it stays the
  // default where the server does not say (CONFIG refused by an ACL, or
  // renamed away). A round trip: Pool asks once per connection it opens.
  std::expected<void, Error> learn_max_bulk() {
    auto r = command({"CONFIG", "GET", "proto-max-bulk-len"});
    if (!r) return std::unexpected(std::move(r.error()));
    const auto& reply = **r;
    if (reply.type != REDIS_REPLY_ARRAY || reply.elements != 2 || reply.element[1]->str == nullptr) return {};
    const std::string_view value{reply.element[1]->str, reply.element[1]->len};
    std::size_t max = 0;
    if (const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), max);
        ec == std::errc{} && end == value.data() + value.size() && max > 0)
      max_bulk_ = std::min<std::size_t>(max, kMaxEnvelope);
    return {};
  }

  // Whether a string of `bytes` (a message, or one wrapped for a service)
  // goes to the server in one piece; else an error naming `what` and both
  // sizes. Checked before anything is sent, so nothing else is lost.
  // `what()` names it ("a message").
  template <class What>
  [[nodiscard]] std::expected<void, Error> fits(std::size_t bytes, What&& what) const {
    if (bytes <= max_bulk_) return {};
    return std::unexpected(Error{Errc::too_large, std::string{what()} + " of " + std::to_string(bytes) +
                                                           " bytes is more than redis at " + url_ +
                                                           " takes in one piece (its proto-max-bulk-len, " +
                                                           std::to_string(max_bulk_) + " bytes); nothing was sent"});
  }

  [[nodiscard]] bool broken() const noexcept { return broken_; }
  [[nodiscard]] bool valid() const noexcept { return ctx_ != nullptr; }
  [[nodiscard]] int pending() const noexcept { return pending_; }
  [[nodiscard]] int fd() const noexcept { return ctx_->fd; }
  [[nodiscard]] const std::string& url() const noexcept { return url_; }

  // Ends a blocking read from another thread (a stop request): the socket is
  // shut down, never closed, so the owner's descriptor stays valid until it
  // drops this connection. Thread-safe.
  void interrupt() const noexcept { ::shutdown(ctx_->fd, SHUT_RDWR); }
  // Marks it broken (in its owner's thread), so it is dropped, not reused.
  void break_off() noexcept { broken_ = true; }

 private:
  Connection(std::unique_ptr<redisContext, ContextDeleter> ctx, std::string url)
      : ctx_{std::move(ctx)}, url_{std::move(url)} {}

  // A RESP header: `kind` (* for an array, $ for a bulk string) and a count.
  void put_length(char kind, std::size_t n) {
    char digits[24];
    digits[0] = kind;
    const auto end = std::to_chars(digits + 1, digits + sizeof digits - 2, n).ptr;
    end[0] = '\r';
    end[1] = '\n';
    command_.append(digits, static_cast<std::size_t>(end + 2 - digits));
  }

  Error io_error() const {
    if (oversized_ != 0)
      return Error{Errc::too_large, "redis at " + url_ + ": a command with a string of " + std::to_string(oversized_) +
                                             " bytes, more than the server takes in one piece (its proto-max-bulk-len, " +
                                             std::to_string(max_bulk_) + " bytes), was not sent; the connection is dropped"};
    std::string why = ctx_->err ? std::string{ctx_->errstr} : "connection lost";
    if (ctx_->err == REDIS_ERR_IO && (errno == EAGAIN || errno == EWOULDBLOCK)) why = "no answer in time";
    return Error{Errc::unreachable, "redis at " + url_ + ": " + why};
  }

  std::unique_ptr<redisContext, ContextDeleter> ctx_;
  std::string url_;
  std::chrono::microseconds timeout_{-1};
  std::size_t max_bulk_ = kDefaultMaxBulk;
  std::size_t oversized_ = 0;  // the string that kept a command from being sent
  bool broken_ = false;
  bool unsent_ = false;  // commands appended since the last send
  int pending_ = 0;
  std::string command_;  // the one append() writes out, kept for its capacity
};

// Lets a stop request end a blocking read on a connection at once, and only
// a read: a write in progress (a reply on its way to a caller) is never cut.
// With `wake` (a push to a key the read also waits on; false when it could
// not be made), the read ends with that push, so what it took from the
// server meanwhile still arrives; else, or when the push fails, the socket
// is shut down, and what the read took is lost with it.
// Lives no longer than the connection's lease.
class StopGuard {
 public:
  StopGuard(Connection& connection, std::stop_token stop, std::function<bool()> wake = {})
      : connection_{connection}, wake_{std::move(wake)}, callback_{std::move(stop), Wake{this}} {}
  StopGuard(const StopGuard&) = delete;
  StopGuard& operator=(const StopGuard&) = delete;

  // Before a blocking read: false when a stop was requested (do not block).
  [[nodiscard]] bool begin_blocking() {
    std::scoped_lock lock{mutex_};
    if (stopping_) return false;
    blocking_ = true;
    return true;
  }
  // After it. A connection a stop shut down is broken from then on, even if
  // the read got its reply before the shutdown: it is never used again.
  void end_blocking() {
    std::scoped_lock lock{mutex_};
    blocking_ = false;
    if (interrupted_) connection_.break_off();
  }
  [[nodiscard]] bool stopping() {
    std::scoped_lock lock{mutex_};
    return stopping_;
  }

 private:
  struct Wake {
    StopGuard* guard;
    void operator()() const noexcept {
      std::scoped_lock lock{guard->mutex_};
      guard->stopping_ = true;
      if (guard->wake_ && pushed()) return;
      if (!guard->blocking_) return;
      guard->connection_.interrupt();
      guard->interrupted_ = true;
    }
    [[nodiscard]] bool pushed() const noexcept {
      try {
        return guard->wake_();
      } catch (...) {
        return false;
      }
    }
  };

  Connection& connection_;
  std::function<bool()> wake_;
  std::mutex mutex_;
  bool blocking_ = false;
  bool stopping_ = false;
  bool interrupted_ = false;
  std::stop_callback<Wake> callback_;  // last: registered once the rest exists
};

// What a reply says, for the few shapes the medium reads.
inline std::string_view text(const redisReply& r) noexcept { return {r.str ? r.str : "", r.str ? r.len : 0}; }
inline bool is_error(const redisReply& r) noexcept { return r.type == REDIS_REPLY_ERROR; }
inline bool is_nil(const redisReply& r) noexcept { return r.type == REDIS_REPLY_NIL; }

// A server's error reply as an Error naming what was being done.
inline Error server_error(const redisReply& r, const std::string& what) {
  const auto message = text(r);
  const auto code = message.starts_with("WRONGTYPE") ? Errc::type_mismatch : Errc::unreachable;
  return Error{code, what + ": the server said " + std::string{message}};
}

}  // namespace prime::optimus::detail
