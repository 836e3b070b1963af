// Looking at an Optimus domain from outside (inspect.hpp): its registry,
// streams and live services, read through one connection.
#include "prime/optimus/inspect.hpp"

#include <map>

#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/stream_protocol.hpp"

namespace prime::optimus {

namespace {

detail::Connection open(const Options& options) {
  const auto endpoint = detail::parse_url(options.url);
  if (!endpoint) throw Failure{endpoint.error()};
  auto connection = detail::Connection::open(options, *endpoint);
  if (!connection) throw Failure{connection.error()};
  return std::move(*connection);
}

// The reply to `words`, or a Failure naming what went wrong.
detail::Reply command(detail::Connection& connection, const Options& options, const std::vector<std::string>& words) {
  const std::vector<std::string_view> args(words.begin(), words.end());
  auto reply = connection.command(args);
  if (!reply) throw Failure{reply.error()};
  if ((*reply)->is_error())
    throw Failure{{Errc::unreachable,
                   "redis at " + detail::without_password(options.url) + ": " + std::string{(*reply)->text()}}};
  return std::move(*reply);
}

std::map<std::string, std::string> hash(detail::Connection& connection, const Options& options, const std::string& key) {
  std::map<std::string, std::string> out;
  auto reply = command(connection, options, {"HGETALL", key});
  if (!reply->is_array()) return out;
  for (std::size_t i = 0; i + 1 < reply->size(); i += 2)
    out[std::string{(*reply)[i].text()}] = std::string{(*reply)[i + 1].text()};
  return out;
}

// A source's readers: the "r<id>" fields of its readers hash (a reader
// that has lost values also has an "l<id>" field there).
long long readers(detail::Connection& connection, const Options& options, const std::string& source) {
  auto reply = command(connection, options, {"HKEYS", detail::readers_key(options.domain, source)});
  long long n = 0;
  for (std::size_t i = 0; i < reply->size(); ++i)
    if ((*reply)[i].text().starts_with('r')) ++n;
  return n;
}

// "0123456789abcdef Pose (24 bytes, ...)" -> "Pose (24 bytes, ...)"
std::string described(const std::string& record) {
  const auto space = record.find(' ');
  return space == std::string::npos ? record : record.substr(space + 1);
}

}  // namespace

Inspector::Inspector(Options options)
    : options_{std::move(options)}, connection_{std::make_unique<detail::Connection>(open(options_))} {}
Inspector::Inspector(Inspector&&) noexcept = default;
Inspector& Inspector::operator=(Inspector&&) noexcept = default;
Inspector::~Inspector() = default;

std::string Inspector::server() const { return detail::without_password(options_.url); }

std::vector<SourceSummary> Inspector::sources() {
  std::vector<SourceSummary> out;
  for (auto& [name, record] : hash(*connection_, options_, detail::sources_key(options_.domain))) {
    auto stream = detail::stream_key(options_.domain, name);
    const auto length = command(*connection_, options_, {"XLEN", stream})->integer();
    out.push_back({name, described(record), std::move(stream), length, readers(*connection_, options_, name), record});
  }
  return out;
}

std::vector<ServiceSummary> Inspector::services() {
  std::vector<ServiceSummary> out;
  for (auto& [name, record] : hash(*connection_, options_, detail::services_key(options_.domain))) {
    const auto alive = detail::alive_key(detail::service_key(options_.domain, name));
    out.push_back({name, described(record), command(*connection_, options_, {"EXISTS", alive})->integer() != 0});
  }
  return out;
}

Inspector::Tail Inspector::tail(const std::string& source) {
  // From the stream's newest entry as it is now, by its id: "$" would be
  // looked up again by each read, and an entry appended between two reads
  // (or before the first) would never be seen.
  auto stream = detail::stream_key(options_.domain, source);
  auto newest = command(*connection_, options_, {"XREVRANGE", stream, "+", "-", "COUNT", "1"});
  std::string from = "0-0";
  if (newest->is_array() && newest->size() > 0 && (*newest)[0].is_array() && (*newest)[0].size() > 0 &&
      (*newest)[0][0].is_string() && detail::entry_id((*newest)[0][0].text()))
    from = std::string{(*newest)[0][0].text()};
  return Tail{*this, std::move(stream), std::move(from)};
}

std::optional<StreamEntry> Inspector::Tail::next(Clock::duration timeout) {
  if (buffered_.empty()) {
    // At least 1 ms: BLOCK 0 would wait for ever.
    const auto ms = std::max<long long>(1, std::chrono::duration_cast<std::chrono::milliseconds>(timeout).count());
    auto reply = command(*inspector_->connection_, inspector_->options_,
                         {"XREAD", "COUNT", "100", "BLOCK", std::to_string(ms), "STREAMS", stream_, last_});
    if (reply->is_array() && reply->size() > 0) read((*reply)[0]);
  }
  if (buffered_.empty()) return std::nullopt;
  auto front = std::move(buffered_.front());
  buffered_.pop_front();
  return front;
}

void Inspector::Tail::read(detail::ReplyRef stream) {
  if (!stream.is_array() || stream.size() < 2 || !stream[1].is_array()) return;
  const auto entries = stream[1];
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const auto e = entries[i];
    if (!e.is_array() || e.size() < 2 || !e[0].is_string()) continue;
    const std::string id{e[0].text()};
    last_ = id;
    StreamEntry out;
    if (const auto parsed = detail::entry_id(id)) out.sequence = parsed->seq;
    const auto fields = e[1];
    if (fields.is_array())
      for (std::size_t f = 0; f + 1 < fields.size(); f += 2) {
        const auto name = fields[f].text();
        const auto value = fields[f + 1].text();
        if (name == "d") out.data = std::string{value};
        std::int64_t ns = 0;
        if (name == "t" && std::from_chars(value.data(), value.data() + value.size(), ns).ec == std::errc{})
          out.stamp = Clock::time_point{std::chrono::nanoseconds{ns}};
      }
    buffered_.push_back(std::move(out));
  }
}

}  // namespace prime::optimus
