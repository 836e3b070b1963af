// Connections to the Redis server and the replies read from it, through
// hiredis, which stays inside this library.
#include "prime/optimus/detail/connection.hpp"

#include <hiredis/hiredis.h>
#include <pthread.h>
#include <sys/socket.h>
#include <sys/time.h>

#include <cerrno>
#include <csignal>
#include <ctime>

#include "prime/optimus/detail/reply.hpp"

namespace prime::optimus::detail {

// RawReply and Connection::Context are never defined: pointers to them are
// hiredis's, cast back here.
namespace {

const redisReply& raw(const RawReply* node) noexcept { return *reinterpret_cast<const redisReply*>(node); }
template <class Owner>
redisContext* hiredis(const Owner& ctx) noexcept {
  return reinterpret_cast<redisContext*>(ctx.get());
}

timeval to_timeval(std::chrono::microseconds d) {
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

}  // namespace

// Replies.

bool ReplyRef::is_string() const noexcept {
  return raw(node_).type == REDIS_REPLY_STRING || raw(node_).type == REDIS_REPLY_STATUS;
}
bool ReplyRef::is_array() const noexcept { return raw(node_).type == REDIS_REPLY_ARRAY; }
bool ReplyRef::is_integer() const noexcept { return raw(node_).type == REDIS_REPLY_INTEGER; }
bool ReplyRef::is_nil() const noexcept { return raw(node_).type == REDIS_REPLY_NIL; }
bool ReplyRef::is_error() const noexcept { return raw(node_).type == REDIS_REPLY_ERROR; }
std::string_view ReplyRef::text() const noexcept {
  const auto& r = raw(node_);
  const bool has_text = r.type == REDIS_REPLY_STRING || r.type == REDIS_REPLY_STATUS || r.type == REDIS_REPLY_ERROR;
  return has_text && r.str != nullptr ? std::string_view{r.str, r.len} : std::string_view{};
}
long long ReplyRef::integer() const noexcept {
  return raw(node_).type == REDIS_REPLY_INTEGER ? raw(node_).integer : 0;
}
std::size_t ReplyRef::size() const noexcept {
  return raw(node_).type == REDIS_REPLY_ARRAY ? raw(node_).elements : 0;
}
ReplyRef ReplyRef::operator[](std::size_t i) const noexcept {
  return ReplyRef{reinterpret_cast<const RawReply*>(raw(node_).element[i])};
}
void Reply::Free::operator()(RawReply* r) const noexcept { freeReplyObject(reinterpret_cast<redisReply*>(r)); }

// Connections.

void Connection::Free::operator()(Context* c) const noexcept { redisFree(reinterpret_cast<redisContext*>(c)); }

Connection::Connection(std::unique_ptr<Context, Free> ctx, std::string url) : ctx_{std::move(ctx)}, url_{std::move(url)} {}
Connection::Connection(Connection&&) noexcept = default;
Connection& Connection::operator=(Connection&&) noexcept = default;
Connection::~Connection() = default;

std::expected<Connection, Error> Connection::open(const Options& options, const Endpoint& endpoint) {
  const auto& url = endpoint.shown;
  auto auth = credentials(options, endpoint);
  if (!auth) return std::unexpected(std::move(auth.error()));
  const auto tv = to_timeval(options.connect_timeout);
  auto* made = endpoint.unix_socket ? redisConnectUnixWithTimeout(endpoint.path.c_str(), tv)
                                    : redisConnectWithTimeout(endpoint.host.c_str(), endpoint.port, tv);
  std::unique_ptr<Context, Free> ctx{reinterpret_cast<Context*>(made)};
  if (!made) return std::unexpected(Error{Errc::unreachable, "redis at " + url + ": out of memory"});
  if (made->err) return std::unexpected(Error{Errc::unreachable, "redis at " + url + " is unreachable: " + made->errstr});
  Connection c{std::move(ctx), url};
  if (!c.set_timeout(options.connect_timeout))
    return std::unexpected(Error{Errc::unreachable, "redis at " + url + ": cannot set a socket timeout"});
  if (const auto& who = *auth) {
    auto reply = who->username.empty() ? c.command({"AUTH", who->password})
                                       : c.command({"AUTH", who->username, who->password});
    if (!reply) return std::unexpected(std::move(reply.error()));
    if ((*reply)->is_error())
      return std::unexpected(Error{Errc::unreachable, "redis at " + url + " refused AUTH" +
                                                          (who->username.empty() ? "" : " as '" + who->username + "'") +
                                                          ": " + std::string{(*reply)->text()}});
  }
  return c;
}

bool Connection::set_timeout(std::chrono::microseconds timeout) {
  if (timeout == timeout_) return true;
  if (redisSetTimeout(hiredis(ctx_), to_timeval(timeout)) != REDIS_OK) return false;
  timeout_ = timeout;
  return true;
}

void Connection::append(std::span<const std::string_view> args) {
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
  if (redisAppendFormattedCommand(hiredis(ctx_), command_.data(), command_.size()) != REDIS_OK) broken_ = true;
}

std::expected<Reply, Error> Connection::reply() {
  if (pending_ > 0) --pending_;
  if (broken_) return std::unexpected(io_error());
  void* got = nullptr;
  std::optional<NoSigpipe> writing;  // redisGetReply sends what is queued first
  if (std::exchange(unsent_, false)) writing.emplace();
  if (redisGetReply(hiredis(ctx_), &got) != REDIS_OK || got == nullptr) {
    broken_ = true;
    return std::unexpected(io_error());
  }
  return Reply{static_cast<RawReply*>(got)};
}

bool Connection::flush() {
  if (broken_) return false;
  unsent_ = false;
  const NoSigpipe writing;
  int done = 0;
  while (!done) {
    if (redisBufferWrite(hiredis(ctx_), &done) != REDIS_OK) {
      broken_ = true;
      return false;
    }
  }
  return true;
}

std::expected<void, Error> Connection::learn_max_bulk() {
  auto r = command({"CONFIG", "GET", "proto-max-bulk-len"});
  if (!r) return std::unexpected(std::move(r.error()));
  const auto& reply = **r;
  if (!reply.is_array() || reply.size() != 2 || !reply[1].is_string()) return {};
  const auto value = reply[1].text();
  std::size_t max = 0;
  if (const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), max);
      ec == std::errc{} && end == value.data() + value.size() && max > 0)
    max_bulk_ = std::min<std::size_t>(max, kMaxEnvelope);
  return {};
}

int Connection::fd() const noexcept { return hiredis(ctx_)->fd; }

void Connection::interrupt() const noexcept { ::shutdown(hiredis(ctx_)->fd, SHUT_RDWR); }

Error Connection::io_error() const {
  if (oversized_ != 0)
    return Error{Errc::too_large, "redis at " + url_ + ": a command with a string of " + std::to_string(oversized_) +
                                           " bytes, more than the server takes in one piece (its proto-max-bulk-len, " +
                                           std::to_string(max_bulk_) + " bytes), was not sent; the connection is dropped"};
  const auto* ctx = hiredis(ctx_);
  std::string why = ctx->err ? std::string{ctx->errstr} : "connection lost";
  if (ctx->err == REDIS_ERR_IO && (errno == EAGAIN || errno == EWOULDBLOCK)) why = "no answer in time";
  return Error{Errc::unreachable, "redis at " + url_ + ": " + why};
}

}  // namespace prime::optimus::detail
