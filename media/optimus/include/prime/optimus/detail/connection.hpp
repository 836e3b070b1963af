#pragma once

#include <algorithm>
#include <charconv>
#include <chrono>
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
#include "prime/optimus/detail/reply.hpp"
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

// A command's words. Views: the strings must outlive the call.
using Args = std::initializer_list<std::string_view>;

// The longest string a server takes in one piece where it does not say
// (Redis's default proto-max-bulk-len, 512 MiB).
inline constexpr std::size_t kDefaultMaxBulk = std::size_t{512} << 20;
// The longest a message may be whatever the server takes: a service's
// envelope (envelope.hpp) gives its payload a 32-bit length.
inline constexpr std::size_t kMaxEnvelope = 0xffffffffu;

// One connection to the server, through hiredis (in the compiled library:
// connection.cpp). Not thread-safe: hiredis contexts are not, so each
// thread uses its own (see Pool). After an I/O error it is `broken()` and
// must be dropped: a reply may be half read.
class Connection {
 public:
  static std::expected<Connection, Error> open(const Options& options, const Endpoint& endpoint);

  Connection(Connection&&) noexcept;
  Connection& operator=(Connection&&) noexcept;
  ~Connection();

  // Bounds every blocking read and write on the socket from now on.
  bool set_timeout(std::chrono::microseconds timeout);

  // Queues a command; nothing is sent until a reply is asked for. Written
  // out here (an array of bulk strings), not by hiredis's own formatting
  // (docs/performance.md: "Commands formatted by Optimus").
  // A command with a string longer than the server takes is not sent: the
  // server would drop the connection. It breaks this one instead, and the
  // reply says why (callers check a message with fits() before that).
  void append(std::span<const std::string_view> args);
  void append(Args args) { append(std::span<const std::string_view>{args.begin(), args.size()}); }

  // The next queued command's reply (sending what is queued first). An error
  // reply from the server is a reply, not an Error: callers judge it.
  std::expected<Reply, Error> reply();

  std::expected<Reply, Error> command(std::span<const std::string_view> args) {
    append(args);
    return reply();
  }
  std::expected<Reply, Error> command(Args args) { return command(std::span<const std::string_view>{args.begin(), args.size()}); }

  // Sends what is queued, without reading anything back.
  bool flush();

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
  std::expected<void, Error> learn_max_bulk();

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
  [[nodiscard]] int fd() const noexcept;
  [[nodiscard]] const std::string& url() const noexcept { return url_; }

  // Ends a blocking read from another thread (a stop request): the socket is
  // shut down, never closed, so the owner's descriptor stays valid until it
  // drops this connection. Thread-safe.
  void interrupt() const noexcept;
  // Marks it broken (in its owner's thread), so it is dropped, not reused.
  void break_off() noexcept { broken_ = true; }

 private:
  struct Context;  // hiredis's redisContext
  struct Free {
    void operator()(Context* c) const noexcept;
  };
  Connection(std::unique_ptr<Context, Free> ctx, std::string url);

  // A RESP header: `kind` (* for an array, $ for a bulk string) and a count.
  void put_length(char kind, std::size_t n) {
    char digits[24];
    digits[0] = kind;
    const auto end = std::to_chars(digits + 1, digits + sizeof digits - 2, n).ptr;
    end[0] = '\r';
    end[1] = '\n';
    command_.append(digits, static_cast<std::size_t>(end + 2 - digits));
  }

  Error io_error() const;

  std::unique_ptr<Context, Free> ctx_;
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

// A server's error reply as an Error naming what was being done.
inline Error server_error(ReplyRef r, const std::string& what) {
  const auto message = text(r);
  const auto code = message.starts_with("WRONGTYPE") ? Errc::type_mismatch : Errc::unreachable;
  return Error{code, what + ": the server said " + std::string{message}};
}

}  // namespace prime::optimus::detail
